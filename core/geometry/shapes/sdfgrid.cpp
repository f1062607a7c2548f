#include "core/geometry/shapes/sdfgrid.h"

#include <tbb/parallel_for.h>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include "core/geometry/embree_user.h"

namespace limn {

// ---- cubic roots (Marmitt et al. 2004) ----------------------------------------------------------
namespace {
double cubic(double c0, double c1, double c2, double c3, double t) { return c0 + t * (c1 + t * (c2 + t * c3)); }

// The root of a cubic that changes sign over [a, b] (fa, fb its values there): bracketed Newton,
// falling back to bisection when a step leaves the bracket.
double refine_root(double c0, double c1, double c2, double c3, double a, double b, double fa) {
  double t = 0.5 * (a + b);
  for (int it = 0; it < 100; ++it) {
    const double f = cubic(c0, c1, c2, c3, t);
    if (f == 0.0) return t;
    if ((f > 0.0) == (fa > 0.0)) a = t, fa = f;
    else b = t;
    const double df = c1 + t * (2.0 * c2 + 3.0 * t * c3);
    double next = df != 0.0 ? t - f / df : 0.5 * (a + b);
    if (!(next > a && next < b)) next = 0.5 * (a + b);
    // Converged when the bracket or the step is at double resolution of the interval's end.
    const double tol = 4.0 * std::numeric_limits<double>::epsilon() * std::max(std::abs(a), std::abs(b));
    if (b - a <= tol || std::abs(next - t) <= tol) return next;
    t = next;
  }
  return t;
}
}  // namespace

bool first_cubic_root(double c0, double c1, double c2, double c3, double t0, double t1, double& t) {
  if (!(t1 >= t0)) return false;
  if (c0 == 0.0 && c1 == 0.0 && c2 == 0.0 && c3 == 0.0) return false;  // the line lies in the zero set: no crossing
  // Split points: the derivative's roots 3 c3 t^2 + 2 c2 t + c1 = 0 inside (t0, t1).
  double split[4] = {t0, 0.0, 0.0, 0.0};
  int n = 1;
  const double qa = 3.0 * c3, qb = 2.0 * c2, qc = c1;
  double r[2];
  int nr = 0;
  if (qa != 0.0) {
    const double disc = qb * qb - 4.0 * qa * qc;
    if (disc >= 0.0) {
      const double s = std::sqrt(disc);
      const double q = qb < 0.0 ? -0.5 * (qb - s) : -0.5 * (qb + s);  // stable form
      r[nr++] = q / qa;
      if (q != 0.0) r[nr++] = qc / q;
    }
  } else if (qb != 0.0) {
    r[nr++] = -qc / qb;
  }
  if (nr == 2 && r[0] > r[1]) std::swap(r[0], r[1]);
  for (int i = 0; i < nr; ++i)
    if (r[i] > t0 && r[i] < t1) split[n++] = r[i];
  split[n++] = t1;
  double fa = cubic(c0, c1, c2, c3, split[0]);
  for (int i = 0; i + 1 < n; ++i) {
    const double a = split[i], b = split[i + 1];
    const double fb = cubic(c0, c1, c2, c3, b);
    if (fa == 0.0) {
      t = a;
      return true;
    }
    if (fb == 0.0 || (fa > 0.0) != (fb > 0.0)) {
      t = fb == 0.0 ? b : refine_root(c0, c1, c2, c3, a, b, fa);
      return true;
    }
    fa = fb;
  }
  return false;
}

// ---- voxels -----------------------------------------------------------------------------------
void SdfGrid::corners(uint32_t v, double c[8]) const {
  int i, j, k;
  voxel_coords(v, i, j, k);
  for (int q = 0; q < 8; ++q) c[q] = values[sample_index(i + (q & 1), j + ((q >> 1) & 1), k + ((q >> 2) & 1))];
}

Trilinear<double> SdfGrid::voxel_function(uint32_t v) const {
  double c[8];
  corners(v, c);
  return Trilinear<double>::from_corners(c);
}

SdfSample SdfGrid::eval(uint32_t v, const Vec3d& s) const {
  const Trilinear<double> t = voxel_function(v);
  SdfSample out;
  out.f = t.value(s.x, s.y, s.z);
  double g[3];
  t.gradient(s.x, s.y, s.z, g);
  out.grad = Vec3d(g[0], g[1], g[2]);
  double fxy, fyz, fxz;
  t.hessian(s.x, s.y, s.z, fxy, fyz, fxz);
  out.hess = glm::dmat3(0.0, fxy, fxz, fxy, 0.0, fyz, fxz, fyz, 0.0);
  return out;
}

uint32_t SdfGrid::locate(const Vec3d& g, Vec3d& s) const {
  const int i = std::clamp(int(std::floor(g.x)), 0, nx - 2), j = std::clamp(int(std::floor(g.y)), 0, ny - 2),
            k = std::clamp(int(std::floor(g.z)), 0, nz - 2);
  s = g - Vec3d(i, j, k);
  return voxel_index(i, j, k);
}

bool SdfGrid::world_normal(const Vec3d& grad, Vec3d& n) const {
  const Vec3d w = A_inv_t * grad;
  const double len = glm::length(w);
  if (!(len > 0.0) || !std::isfinite(len)) return false;
  n = w / len;
  return true;
}

int SdfGrid::voxel_axis(const double c[8]) {
  int best = 2;
  double best_score = -kInfinity;
  double largest = 0.0;
  for (int q = 0; q < 8; ++q)
    for (int a = 0; a < 3; ++a)
      if (!(q & (1 << a))) largest = std::max(largest, std::abs(c[q | (1 << a)] - c[q]));
  for (int a = 2; a >= 0; --a) {  // z first on ties
    double lo = kInfinity, sum = 0.0, abs_sum = 0.0;
    int pos = 0, neg = 0;
    for (int q = 0; q < 8; ++q) {
      if (q & (1 << a)) continue;
      const double e = c[q | (1 << a)] - c[q];
      pos += e > 0.0;
      neg += e < 0.0;
      lo = std::min(lo, std::abs(e));
      sum += e;
      abs_sum += std::abs(e);
    }
    // Monotone along the axis on every line: scored by the smallest edge change (relative);
    // otherwise by how one-sided the changes are, always below the monotone ones.
    const double score = (pos == 4 || neg == 4) ? lo / std::max(largest, 1e-300) : -1.0 + 0.5 * std::abs(sum) / std::max(abs_sum, 1e-300);
    if (score > best_score) best_score = score, best = a;
  }
  return best;
}

bool SdfGrid::straddles(const double c[8]) {
  double lo = c[0], hi = c[0];
  for (int q = 1; q < 8; ++q) lo = std::min(lo, c[q]), hi = std::max(hi, c[q]);
  return lo <= 0.0 && hi >= 0.0 && !(lo == 0.0 && hi == 0.0);
}

bool SdfGrid::build_prim(uint32_t v, Prim& out) const {
  double c[8];
  corners(v, c);
  if (!straddles(c)) return false;
  // Tight box: the sub-cells of a 4 x 4 x 4 split whose corner values straddle zero (a trilinear
  // function's extremes over a box are at its corners). Values within 1e-7 of the largest corner
  // value count as zero, so rounding of the sub-grid cannot drop a sub-cell the surface touches.
  constexpr int S = 4;
  const Trilinear<double> t = Trilinear<double>::from_corners(c);
  double sub[S + 1][S + 1][S + 1];
  double scale = 0.0;
  for (double x : c) scale = std::max(scale, std::abs(x));
  const double tol = 1e-7 * scale;
  for (int z = 0; z <= S; ++z)
    for (int y = 0; y <= S; ++y)
      for (int x = 0; x <= S; ++x) sub[z][y][x] = t.value(double(x) / S, double(y) / S, double(z) / S);
  Vec3d lo(kInfinity), hi(-kInfinity);
  for (int z = 0; z < S; ++z)
    for (int y = 0; y < S; ++y)
      for (int x = 0; x < S; ++x) {
        double mn = kInfinity, mx = -kInfinity;
        for (int q = 0; q < 8; ++q) {
          const double s = sub[z + ((q >> 2) & 1)][y + ((q >> 1) & 1)][x + (q & 1)];
          mn = std::min(mn, s);
          mx = std::max(mx, s);
        }
        if (mn <= tol && mx >= -tol) {
          lo = glm::min(lo, Vec3d(x, y, z) / double(S));
          hi = glm::max(hi, Vec3d(x + 1, y + 1, z + 1) / double(S));
        }
      }
  if (lo.x > hi.x) return false;
  const Vec3d o = voxel_origin(v);
  out.voxel = v;
  out.axis = uint8_t(voxel_axis(c));
  for (int a = 0; a < 3; ++a) {
    out.lo[a] = float(o[a] + lo[a]);
    out.hi[a] = float(o[a] + hi[a]);
  }
  return true;
}

size_t SdfGrid::update_voxels(bool all) {
  const int cx = nx - 1, cy = ny - 1, cz = nz - 1;
  if (all || built_values.size() != values.size()) {
    // Every voxel, one z-slab per task (the lists come back in voxel order).
    std::vector<std::vector<Prim>> slabs(static_cast<size_t>(cz));
    tbb::parallel_for(0, cz, [&](int k) {
      for (int j = 0; j < cy; ++j)
        for (int i = 0; i < cx; ++i) {
          Prim p;
          if (build_prim(voxel_index(i, j, k), p)) slabs[size_t(k)].push_back(p);
        }
    });
    prims.clear();
    for (const auto& s : slabs) prims.insert(prims.end(), s.begin(), s.end());
    built_values = values;
    return voxel_count();
  }
  // Many changed samples (an optimisation step moves every value): the parallel full rebuild is
  // cheaper than the merge below (256^3, every value changed: 24 s merged, 3.5 s rebuilt).
  size_t changed = 0;
  for (size_t idx = 0; idx < values.size(); ++idx) changed += values[idx] != built_values[idx];
  if (changed * 8 > values.size()) return update_voxels(true);
  // The voxels around each changed sample (up to 8).
  std::vector<uint32_t> dirty;
  for (size_t idx = 0; idx < values.size(); ++idx) {
    if (values[idx] == built_values[idx]) continue;
    const int x = int(idx % size_t(nx)), y = int((idx / size_t(nx)) % size_t(ny)), z = int(idx / (size_t(nx) * ny));
    for (int dz = -1; dz <= 0; ++dz)
      for (int dy = -1; dy <= 0; ++dy)
        for (int dx = -1; dx <= 0; ++dx) {
          const int i = x + dx, j = y + dy, k = z + dz;
          if (i >= 0 && j >= 0 && k >= 0 && i < cx && j < cy && k < cz) dirty.push_back(voxel_index(i, j, k));
        }
  }
  if (dirty.empty()) return 0;
  std::sort(dirty.begin(), dirty.end());
  dirty.erase(std::unique(dirty.begin(), dirty.end()), dirty.end());
  // Merge: the old prims of clean voxels and the rebuilt dirty ones, in voxel order.
  std::vector<Prim> rebuilt(dirty.size());
  std::vector<char> ok(dirty.size(), 0);
  tbb::parallel_for(size_t(0), dirty.size(), [&](size_t n) { ok[n] = build_prim(dirty[n], rebuilt[n]); });
  std::vector<Prim> merged;
  merged.reserve(prims.size() + dirty.size());
  size_t a = 0, b = 0;
  while (a < prims.size() || b < dirty.size()) {
    if (b == dirty.size() || (a < prims.size() && prims[a].voxel < dirty[b])) {
      merged.push_back(prims[a++]);
    } else {
      if (a < prims.size() && prims[a].voxel == dirty[b]) ++a;  // replaced
      if (ok[b]) merged.push_back(rebuilt[b]);
      ++b;
    }
  }
  prims.swap(merged);
  for (size_t idx = 0; idx < values.size(); ++idx) built_values[idx] = values[idx];
  return dirty.size();
}

// ---- intersection -------------------------------------------------------------------------------
bool SdfGrid::intersect_voxel(uint32_t v, const Vec3d& o, const Vec3d& d, double tmin, double tmax, double& t_hit) const {
  const Vec3d lo = voxel_origin(v);
  // Slab test against the closed voxel box (a ray along a face belongs to both voxels).
  double t0 = tmin, t1 = tmax;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (o[a] < lo[a] || o[a] > lo[a] + 1.0) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (lo[a] + 1.0 - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 <= t1)) return false;
  // The cubic f(p + t' d), t' = t - t0, about the entry point (JCGT 2022: coefficients about the
  // entry point keep their precision).
  const Trilinear<double> f = voxel_function(v);
  const Vec3d p = o + t0 * d - lo;
  const double* k = f.k;
  const double c0 = f.value(p.x, p.y, p.z);
  const double c1 = k[1] * d.x + k[2] * d.y + k[3] * d.z + k[4] * (p.x * d.y + p.y * d.x) + k[5] * (p.y * d.z + p.z * d.y) +
                    k[6] * (p.x * d.z + p.z * d.x) + k[7] * (d.x * p.y * p.z + p.x * d.y * p.z + p.x * p.y * d.z);
  const double c2 = k[4] * d.x * d.y + k[5] * d.y * d.z + k[6] * d.x * d.z + k[7] * (d.x * d.y * p.z + d.x * p.y * d.z + p.x * d.y * d.z);
  const double c3 = k[7] * d.x * d.y * d.z;
  double s;
  if (!first_cubic_root(c0, c1, c2, c3, 0.0, t1 - t0, s)) return false;
  if (!(t0 + s > tmin)) {
    // A root exactly at the ray's start (tmin) is not a hit: look past it.
    const double eps = 1e-12 * (std::abs(t0) + (t1 - t0));
    if (!first_cubic_root(c0, c1, c2, c3, std::max(s, 0.0) + eps, t1 - t0, s) || !(t0 + s > tmin)) return false;
  }
  t_hit = t0 + s;
  return t_hit < tmax;
}

