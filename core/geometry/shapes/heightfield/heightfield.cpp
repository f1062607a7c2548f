#include "core/geometry/shapes/heightfield/heightfield.h"

#include <array>
#include <cstring>
#include <stdexcept>
#include "core/geometry/embree_user.h"

namespace limn {

PatchCoords Heightfield::patch(double x, double y) const {
  PatchCoords p;
  const double c = std::clamp(grid_c(x), 0.0, double(nx - 1)), r = std::clamp(grid_r(y), 0.0, double(ny - 1));
  p.c0 = std::min(int(c), nx - 2);
  p.r0 = std::min(int(r), ny - 2);
  p.fc = c - p.c0;
  p.fr = r - p.r0;
  for (int b = 0; b < 4; ++b)
    for (int a = 0; a < 4; ++a)
      p.index[b][a] = std::clamp(p.r0 - 1 + b, 0, ny - 1) * nx + std::clamp(p.c0 - 1 + a, 0, nx - 1);
  return p;
}

HeightSample Heightfield::eval(double x, double y) const {
  const PatchCoords p = patch(x, y);
  double bc[4], dbc[4], d2bc[4], br[4], dbr[4], d2br[4];
  bspline_basis(p.fc, bc, dbc, d2bc);
  bspline_basis(p.fr, br, dbr, d2br);
  double z = 0, zc = 0, zr = 0, zcc = 0, zcr = 0, zrr = 0;
  for (int b = 0; b < 4; ++b)
    for (int a = 0; a < 4; ++a) {
      const double h = heights[p.index[b][a]];
      z += br[b] * bc[a] * h;
      zc += br[b] * dbc[a] * h;
      zr += dbr[b] * bc[a] * h;
      zcc += br[b] * d2bc[a] * h;
      zcr += dbr[b] * dbc[a] * h;
      zrr += d2br[b] * bc[a] * h;
    }
  const double s = height_scale, kc = (nx - 1) / double(width), kr = -(ny - 1) / double(depth);  // dc/dx, dr/dy
  HeightSample out;
  out.z = s * z;
  out.dx = s * zc * kc;
  out.dy = s * zr * kr;
  out.dxx = s * zcc * kc * kc;
  out.dxy = s * zcr * kc * kr;
  out.dyy = s * zrr * kr * kr;
  return out;
}

void CellPatch::load(const Heightfield& hf, int cell_i, int cell_j) {
  i = cell_i;
  j = cell_j;
  for (int b = 0; b < 4; ++b) {
    const size_t row = size_t(std::clamp(j - 1 + b, 0, hf.ny - 1)) * hf.nx;
    for (int a = 0; a < 4; ++a) control[b][a] = hf.heights[row + std::clamp(i - 1 + a, 0, hf.nx - 1)];
  }
}

HeightSample CellPatch::eval(const Heightfield& hf, double x, double y) const {
  const double fc = std::clamp(hf.grid_c(x) - i, 0.0, 1.0), fr = std::clamp(hf.grid_r(y) - j, 0.0, 1.0);
  double bc[4], dbc[4], br[4], dbr[4], unused[4];
  bspline_basis(fc, bc, dbc, unused);
  bspline_basis(fr, br, dbr, unused);
  double z = 0, zc = 0, zr = 0;
  for (int b = 0; b < 4; ++b) {
    double row = 0, drow = 0;
    for (int a = 0; a < 4; ++a) {
      row += bc[a] * control[b][a];
      drow += dbc[a] * control[b][a];
    }
    z += br[b] * row;
    zc += br[b] * drow;
    zr += dbr[b] * row;
  }
  const double s = hf.height_scale;
  HeightSample out;
  out.z = s * z;
  out.dx = s * zc * (hf.nx - 1) / double(hf.width);
  out.dy = -s * zr * (hf.ny - 1) / double(hf.depth);
  return out;
}

// ---- maximum mipmap ---------------------------------------------------------------------------------
namespace {
void cell_bounds(const Heightfield& hf, int c0, int r0, Heightfield::Level& L) {
  double H[4][4];
  for (int b = 0; b < 4; ++b) {
    const int r = std::clamp(r0 - 1 + b, 0, hf.ny - 1);
    for (int a = 0; a < 4; ++a) H[b][a] = hf.heights[size_t(r) * hf.nx + std::clamp(c0 - 1 + a, 0, hf.nx - 1)];
  }
  double lo = H[0][0], hi = H[0][0], cc = 0.0, rr = 0.0, cr = 0.0;
  for (int b = 0; b < 4; ++b)
    for (int a = 0; a < 4; ++a) {
      lo = std::min(lo, H[b][a]);
      hi = std::max(hi, H[b][a]);
      if (a < 2) cc = std::max(cc, std::abs(H[b][a] - 2.0 * H[b][a + 1] + H[b][a + 2]));
      if (b < 2) rr = std::max(rr, std::abs(H[b][a] - 2.0 * H[b + 1][a] + H[b + 2][a]));
      if (a < 3 && b < 3) cr = std::max(cr, std::abs(H[b + 1][a + 1] - H[b][a + 1] - H[b + 1][a] + H[b][a]));
    }
  const double s = hf.height_scale, sx = (hf.nx - 1) / double(hf.width), sy = (hf.ny - 1) / double(hf.depth);
  const size_t k = size_t(r0) * L.w + c0;
  L.node[k].lo = float(lo) * hf.height_scale;
  L.node[k].hi = float(hi) * hf.height_scale;
  // Rounded up by a float ulp or so, so that the bound stays a bound after the conversion.
  L.node[k].zxx = float(s * cc * sx * sx * (1.0 + 1e-6));
  L.node[k].zyy = float(s * rr * sy * sy * (1.0 + 1e-6));
  L.node[k].zxy = float(s * cr * sx * sy * (1.0 + 1e-6));
}

// Recomputes cells [x0, x1] x [y0, y1] of level l from level l - 1.
void reduce(Heightfield& hf, int l, int x0, int x1, int y0, int y1) {
  const Heightfield::Level& src = hf.mip[l - 1];
  Heightfield::Level& dst = hf.mip[l];
  for (int j = y0; j <= y1; ++j)
    for (int i = x0; i <= x1; ++i) {
      float lo = kInfinity, hi = -kInfinity, xx = 0.0f, yy = 0.0f, xy = 0.0f;
      for (int b = 0; b < 2; ++b)
        for (int a = 0; a < 2; ++a) {
          const int si = 2 * i + a, sj = 2 * j + b;
          if (si >= src.w || sj >= src.h) continue;
          const size_t k = size_t(sj) * src.w + si;
          lo = std::min(lo, src.node[k].lo);
          hi = std::max(hi, src.node[k].hi);
          xx = std::max(xx, src.node[k].zxx);
          yy = std::max(yy, src.node[k].zyy);
          xy = std::max(xy, src.node[k].zxy);
        }
      const size_t k = size_t(j) * dst.w + i;
      dst.node[k].lo = lo;
      dst.node[k].hi = hi;
      dst.node[k].zxx = xx;
      dst.node[k].zyy = yy;
      dst.node[k].zxy = xy;
    }
}

void rebuild_region(Heightfield& hf, int x0, int x1, int y0, int y1) {
  Heightfield::Level& base = hf.mip[0];
  for (int j = y0; j <= y1; ++j)
    for (int i = x0; i <= x1; ++i) cell_bounds(hf, i, j, base);
  for (size_t l = 1; l < hf.mip.size(); ++l) {
    x0 /= 2; x1 /= 2; y0 /= 2; y1 /= 2;
    reduce(hf, int(l), x0, x1, y0, y1);
  }
}
}  // namespace

void Heightfield::build_mipmap() {
  mip.clear();
  int w = cells_x(), h = cells_y();
  auto level = [](int w, int h) {
    return Level{w, h, std::vector<NodeBounds>(size_t(w) * h)};
  };
  mip.push_back(level(w, h));
  while (w > 1 || h > 1) {
    w = (w + 1) / 2;
    h = (h + 1) / 2;
    mip.push_back(level(w, h));
  }
  rebuild_region(*this, 0, cells_x() - 1, 0, cells_y() - 1);
  mip_heights = heights;
}

size_t Heightfield::update_mipmap() {
  int c_lo = nx, c_hi = -1, r_lo = ny, r_hi = -1;
  for (int r = 0; r < ny; ++r)
    for (int c = 0; c < nx; ++c) {
      const size_t i = size_t(r) * nx + c;
      if (std::memcmp(&heights[i], &mip_heights[i], sizeof(float)) == 0) continue;
      c_lo = std::min(c_lo, c); c_hi = std::max(c_hi, c);
      r_lo = std::min(r_lo, r); r_hi = std::max(r_hi, r);
    }
  if (c_hi < 0) return 0;
  // Control point (r, c) is in the support of cells c - 2 .. c + 1 (and rows alike).
  const int x0 = std::max(0, c_lo - 2), x1 = std::min(cells_x() - 1, c_hi + 1);
  const int y0 = std::max(0, r_lo - 2), y1 = std::min(cells_y() - 1, r_hi + 1);
  rebuild_region(*this, x0, x1, y0, y1);
  for (int r = r_lo; r <= r_hi; ++r)
    std::memcpy(&mip_heights[size_t(r) * nx + c_lo], &heights[size_t(r) * nx + c_lo], sizeof(float) * (c_hi - c_lo + 1));
  return size_t(x1 - x0 + 1) * size_t(y1 - y0 + 1);
}

// ---- ray traversal ----------------------------------------------------------------------------------
namespace {
// Parametric range of the 2D ray o + t d inside [x0, x1] x [y0, y1]; false when empty.
bool slab(double o, double d, double a, double b, double& t0, double& t1) {
  if (d == 0.0) return o >= a && o <= b;
  double ta = (a - o) / d, tb = (b - o) / d;
  if (ta > tb) std::swap(ta, tb);
  t0 = std::max(t0, ta);
  t1 = std::min(t1, tb);
  return t0 <= t1;
}

struct Node {
  int level, i, j;
  double t0, t1;
};
}  // namespace

bool Heightfield::node_span(int l, int i, int j, double ox, double oy, double dx, double dy, double& t0, double& t1) const {
  const int c_lo = i << l, c_hi = std::min((i + 1) << l, cells_x());
  const int r_lo = j << l, r_hi = std::min((j + 1) << l, cells_y());
  if (c_lo >= cells_x() || r_lo >= cells_y()) return false;
  // Rows grow towards -y.
  return slab(ox, dx, local_x(c_lo), local_x(c_hi), t0, t1) && slab(oy, dy, local_y(r_hi), local_y(r_lo), t0, t1);
}

bool Heightfield::intersect_local(const Vec3d& o, const Vec3d& d, double tmin, double tmax, double& t_hit, size_t* cells) const {
  auto node_range = [&](int l, int i, int j, double& t0, double& t1) { return node_span(l, i, j, o.x, o.y, d.x, d.y, t0, t1); };
  // Height tolerance: the bounds are floats, the surface is evaluated in double.
  const double eps = 1e-6 * std::max(1.0, double(std::max(std::abs(max_height()), std::abs(min_height()))));
  double best = tmax;
  bool found = false;
  std::vector<Node> stack;
  stack.reserve(64);
  {
    double t0 = tmin, t1 = tmax;
    const int top = int(mip.size()) - 1;
    if (node_range(top, 0, 0, t0, t1)) stack.push_back({top, 0, 0, t0, t1});
  }
  while (!stack.empty()) {
    const Node n = stack.back();
    stack.pop_back();
    if (n.t0 >= best) continue;
    const double t1 = std::min(n.t1, best);
    const Level& L = mip[n.level];
    const size_t k = size_t(n.j) * L.w + n.i;
    const double za = o.z + n.t0 * d.z, zb = o.z + t1 * d.z;
    if (std::min(za, zb) > L.node[k].hi + eps || std::max(za, zb) < L.node[k].lo - eps) continue;
    if (n.level > 0) {
      std::array<Node, 4> kids;
      int count = 0;
      for (int b = 0; b < 2; ++b)
        for (int a = 0; a < 2; ++a) {
          double c0 = n.t0, c1 = t1;
          const int ci = 2 * n.i + a, cj = 2 * n.j + b;
          if (node_range(n.level - 1, ci, cj, c0, c1)) kids[count++] = {n.level - 1, ci, cj, c0, c1};
        }
      for (int a = 1; a < count; ++a)  // farthest first, so the nearest child is popped next
        for (int b = a; b > 0 && kids[b - 1].t0 < kids[b].t0; --b) std::swap(kids[b - 1], kids[b]);
      for (int c = 0; c < count; ++c) stack.push_back(kids[c]);
      continue;
    }
    // Leaf: solve the cell's patch.
    if (cells) ++*cells;
    CellPatch cell;
    cell.load(*this, n.i, n.j);
    // F and dF/dt at t.
    auto F = [&](double t, double& dF) {
      const HeightSample h = cell.eval(*this, o.x + t * d.x, o.y + t * d.y);
      dF = d.z - (h.dx * d.x + h.dy * d.y);
      return o.z + t * d.z - h.z;
    };
    auto bisect = [&](double lo, double hi, double flo) {
      double unused;
      for (int it = 0; it < 40; ++it) {  // 2^-40 of a sub-step: far below float precision
        const double mid = 0.5 * (lo + hi), fm = F(mid, unused);
        if ((fm > 0.0) == (flo > 0.0) && fm != 0.0) { lo = mid; flo = fm; } else { hi = mid; }
      }
      return 0.5 * (lo + hi);
    };
    // The first sign change of F(t) = ray z - surface z over 8 sub-steps of the cell. Where F keeps
    // its sign at both ends but turns towards zero in between, the extremum of the cubic Hermite
    // interpolant is checked too: that finds near-tangent (grazing) crossings, which are exactly
    // the silhouettes the peak search reports.
    constexpr int kSteps = 8;
    double ta = n.t0, dfa, fa = F(ta, dfa);
    for (int s = 1; s <= kSteps; ++s) {
      const double tb = n.t0 + (t1 - n.t0) * s / kSteps;
      double dfb, fb = F(tb, dfb);
      double root = -1.0;
      if ((fa > 0.0) != (fb > 0.0) || fb == 0.0) {
        root = bisect(ta, tb, fa);
      } else if ((fa > 0.0 && dfa < 0.0 && dfb > 0.0) || (fa < 0.0 && dfa > 0.0 && dfb < 0.0)) {
        // Hermite derivative on u in [0, 1]: p'(u) = a u^2 + b u + c.
        const double h = tb - ta, m0 = dfa * h, m1 = dfb * h;
        const double qa = 6 * fa + 3 * m0 - 6 * fb + 3 * m1, qb = -6 * fa - 4 * m0 + 6 * fb - 2 * m1, qc = m0;
        double u = -1.0;
        if (std::abs(qa) < 1e-300) {
          if (qb != 0.0) u = -qc / qb;
        } else {
          const double disc = qb * qb - 4 * qa * qc;
          if (disc >= 0.0) {
            const double sq = std::sqrt(disc), u0 = (-qb - sq) / (2 * qa), u1 = (-qb + sq) / (2 * qa);
            u = (u0 > 0.0 && u0 < 1.0) ? u0 : u1;
          }
        }
        if (u > 0.0 && u < 1.0) {
          double unused;
          const double te = ta + u * h, fe = F(te, unused);
          if ((fe > 0.0) != (fa > 0.0) || fe == 0.0) root = bisect(ta, te, fa);
        }
      }
      if (root >= 0.0) {
        if (root > tmin && root < best) {
          best = root;
          found = true;
        }
        break;
      }
      ta = tb;
      fa = fb;
      dfa = dfb;
    }
  }
  if (found) t_hit = best;
  return found;
}

bool Heightfield::intersect(const Ray& ray, float& t_hit) const {
  const Mat4d& inv = world_from_local.inverse_matrix();
  const Vec3d o = Vec3d(inv * glm::dvec4(Vec3d(ray.o), 1.0)), d = glm::dmat3(inv) * Vec3d(ray.d);
  double t;
  if (!intersect_local(o, d, double(ray.tmin), double(ray.tmax), t)) return false;
  t_hit = float(t);
  if (!(t_hit > ray.tmin && t_hit < ray.tmax)) return false;  // rounding to float left the interval
  return true;
}

void Heightfield::fill_interaction(double x, double y, SurfaceInteraction& si) const {
  x = std::clamp(x, -0.5 * width, 0.5 * width);
  y = std::clamp(y, -0.5 * depth, 0.5 * depth);
  const HeightSample h = eval(x, y);
  const Vec3 p_local(float(x), float(y), float(h.z));
  si.p = world_from_local.point(p_local);
  // The root is solved to double precision; the float position and transform round a few ulps.
  si.p_error = gamma_bound(8) * (glm::abs(si.p) + Vec3(scale * (0.5f * std::max(width, depth) + std::max(std::abs(max_height()), std::abs(min_height())))));
  si.ng = si.ns = world_from_local.normal(glm::normalize(Vec3(float(-h.dx), float(-h.dy), 1.0f)));
  const double c = grid_c(x), r = grid_r(y);
  si.uv = Vec2(float(c / (nx - 1)), float(1.0 - r / (ny - 1)));
  si.bary = Vec2(float(c), float(r));
  const PatchCoords pc = patch(x, y);
  si.prim = pc.r0 * cells_x() + pc.c0;
  si.frame = Frame(si.ns);
}

void Heightfield::fill_interaction_world(const Vec3& p_world, SurfaceInteraction& si) const {
  const Vec3 pl = world_from_local.inverse().point(p_world);
  fill_interaction(pl.x, pl.y, si);
}

void Heightfield::bounds(Vec3& lo, Vec3& hi) const {
  lo = Vec3(kInfinity);
  hi = Vec3(-kInfinity);
  for (int k = 0; k < 8; ++k) {
    const Vec3 c((k & 1 ? 0.5f : -0.5f) * width, (k & 2 ? 0.5f : -0.5f) * depth, k & 4 ? max_height() : min_height());
    const Vec3 w = world_from_local.point(c);
    lo = glm::min(lo, w);
    hi = glm::max(hi, w);
  }
}

std::vector<float> Heightfield::surface_heights() const {
  std::vector<float> z(size_t(nx) * ny);
  for (int r = 0; r < ny; ++r)
    for (int c = 0; c < nx; ++c) z[size_t(r) * nx + c] = float(eval(local_x(c), local_y(r)).z);
  return z;
}

float Heightfield::area() const {
  const std::vector<float> z = surface_heights();
  double a = 0;
  const double dx = width / double(nx - 1), dy = depth / double(ny - 1);
  for (int r = 0; r + 1 < ny; ++r)
    for (int c = 0; c + 1 < nx; ++c) {
      const double z00 = z[size_t(r) * nx + c], z10 = z[size_t(r) * nx + c + 1], z01 = z[size_t(r + 1) * nx + c],
                   z11 = z[size_t(r + 1) * nx + c + 1];
      const Vec3d e1(dx, 0, z10 - z00), e2(0, dy, z01 - z00), e3(dx, 0, z11 - z01), e4(0, dy, z11 - z10);
      a += 0.5 * glm::length(glm::cross(e1, e2)) + 0.5 * glm::length(glm::cross(e3, e4));
    }
  return float(a * scale * scale);
}

namespace {
void heightfield_bounds(const RTCBoundsFunctionArguments* args) {
  const Heightfield& h = *static_cast<const Heightfield*>(args->geometryUserPtr);
  Vec3 lo, hi;
  h.bounds(lo, hi);
  // The same few-ulp widening as spheres: the surface is evaluated in double.
  const Vec3 pad = 1e-6f * (glm::abs(lo) + glm::abs(hi) + Vec3(1e-3f));
  embree_user::set_bounds(args->bounds_o, lo - pad, hi + pad);
}
}  // namespace

RTCGeometry Heightfield::create_embree_geometry(RTCDevice device) const {
  return embree_user::new_geometry(device, *this, heightfield_bounds);
}

void Heightfield::list_parameters(const std::string& id, int index, std::vector<Parameter>& out) {
  out.push_back({id + ".heights", Parameter::Kind::Heights, index, heights.data(), {size_t(ny), size_t(nx)}, true});
}

void Heightfield::validate_parameter(const Parameter& p, const std::string& where) const {
  // Heights reach height_scale * scale * |h| from the field's origin (a similarity).
  const Vec3 origin = world_from_local.point(Vec3(0.0f));
  const double reach = double(max_component(glm::abs(origin))) + double(scale) * std::max(width, depth);
  for (size_t i = 0; i < p.size(); ++i) {
    if (!std::isfinite(p.data[i]))
      throw std::invalid_argument(where + ": height at row " + std::to_string(i / nx) + ", column " + std::to_string(i % nx) +
                                  " is not finite (" + std::to_string(p.data[i]) + ")");
    if (reach + double(scale) * height_scale * std::abs(p.data[i]) > kMaxCoordinate)
      throw std::invalid_argument(where + ": height at row " + std::to_string(i / nx) + ", column " + std::to_string(i % nx) + " (" +
                                  format_values(p.data + i, 1) + ") is beyond the traceable range (|coordinate| <= 1e18)");
  }
}

void Heightfield::geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const {
  values.insert(values.end(), heights.begin(), heights.end());
  Vec3 l, h;
  bounds(l, h);
  lo = glm::min(lo, l);
  hi = glm::max(hi, h);
}

}  // namespace limn