void SdfGrid::fill_interaction(uint32_t v, const Vec3d& g_in, const Vec3& toward, SurfaceInteraction& si) const {
  const Vec3d lo = voxel_origin(v);
  const Vec3d g = glm::clamp(g_in, lo, lo + Vec3d(1.0));
  const SdfSample S = eval(v, g - lo);
  const Vec3d pw = world_from_grid(g);
  si.p = Vec3(pw);
  Vec3d n;
  const bool has_normal = world_normal(S.grad, n);
  if (!has_normal) {
    // |grad f| = 0 (a flat or saddle point of the samples): no normal exists; face the ray so
    // shading stays finite.
    const float len = glm::length(toward);
    n = len > 0.0f ? Vec3d(toward / len) : Vec3d(0, 0, 1);
  }
  si.ng = si.ns = Vec3(n);
  // Rounding: the double root converted to float and mapped through A (a few ulps of the
  // magnitudes involved), plus how far the float point lies from the zero set along the normal
  // (|f| / |grad_world f|), which is large where the gradient is small.
  const Vec3 reach = Vec3(glm::abs(pw) + glm::abs(origin) + glm::abs(A * g));
  float off_surface = 0.0f;
  if (has_normal) off_surface = float(2.0 * std::abs(eval(v, grid_from_world(Vec3d(si.p)) - lo).f) / glm::length(A_inv_t * S.grad));
  si.p_error = gamma_bound(8) * reach + Vec3(std::isfinite(off_surface) ? off_surface : 0.0f);
  const Vec3d l(g.x / (nx - 1), g.y / (ny - 1), g.z / (nz - 1));
  si.uv = Vec2(float(l.x), float(l.y));
  si.bary = Vec2(float(l.z), 0.0f);
  si.prim = int(v);
  si.frame = Frame(si.ns);
}

void SdfGrid::fill_hit(const Ray& ray, float t, unsigned prim, const Vec2&, SurfaceInteraction& si) const {
  const uint32_t v = prims[prim].voxel;
  const Vec3d o = grid_from_world(Vec3d(ray.o)), d = A_inv * Vec3d(ray.d);
  // Embree keeps t in float: the root again in double, in a bracket around it.
  double th = double(t);
  const double w = 1e-5 * (std::abs(th) + 1e-3);
  double tr;
  if (intersect_voxel(v, o, d, std::max(double(ray.tmin), th - w), th + w, tr)) th = tr;
  fill_interaction(v, o + th * d, -ray.d, si);
}

// ---- Embree -------------------------------------------------------------------------------------
namespace {
void sdf_bounds(const RTCBoundsFunctionArguments* args) {
  const SdfGrid& s = *static_cast<const SdfGrid*>(args->geometryUserPtr);
  const SdfGrid::Prim& p = s.prims[args->primID];
  Vec3d lo(kInfinity), hi(-kInfinity);
  for (int q = 0; q < 8; ++q) {
    const Vec3d w = s.world_from_grid(Vec3d(q & 1 ? p.hi[0] : p.lo[0], q & 2 ? p.hi[1] : p.lo[1], q & 4 ? p.hi[2] : p.lo[2]));
    lo = glm::min(lo, w);
    hi = glm::max(hi, w);
  }
  // Widened by a few ulps: the box is rounded to float, the intersector works in double.
  const Vec3d pad = 1e-6 * (glm::abs(lo) + glm::abs(hi)) + Vec3d(1e-6 * s.voxel_size);
  embree_user::set_bounds(args->bounds_o, Vec3(lo - pad), Vec3(hi + pad));
}

void sdf_intersect(const RTCIntersectFunctionNArguments* args) {
  const SdfGrid& s = *static_cast<const SdfGrid*>(args->geometryUserPtr);
  RTCRayN* ray = RTCRayHitN_RayN(args->rayhit, args->N);
  RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, args->N);
  const uint32_t v = s.prims[args->primID].voxel;
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const Ray r = embree_user::ray_from_n(ray, args->N, i);
    double t;
    if (!s.intersect_voxel(v, s.grid_from_world(Vec3d(r.o)), s.A_inv * Vec3d(r.d), r.tmin, r.tmax, t)) continue;
    const float tf = float(t);
    if (!(tf > r.tmin && tf < r.tmax)) continue;  // rounding to float left the interval
    embree_user::record_hit(args, ray, hit, i, tf);
  }
}

void sdf_occluded(const RTCOccludedFunctionNArguments* args) {
  const SdfGrid& s = *static_cast<const SdfGrid*>(args->geometryUserPtr);
  const uint32_t v = s.prims[args->primID].voxel;
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const Ray r = embree_user::ray_from_n(args->ray, args->N, i);
    double t;
    if (!s.intersect_voxel(v, s.grid_from_world(Vec3d(r.o)), s.A_inv * Vec3d(r.d), r.tmin, r.tmax, t)) continue;
    const float tf = float(t);
    if (tf > r.tmin && tf < r.tmax) RTCRayN_tfar(args->ray, args->N, i) = -kInfinity;
  }
}
}  // namespace

RTCGeometry SdfGrid::create_embree_geometry(RTCDevice device) const {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(geom, unsigned(prims.size()));
  rtcSetGeometryUserData(geom, const_cast<SdfGrid*>(this));
  rtcSetGeometryBoundsFunction(geom, sdf_bounds, nullptr);
  rtcSetGeometryIntersectFunction(geom, sdf_intersect);
  rtcSetGeometryOccludedFunction(geom, sdf_occluded);
  return geom;
}

void SdfGrid::update_embree_geometry(RTCGeometry g) const { rtcSetGeometryUserPrimitiveCount(g, unsigned(prims.size())); }

// ---- the rest of the interface -------------------------------------------------------------------
void SdfGrid::build_derived() {
  const Mat4d& m = world_from_local.matrix();
  const glm::dmat3 L(m);
  A = L * glm::dmat3(1.0 / (nx - 1), 0, 0, 0, 1.0 / (ny - 1), 0, 0, 0, 1.0 / (nz - 1));
  A_inv = glm::inverse(A);
  A_inv_t = glm::transpose(A_inv);
  det_A = glm::determinant(A);
  origin = Vec3d(m[3]);
  voxel_size = std::cbrt(std::abs(det_A));
  update_voxels(true);
}

void SdfGrid::translate(const Vec3& delta) {
  world_from_local = Transform::translate(Vec3d(delta)) * world_from_local;
  origin = Vec3d(world_from_local.matrix()[3]);
}

float SdfGrid::area() const {
  // Midpoint rule (4 x 4) over each patch as a graph along its axis: J = |det A| |A^-T grad f| / |f_c|.
  double total = 0.0;
  for (const Prim& p : prims) {
    const Trilinear<double> t = voxel_function(p.voxel);
    const int c = p.axis, a = (c + 1) % 3, b = (c + 2) % 3;
    for (int u = 0; u < 4; ++u)
      for (int w = 0; w < 4; ++w) {
        Vec3d s(0.0);
        s[a] = (u + 0.5) / 4.0;
        s[b] = (w + 0.5) / 4.0;
        Vec3d s1 = s;
        s1[c] = 1.0;
        const double f0 = t.value(s.x, s.y, s.z), f1 = t.value(s1.x, s1.y, s1.z), fc = f1 - f0;
        if (fc == 0.0) continue;
        s[c] = -f0 / fc;
        if (!(s[c] >= 0.0 && s[c] <= 1.0)) continue;
        double g[3];
        t.gradient(s.x, s.y, s.z, g);
        total += std::abs(det_A) * glm::length(A_inv_t * Vec3d(g[0], g[1], g[2])) / std::abs(fc) / 16.0;
      }
  }
  return float(total);
}

void SdfGrid::list_parameters(const std::string& id, int index, std::vector<Parameter>& out) {
  out.push_back({id + ".data", Parameter::Kind::SdfData, index, values.data(), {size_t(nz), size_t(ny), size_t(nx)}, true});
}

void SdfGrid::validate_parameter(const Parameter& p, const std::string& where) const {
  for (size_t i = 0; i < p.size(); ++i)
    if (!std::isfinite(p.data[i]))
      throw std::invalid_argument(where + ": value at [z, y, x] = [" + std::to_string(i / (size_t(nx) * ny)) + ", " +
                                  std::to_string((i / size_t(nx)) % size_t(ny)) + ", " + std::to_string(i % size_t(nx)) +
                                  "] is not finite (" + std::to_string(p.data[i]) + ")");
}

void SdfGrid::bounds(Vec3& lo, Vec3& hi) const {
  Vec3d l(kInfinity), h(-kInfinity);
  for (const Prim& p : prims)
    for (int q = 0; q < 8; ++q) {
      const Vec3d w = world_from_grid(Vec3d(q & 1 ? p.hi[0] : p.lo[0], q & 2 ? p.hi[1] : p.lo[1], q & 4 ? p.hi[2] : p.lo[2]));
      l = glm::min(l, w);
      h = glm::max(h, w);
    }
  lo = Vec3(l);
  hi = Vec3(h);
}

void SdfGrid::geometry_state(std::vector<float>& out, Vec3& lo, Vec3& hi) const {
  out.insert(out.end(), values.begin(), values.end());
  const Vec3d o = origin;
  out.insert(out.end(), {float(o.x), float(o.y), float(o.z)});
  Vec3 l, h;
  bounds(l, h);
  if (l.x <= h.x) {
    lo = glm::min(lo, l);
    hi = glm::max(hi, h);
  }
}

}  // namespace limn
