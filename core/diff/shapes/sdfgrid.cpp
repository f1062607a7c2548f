#include "core/diff/shapes/sdfgrid.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <unordered_map>
#include "core/math/warp.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;

const SdfGrid& grid_of(const Scene& scene, int shape) { return std::get<SdfGrid>(scene.shapes[size_t(shape)].geometry); }

Vec3d unit(int a) {
  Vec3d e(0.0);
  e[a] = 1.0;
  return e;
}

// M v for a grid-space matrix and a taped vector.
VV mul(const glm::dmat3& M, const VV& v) {
  return VV(v.x * Var(M[0][0]) + v.y * Var(M[1][0]) + v.z * Var(M[2][0]), v.x * Var(M[0][1]) + v.y * Var(M[1][1]) + v.z * Var(M[2][1]),
            v.x * Var(M[0][2]) + v.y * Var(M[1][2]) + v.z * Var(M[2][2]));
}
VV constant(const Vec3d& v) { return VV(Var(v.x), Var(v.y), Var(v.z)); }

// The corner values of voxel v on the tape ("<id>.data" slots), and the voxel's interpolant.
Trilinear<Var> tape_voxel(const DiffContext& c, const SdfGrid& g, int shape, uint32_t v) {
  const long slot = c.params.slot(Parameter::Kind::SdfData, shape);
  int i, j, k;
  g.voxel_coords(v, i, j, k);
  Var cv[8];
  for (int q = 0; q < 8; ++q) {
    const size_t idx = g.sample_index(i + (q & 1), j + ((q >> 1) & 1), k + ((q >> 2) & 1));
    cv[q] = c.in.make(g.values[idx], slot < 0 ? -1 : slot + long(idx));
  }
  return Trilinear<Var>::from_corners(cv);
}

// World point of a taped grid point, with the shape's translation parameter.
VV world_point(const DiffContext& c, const SdfGrid& g, int shape, const VV& xg) {
  return plus_translation(c.params, c.in, shape, mul(g.A, xg) + constant(g.origin));
}

// A value with the primal value removed: its derivative only (the value is exactly 0).
Var derivative_part(const Var& v) { return v - Var(v.v); }

// ---- attachment direction D = P(s) n (header comment) -------------------------------------------
struct Attachment {
  Vec3d D;
  double dD[3][3];  // dD_i / ds_j
  bool ok;
};
Attachment attachment(const SdfSample& S, const Vec3d& s) {
  Attachment a{};
  const double len = glm::length(S.grad);
  if (!(len > 0.0) || !std::isfinite(len)) return a;
  const Vec3d n = S.grad / len;
  double dn[3][3];  // dn_i / ds_j = ((I - n n^T) H)_ij / |grad f|
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double hij = 0.0;
      for (int m = 0; m < 3; ++m) hij += ((i == m ? 1.0 : 0.0) - n[i] * n[m]) * S.hess[j][m];
      dn[i][j] = hij / len;
    }
  for (int i = 0; i < 3; ++i) {
    const double w = 4.0 * s[i] * (1.0 - s[i]), dw = 4.0 - 8.0 * s[i];
    a.D[i] = w * n[i];
    for (int j = 0; j < 3; ++j) a.dD[i][j] = w * dn[i][j] + (i == j ? dw * n[i] : 0.0);
  }
  // D . n > 0 except where the point sits on a voxel edge with its normal across it (measure zero);
  // there the crease cannot keep the point and the plain normal is used.
  a.ok = glm::dot(a.D, n) > 1e-9;
  if (!a.ok) {
    for (int i = 0; i < 3; ++i) {
      a.D[i] = n[i];
      for (int j = 0; j < 3; ++j) a.dD[i][j] = dn[i][j];
    }
    a.ok = true;
  }
  return a;
}

// The root tau of f(s + tau D) nearest 0 (Newton from 0; the attached point moves little).
double solve_along(const SdfGrid& g, uint32_t v, const Vec3d& s, const Vec3d& D) {
  double tau = 0.0;
  for (int it = 0; it < 40; ++it) {
    const SdfSample S = g.eval(v, s + tau * D);
    const double df = glm::dot(S.grad, D);
    if (!(std::abs(df) > 0.0)) break;
    const double step = std::clamp(S.f / df, -0.25, 0.25);  // at most a quarter voxel per step
    tau -= step;
    if (std::abs(step) < 1e-15 * (1.0 + std::abs(tau))) break;
  }
  return std::isfinite(tau) ? tau : 0.0;
}

// Orthonormal tangents of a unit grid-space normal (Duff et al. 2017).
void tangents(const Vec3d& n, Vec3d& t1, Vec3d& t2) {
  const double sign = n.z >= 0.0 ? 1.0 : -1.0, a = -1.0 / (sign + n.z), b = n.x * n.y * a;
  t1 = Vec3d(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
  t2 = Vec3d(b, sign + n.y * n.y * a, -n.y);
}

// ---- interior parameterisation (graph along the voxel's axis) --------------------------------------
struct GraphPoint {
  Vec3d s;          // voxel-local point (its axis coordinate extrapolated outside [0,1] when invalid)
  SdfSample S;
  double fc = 0.0;  // df / d(axis), constant along the axis
  double jac = 0.0; // world area per unit (a, b)
  bool valid = false;
};
// Jacobian used for samples whose point is not on the voxel's patch, where only 1/pdf matters:
// the extrapolated one, capped at 16 times that of a patch perpendicular to the axis.
double jacobian_cap(const SdfGrid& g, int axis) { return 16.0 * std::abs(g.det_A) * glm::length(g.A_inv_t * unit(axis)); }

bool graph_point(const SdfGrid& g, const Trilinear<double>& t, int axis, double a, double b, GraphPoint& out) {
  const int ia = (axis + 1) % 3, ib = (axis + 2) % 3;
  Vec3d s(0.0);
  s[ia] = a;
  s[ib] = b;
  Vec3d s1 = s;
  s1[axis] = 1.0;
  const double f0 = t.value(s.x, s.y, s.z), f1 = t.value(s1.x, s1.y, s1.z);
  out.fc = f1 - f0;
  out.valid = false;
  if (out.fc == 0.0) {
    out.s = s;
    out.jac = jacobian_cap(g, axis);
    return false;
  }
  s[axis] = -f0 / out.fc;
  out.s = s;
  double gr[3];
  t.gradient(s.x, s.y, s.z, gr);
  out.S.f = 0.0;
  out.S.grad = Vec3d(gr[0], gr[1], gr[2]);
  double fxy, fyz, fxz;
  t.hessian(s.x, s.y, s.z, fxy, fyz, fxz);
  out.S.hess = glm::dmat3(0.0, fxy, fxz, fxy, 0.0, fyz, fxz, fyz, 0.0);
  out.jac = std::abs(g.det_A) * glm::length(g.A_inv_t * out.S.grad) / std::abs(out.fc);
  out.valid = s[axis] >= 0.0 && s[axis] <= 1.0 && std::isfinite(out.jac) && out.jac > 0.0;
  if (!out.valid) out.jac = std::min(std::isfinite(out.jac) ? out.jac : kInfinity, jacobian_cap(g, axis));
  return out.valid;
}

// World normal curvature along unit world tangent w: w^T H_w w / |grad_w f| (> 0: the surface bends
// away from the line along w, which then grazes it from outside).
double normal_curvature(const SdfGrid& g, const SdfSample& S, const Vec3d& w) {
  const Vec3d wg = g.A_inv * w;  // H_w = A^-T H A^-1
  return glm::dot(wg, S.hess * wg) / glm::length(g.A_inv_t * S.grad);
}

// Gauss-Legendre nodes and weights on [0, 1].
constexpr int kGauss = 6;
constexpr double kGaussX[kGauss] = {0.033765242898423975, 0.16939530676686776, 0.38069040695840156,
                                    0.61930959304159844,  0.83060469323313224, 0.96623475710157603};
constexpr double kGaussW[kGauss] = {0.085662246189585178, 0.18038078652406930, 0.23395696728634552,
                                    0.23395696728634552,  0.18038078652406930, 0.085662246189585178};

// ---- faces and creases ----------------------------------------------------------------------------
// The face's bilinear values G[p][q] over its two axes (d + 1, d + 2).
void face_values(const SdfGrid& g, const sdf::Face& f, double G[2][2]) {
  const int ap = (f.d + 1) % 3, aq = (f.d + 2) % 3;
  for (int p = 0; p < 2; ++p)
    for (int q = 0; q < 2; ++q) {
      int x[3] = {f.i, f.j, f.k};
      x[ap] += p;
      x[aq] += q;
      G[p][q] = g.values[g.sample_index(x[0], x[1], x[2])];
    }
}

bool face_straddles(const SdfGrid& g, const sdf::Face& f) {
  double G[2][2];
  face_values(g, f, G);
  const double lo = std::min({G[0][0], G[0][1], G[1][0], G[1][1]}), hi = std::max({G[0][0], G[0][1], G[1][0], G[1][1]});
  return lo <= 0.0 && hi >= 0.0 && !(lo == 0.0 && hi == 0.0);
}

// The face axis to parameterise its crease along: the one across which G changes with one sign.
int face_along(const SdfGrid& g, const sdf::Face& f) {
  double G[2][2];
  face_values(g, f, G);
  const int ap = (f.d + 1) % 3, aq = (f.d + 2) % 3;
  // Along p: o = q, G_q(p) linear with ends G[0][1]-G[0][0], G[1][1]-G[1][0].
  const double e[2][2] = {{G[0][1] - G[0][0], G[1][1] - G[1][0]}, {G[1][0] - G[0][0], G[1][1] - G[0][1]}};
  const double largest = std::max({std::abs(e[0][0]), std::abs(e[0][1]), std::abs(e[1][0]), std::abs(e[1][1]), 1e-300});
  auto score = [&](int c) {
    return e[c][0] * e[c][1] > 0.0 ? std::min(std::abs(e[c][0]), std::abs(e[c][1])) / largest : -1.0 + 0.5 * std::abs(e[c][0] + e[c][1]) / (std::abs(e[c][0]) + std::abs(e[c][1]) + 1e-300);
  };
  return score(0) >= score(1) ? ap : aq;
}

// The voxels on either side of a face (-1 where the grid ends).
void face_voxels(const SdfGrid& g, const sdf::Face& f, long& below, long& above) {
  int x[3] = {f.i, f.j, f.k};
  const int n[3] = {g.nx - 1, g.ny - 1, g.nz - 1};
  above = x[f.d] < n[f.d] ? long(g.voxel_index(x[0], x[1], x[2])) : -1;
  x[f.d] -= 1;
  below = x[f.d] >= 0 ? long(g.voxel_index(x[0], x[1], x[2])) : -1;
}

// Whether the crease at grid point gp (world tangent t) is a silhouette along w: both patches leave
// it on the same side of the plane through t and w (mesh edges: edge_side). Fills n_b (away from
// the patches), n_out and sin(phi).
bool crease_silhouette(const SdfGrid& g, const sdf::Face& f, const Vec3d& gp, const Vec3d& t, const Vec3d& w, Vec3d& n_b, Vec3d& n_out,
                       double& sin_phi) {
  const Vec3d nu = glm::cross(t, w);
  sin_phi = glm::length(nu);
  if (!(sin_phi > 1e-6)) return false;  // w along the crease: it is invisible in that direction
  long vox[2];
  face_voxels(g, f, vox[0], vox[1]);
  const Vec3d face_n = glm::normalize(g.A_inv_t * unit(f.d));
  int side = 0, count = 0;
  Vec3d n_sum(0.0), n_last(0.0);
  for (int q = 0; q < 2; ++q) {
    if (vox[q] < 0) continue;
    const uint32_t v = uint32_t(vox[q]);
    const SdfSample S = g.eval(v, gp - g.voxel_origin(v));
    Vec3d n;
    if (!g.world_normal(S.grad, n)) return false;
    // The patch's direction away from the crease into its voxel (below: -face_n, above: +face_n).
    Vec3d m = glm::cross(n, t);
    const double into = glm::dot(m, face_n) * (q == 1 ? 1.0 : -1.0);
    if (!(std::abs(into) > 1e-9)) return false;  // the patch lies in the face: no side to tell
    if (into < 0.0) m = -m;
    const double sd = glm::dot(m, nu);
    if (sd == 0.0) return false;
    const int s = sd > 0.0 ? 1 : -1;
    if (count > 0 && s != side) return false;
    side = s;
    ++count;
    n_sum += n;
    n_last = n;
  }
  if (count == 0) return false;
  n_b = -double(side) * nu / sin_phi;
  if (count == 2) n_out = glm::length(n_sum) > 1e-9 ? glm::normalize(n_sum) : n_b;
  else n_out = n_last * (glm::dot(n_last, w) >= 0.0 ? 1.0 : -1.0);
  return true;
}

// World length per unit r of a crease sample (1/pdf's factor): the crease's own where the point is on
// the face; where it is not, the extrapolated one capped at 16 times the face's edge length.
double crease_jacobian(const SdfGrid& g, const sdf::Face& f, int along, double r, bool valid, const sdf::CreasePoint& cp) {
  if (valid) return cp.dl_dr;
  const double cap = 16.0 * glm::length(g.A * unit(along));
  sdf::CreasePoint ext;
  if (sdf::crease_point(g, f, along, r, ext, false)) return std::min(ext.dl_dr, cap);
  return cap;
}

// Interior segment local code <-> (voxel, axis); perimeter: (face code, along axis).
int interior_local(uint32_t v, int axis) { return int(v) * 3 + axis; }
void interior_of(int local, uint32_t& v, int& axis) {
  v = uint32_t(local / 3);
  axis = local % 3;
}
int face_local(int code, int along) { return code * 3 + along; }
void face_of(const SdfGrid& g, int local, sdf::Face& f, int& along) {
  f = sdf::Face::of_code(g, local / 3);
  along = local % 3;
}

float wrap_unit(float x) {
  x -= std::floor(x);
  return std::min(x, std::nextafter(1.0f, 0.0f));
}

float probe_delta(const SdfGrid& g, const Vec3& xb) { return probe_offset(float(g.voxel_size), xb); }

// ---- projection --------------------------------------------------------------------------------
std::atomic<uint64_t> g_tried{0}, g_interior{0}, g_crease{0}, g_fallback{0}, g_failed{0};

class SdfProjector : public ShapeProjector {
 public:
  SdfProjector(const SdfGrid& g, const SegmentSpace& space, const std::vector<int>& segments) : m_g(g), m_space(space) {
    for (int seg : segments) {
      const BoundarySegment& s = space.segments()[size_t(seg)];
      if (s.part == BoundaryPart::Interior) {
        uint32_t v;
        int axis;
        interior_of(s.local, v, axis);
        m_interior[v] = seg;
      } else {
        m_perimeter[s.local / 3] = seg;
      }
    }
  }

  std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32&) const override {
    g_tried.fetch_add(1, std::memory_order_relaxed);
    auto r = march(xa, hit);
    if (!r) g_failed.fetch_add(1, std::memory_order_relaxed);
    return r;
  }

 private:
  std::optional<Projection> march(const Vec3& xa, const SurfaceInteraction& hit) const {
    const SdfGrid& g = m_g;
    const Vec3d e = g.grid_from_world(Vec3d(xa));
    uint32_t v = uint32_t(hit.prim);
    Vec3d x = g.grid_from_world(Vec3d(hit.p));
    // Gauss-Newton on r = (f, (x - e) . grad f) (both affine invariant: grid coordinates), the
    // minimum-norm step of the 2 x 3 system; at most half a voxel per step. A step that leaves the
    // voxel stops on the face it crosses: a crease there that is a silhouette from x_a is taken
    // (the nearest silhouette along the march), otherwise the march continues in the next voxel.
    bool converged = false;
    for (int it = 0, crossings = 0; it < 48 && crossings < 32; ++it) {
      const Vec3d lo = g.voxel_origin(v);
      const SdfSample S = g.eval(v, x - lo);
      const Vec3d q = x - e;
      const double r1 = S.f, r2 = glm::dot(q, S.grad);
      const double gl = glm::length(S.grad), ql = glm::length(q);
      if (!(gl > 0.0) || !(ql > 0.0)) break;
      // Converged: within 1e-9 voxels of the surface, and the view direction within 1e-9 (cosine) of tangent.
      if (std::abs(r1) <= 1e-9 * gl && std::abs(r2) <= 1e-9 * gl * ql) {
        converged = true;
        break;
      }
      const Vec3d j1 = S.grad, j2 = S.grad + S.hess * q;
      const double a11 = glm::dot(j1, j1), a12 = glm::dot(j1, j2), a22 = glm::dot(j2, j2), det = a11 * a22 - a12 * a12;
      if (!(std::abs(det) > 1e-30 * a11 * a22)) break;
      const double l1 = (a22 * r1 - a12 * r2) / det, l2 = (a11 * r2 - a12 * r1) / det;
      Vec3d step = -(l1 * j1 + l2 * j2);
      const double sl = glm::length(step);
      if (!std::isfinite(sl)) break;
      if (sl > 0.5) step *= 0.5 / sl;
      // The first face of the voxel the step crosses.
      double lambda = 1.0;
      int axis = -1, dir = 0;
      for (int a = 0; a < 3; ++a) {
        const double to = x[a] + step[a];
        if (to < lo[a] && step[a] < 0.0) {
          const double l = (lo[a] - x[a]) / step[a];
          if (l < lambda) lambda = l, axis = a, dir = -1;
        } else if (to > lo[a] + 1.0 && step[a] > 0.0) {
          const double l = (lo[a] + 1.0 - x[a]) / step[a];
          if (l < lambda) lambda = l, axis = a, dir = 1;
        }
      }
      if (axis < 0) {
        x += step;
        continue;
      }
      x += std::max(lambda, 0.0) * step;
      x[axis] = lo[axis] + (dir > 0 ? 1.0 : 0.0);
      ++crossings;
      int c[3];
      g.voxel_coords(v, c[0], c[1], c[2]);
      sdf::Face face{c[0], c[1], c[2], axis};
      if (dir > 0) (axis == 0 ? face.i : axis == 1 ? face.j : face.k) += 1;
      if (auto p = crease(face, x, xa)) {
        g_crease.fetch_add(1, std::memory_order_relaxed);
        return p;
      }
      c[axis] += dir;
      const int n[3] = {g.nx - 1, g.ny - 1, g.nz - 1};
      if (c[axis] < 0 || c[axis] >= n[axis]) break;  // the grid ends here
      v = g.voxel_index(c[0], c[1], c[2]);
    }
    const Vec3d lo = g.voxel_origin(v);
    const Vec3d s = x - lo;
    const bool inside = s.x >= -1e-9 && s.y >= -1e-9 && s.z >= -1e-9 && s.x <= 1 + 1e-9 && s.y <= 1 + 1e-9 && s.z <= 1 + 1e-9;
    const Vec3 w_orig = glm::normalize(xa - hit.p);
    if (converged && inside) {
      const Vec3 xb = Vec3(g.world_from_grid(x));
      auto seg = m_interior.find(v);
      if (seg != m_interior.end()) {
        const SdfSample S = g.eval(v, s);
        Vec3d n;
        if (g.world_normal(S.grad, n)) {
          const Vec3 nf(n);
          if (auto p = finish_projection(m_space, seg->second, xa, xb, true, w_orig - glm::dot(w_orig, nf) * nf)) {
            g_interior.fetch_add(1, std::memory_order_relaxed);
            return p;
          }
        }
      }
    }
    // Not found (section 5): the hit itself, with the tangential direction nearest the original.
    g_fallback.fetch_add(1, std::memory_order_relaxed);
    const uint32_t v0 = uint32_t(hit.prim);
    auto seg = m_interior.find(v0);
    if (seg == m_interior.end()) return std::nullopt;
    const Vec3d n = Vec3d(hit.ng);
    const Vec3 nf(n);
    const Vec3 t = w_orig - glm::dot(w_orig, nf) * nf;
    if (!(glm::length(t) > 1e-6f)) return std::nullopt;
    auto p = finish_projection(m_space, seg->second, xa, hit.p, false, glm::normalize(t));
    if (p) p->found = false;
    return p;
  }

  // The crease point on `face` nearest to grid point x (along the face's crease parameter), if it is
  // a silhouette seen from xa.
  std::optional<Projection> crease(const sdf::Face& face, const Vec3d& x, const Vec3& xa) const {
    auto seg = m_perimeter.find(face.code(m_g));
    if (seg == m_perimeter.end()) return std::nullopt;
    sdf::Face f;
    int along;
    face_of(m_g, m_space.segments()[size_t(seg->second)].local, f, along);
    const Vec3d base(f.i, f.j, f.k);
    const double r0 = std::clamp(x[along] - base[along], 0.0, 1.0);
    // The crease point at the crossing, else the nearest point of the crease (17 points along it)
    // that is a silhouette from x_a: a crease is a silhouette over a stretch only, and a march
    // that reaches the face beside that stretch would otherwise step back and forth across it.
    auto at = [&](double r) -> std::optional<Projection> {
      sdf::CreasePoint cp;
      if (!sdf::crease_point(m_g, f, along, r, cp)) return std::nullopt;
      const Vec3 xb = Vec3(m_g.world_from_grid(cp.g));
      const Vec3d w = glm::normalize(Vec3d(xa) - Vec3d(xb));
      Vec3d n_b, n_out;
      double sin_phi;
      if (!crease_silhouette(m_g, f, cp.g, cp.tangent, w, n_b, n_out, sin_phi)) return std::nullopt;
      return finish_projection(m_space, seg->second, xa, xb, true, Vec3(w));
    };
    if (auto p = at(r0)) return p;
    constexpr int kScan = 16;
    for (int k = 1; k <= kScan; ++k)  // outwards from r0, nearest first
      for (const double r : {r0 - double(k) / kScan, r0 + double(k) / kScan})
        if (r >= 0.0 && r <= 1.0)
          if (auto p = at(r)) return p;
    return std::nullopt;
  }

  const SdfGrid& m_g;
  const SegmentSpace& m_space;
  std::unordered_map<uint32_t, int> m_interior;  // voxel -> segment
  std::unordered_map<int, int> m_perimeter;      // face code -> segment
};

// One contour point of voxel v seen from e at coordinate a: its grid point, world tangent dx/da and
// the root count (a chosen root `pick` of them).
// The second number split off a 1D sample (its digits below 2^-12), for choosing among roots.
double low_digits(double u) {
  const double x = u * 4096.0;
  return x - std::floor(x);
}

struct ContourPoint {
  Vec3d s;         // voxel-local
  Vec3d tangent;   // world, unit
  double pdf = 0;  // per unit world length
};
// A point of voxel v's contour seen from e, sampled by number u. The contour is found on lines of
// the graph x(a, b) at fixed a or at fixed b (u's first half or second half, the rest of u placing
// the line), choosing uniformly among the roots on the line. Lines at one coordinate alone miss a
// contour running nearly along them (a 16^3 ball's outline was 4 % short), so both families sample
// it, combined by the balance heuristic: pdf = (p_a + p_b) / 2, p_k = 1 / (roots on the line x's
// coordinate k is held on) / |dx/dk| in world units, 0 where that line's roots miss x.
bool contour_point(const SdfGrid& g, uint32_t v, int axis, double u, const Vec3d& e, bool directional, ContourPoint& out) {
  const int held = u < 0.5 ? 0 : 1;
  const double at = std::min(held == 0 ? 2.0 * u : 2.0 * u - 1.0, std::nextafter(1.0, 0.0));
  double roots[8];
  const int count = sdf::contour_roots(g, v, axis, held, at, e, directional, roots, 8);
  if (count == 0) return false;
  const int k = std::min(count - 1, int(low_digits(at) * count));
  const Trilinear<double> t = g.voxel_function(v);
  GraphPoint gp;
  const double a = held == 0 ? at : roots[k], b = held == 0 ? roots[k] : at;
  if (!graph_point(g, t, axis, a, b, gp)) return false;
  const int ia = (axis + 1) % 3, ib = (axis + 2) % 3;
  // Tangents of the graph x(a, b) = (a, b, c(a, b)): c_a = -f_a / f_c.
  const Vec3d ta = unit(ia) - (gp.S.grad[ia] / gp.fc) * unit(axis), tb = unit(ib) - (gp.S.grad[ib] / gp.fc) * unit(axis);
  const Vec3d q = directional ? e : gp.s + g.voxel_origin(v) - e;
  // d/da of (x - e) . grad f along the surface is (x - e)^T H t (t . grad f = 0); the same for e . grad f.
  const double ga = glm::dot(q, gp.S.hess * ta), gb = glm::dot(q, gp.S.hess * tb);
  // The contour's tangent ga tb - gb ta (grid units) per unit b is that over ga, per unit a over -gb.
  const Vec3d tw = g.A * (ga * tb - gb * ta);
  const double len = glm::length(tw);
  if (!(len > 0.0) || !std::isfinite(len)) return false;
  // Density per unit length of one family at x: held coordinate uniform, one of its line's roots.
  auto family_pdf = [&](int family) {
    const double speed = std::abs(family == 0 ? gb : ga);  // |d(held coordinate)/d(grid tangent)| * len
    if (!(speed > 0.0)) return 0.0;
    double r[8];
    const double x_held = family == 0 ? a : b, x_free = family == 0 ? b : a;
    const int n = family == held ? count : sdf::contour_roots(g, v, axis, family, x_held, e, directional, r, 8);
    const double* list = family == held ? roots : r;
    bool found = false;
    for (int i = 0; i < n; ++i) found = found || std::abs(list[i] - x_free) < 1e-6;  // the bisection resolves roots far below this
    return found ? speed / (len * double(n)) : 0.0;
  };
  out.s = gp.s;
  out.tangent = tw / len;
  out.pdf = 0.5 * (family_pdf(0) + family_pdf(1));
  return out.pdf > 0.0 && std::isfinite(out.pdf);
}


}  // namespace

// ---- shared helpers -------------------------------------------------------------------------------
namespace sdf {

Face Face::of_code(const SdfGrid& g, int code) {
  const int d = code % 3;
  const size_t idx = size_t(code / 3);
  return Face{int(idx % size_t(g.nx)), int((idx / size_t(g.nx)) % size_t(g.ny)), int(idx / (size_t(g.nx) * g.ny)), d};
}

bool crease_point(const SdfGrid& g, const Face& face, int along, double r, CreasePoint& out, bool clamp_inside) {
  double G[2][2];
  face_values(g, face, G);
  const int ap = (face.d + 1) % 3;
  const bool p_along = along == ap;
  // Bilinear value at (along = r, other = o): lerp over `other` of lerps over `along`.
  auto at = [&](double rr, double o) {
    const double p = p_along ? rr : o, q = p_along ? o : rr;
    return G[0][0] * (1 - p) * (1 - q) + G[1][0] * p * (1 - q) + G[0][1] * (1 - p) * q + G[1][1] * p * q;
  };
  const double g0 = at(r, 0.0), g1 = at(r, 1.0), go = g1 - g0;
  if (go == 0.0) return false;
  out.o = -g0 / go;
  if (clamp_inside && !(out.o >= 0.0 && out.o <= 1.0)) return false;
  // dG/dr at (r, o): d/dr of the lerp.
  const double gr = (at(1.0, out.o) - at(0.0, out.o));
  out.do_dr = -gr / go;
  const int other = p_along ? (face.d + 2) % 3 : ap;
  out.g = Vec3d(face.i, face.j, face.k) + r * unit(along) + out.o * unit(other);
  const Vec3d tw = g.A * (unit(along) + out.do_dr * unit(other));
  out.dl_dr = glm::length(tw);
  if (!(out.dl_dr > 0.0) || !std::isfinite(out.dl_dr)) return false;
  out.tangent = tw / out.dl_dr;
  return true;
}

int contour_roots(const SdfGrid& g, uint32_t v, int axis, int held, double at, const Vec3d& e, bool directional, double* b_out, int max) {
  const Trilinear<double> t = g.voxel_function(v);
  const Vec3d lo = g.voxel_origin(v);
  auto value = [&](double b, bool& valid) {
    GraphPoint gp;
    graph_point(g, t, axis, held == 0 ? at : b, held == 0 ? b : at, gp);
    valid = gp.valid;
    if (gp.fc == 0.0) return std::numeric_limits<double>::quiet_NaN();
    const Vec3d q = directional ? e : gp.s + lo - e;
    return glm::dot(q, gp.S.grad);
  };
  // Sign changes over 16 sub-intervals, then bisection (roots closer than 1/16 voxel to each other
  // can be missed: a contour grazing the line a = const; docs/sdf.md).
  constexpr int N = 16;
  int count = 0;
  bool vp;
  double bp = 0.0, gp = value(0.0, vp);
  for (int k = 1; k <= N && count < max; ++k) {
    const double bn = double(k) / N;
    bool vn;
    const double gn = value(bn, vn);
    if (std::isfinite(gp) && std::isfinite(gn) && ((gp <= 0.0) != (gn <= 0.0) || gp == 0.0)) {
      double lo_b = bp, hi_b = bn, glo = gp;
      for (int it = 0; it < 60 && glo != 0.0; ++it) {
        const double m = 0.5 * (lo_b + hi_b);
        bool vm;
        const double gm = value(m, vm);
        if (!std::isfinite(gm)) break;
        if ((gm <= 0.0) == (glo <= 0.0)) lo_b = m, glo = gm;
        else hi_b = m;
      }
      const double root = glo == 0.0 ? lo_b : 0.5 * (lo_b + hi_b);
      bool vr;
      const double gr = value(root, vr);
      // A pole of the graph (f_c = 0 inside the voxel) also flips the sign: not a root.
      if (vr && std::abs(gr) <= 1e-6 * (std::abs(gp) + std::abs(gn)) + 1e-300 && (count == 0 || root > b_out[count - 1])) b_out[count++] = root;
    }
    bp = bn;
    gp = gn;
  }
  return count;
}

ProjectionStats projection_stats() {
  return {g_tried.load(), g_interior.load(), g_crease.load(), g_fallback.load(), g_failed.load()};
}
void reset_projection_stats() {
  for (auto* c : {&g_tried, &g_interior, &g_crease, &g_fallback, &g_failed}) c->store(0);
}

}  // namespace sdf

// ---- attached points ------------------------------------------------------------------------------
VV SurfaceDiff<SdfGrid>::position(const DiffContext& c, const SdfGrid& g, const SurfacePoint& sp) {
  const uint32_t v = uint32_t(sp.prim);
  const Vec3d lo = g.voxel_origin(v);
  const Vec3d s0 = g.grid_of_local(g.local_of(sp.uv, sp.bary)) - lo;
  const Attachment at = attachment(g.eval(v, s0), s0);
  if (!at.ok) return world_point(c, g, sp.shape, constant(s0 + lo));  // |grad f| = 0: nothing to follow
  const double tau = solve_along(g, v, s0, at.D);
  const Vec3d x = s0 + tau * at.D;
  // One taped Newton step at the root: value tau, derivative -(df/dtheta) / (grad f . D).
  const Trilinear<Var> tf = tape_voxel(c, g, sp.shape, v);
  const Var fx = tf.value(x.x, x.y, x.z);
  const double den = glm::dot(g.eval(v, x).grad, at.D);
  const Var t = Var(tau) - derivative_part(fx) / Var(den);
  return world_point(c, g, sp.shape, constant(lo + s0) + constant(at.D) * t);
}

DiffVertex SurfaceDiff<SdfGrid>::attach(const DiffContext& c, const SdfGrid& g, const SurfacePoint& sp) {
  DiffVertex out;
  const uint32_t v = uint32_t(sp.prim);
  const Vec3d lo = g.voxel_origin(v);
  const Vec3d s0 = g.grid_of_local(g.local_of(sp.uv, sp.bary)) - lo;
  const Attachment at0 = attachment(g.eval(v, s0), s0);
  const Trilinear<Var> tf = tape_voxel(c, g, sp.shape, v);
  const double tau = at0.ok ? solve_along(g, v, s0, at0.D) : 0.0;
  const Vec3d x = s0 + tau * at0.D;  // the root (s0 itself at the primal parameters, up to rounding)
  const SdfSample S = g.eval(v, x);
  const Attachment at = attachment(S, x);
  const double gl = glm::length(S.grad);
  if (!at.ok || !(gl > 0.0)) {  // |grad f| = 0: a fixed point with the primal normal
    out.p = world_point(c, g, sp.shape, constant(lo + x));
    out.ng = out.ns = constant(Vec3d(sp.n));
    out.u = Var(sp.uv.x);
    out.v = Var(sp.uv.y);
    return out;
  }
  const double k = glm::dot(S.grad, at.D);
  const Var fx = tf.value(x.x, x.y, x.z);
  const Var df = derivative_part(fx);
  const Var T = -df / Var(k);  // tau's change (value 0)
  const VV xg = constant(lo + x) + constant(at.D) * T;
  out.p = world_point(c, g, sp.shape, xg);
  // Normal: the gradient of the taped interpolant at the moving point.
  const VV xs = xg - constant(lo);
  Var gr[3];
  tf.gradient(xs.x, xs.y, xs.z, gr);
  out.ng = out.ns = normalize(mul(g.A_inv_t, VV(gr[0], gr[1], gr[2])));
  // Area Jacobian: the map u -> u + tau(u) D(u) of the primal surface; its tangents t_i gain
  // (d_i tau) D + tau (dD/ds) t_i, with d_i tau = -(dgrad f . t_i) / k + df (grad k . t_i) / k^2 and
  // grad k = H D + (dD/ds)^T grad f.
  Vec3d t1, t2;
  tangents(S.grad / gl, t1, t2);
  Var dgrad[3];
  tf.gradient(x.x, x.y, x.z, dgrad);
  const VV dg(derivative_part(dgrad[0]), derivative_part(dgrad[1]), derivative_part(dgrad[2]));
  Vec3d grad_k = S.hess * at.D;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) grad_k[j] += S.grad[i] * at.dD[i][j];
  auto moved_tangent = [&](const Vec3d& ti) {
    const Var di_tau = -dot(dg, constant(ti)) / Var(k) + df * Var(glm::dot(grad_k, ti) / (k * k));
    Vec3d dD_ti(0.0);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) dD_ti[i] += at.dD[i][j] * ti[j];
    return mul(g.A, constant(ti) + constant(at.D) * di_tau + constant(dD_ti) * T);
  };
  const double area0 = glm::length(glm::cross(g.A * t1, g.A * t2));
  out.jacobian = length(cross(moved_tangent(t1), moved_tangent(t2))) / Var(area0);
  out.u = xg.x / Var(double(g.nx - 1));
  out.v = xg.y / Var(double(g.ny - 1));
  return out;
}

DiffVertex SurfaceDiff<SdfGrid>::ray_hit(const DiffContext& c, const SdfGrid& g, const VV& o, const VV& d, const SurfaceInteraction& si,
                                         const Ray&) {
  DiffVertex out;
  const uint32_t v = uint32_t(si.prim);
  const Vec3d lo = g.voxel_origin(v);
  const double t0 = si.t;
  const VV origin = plus_translation(c.params, c.in, si.shape, constant(g.origin));
  auto grid_of = [&](const VV& p) { return mul(g.A_inv, p - origin); };
  const Trilinear<Var> tf = tape_voxel(c, g, si.shape, v);
  const VV s_ray = grid_of(o + d * Var(t0)) - constant(lo);
  const Var f = tf.value(s_ray.x, s_ray.y, s_ray.z);
  const Vec3d s_val(s_ray.x.v, s_ray.y.v, s_ray.z.v);
  const SdfSample S = g.eval(v, s_val);
  const Vec3d dg = g.A_inv * Vec3d(d.x.v, d.y.v, d.z.v);
  const double den = glm::dot(S.grad, dg);
  // One taped Newton step along the ray from the primal root: t = t0 - f / (grad f . d) (f = 0 up to
  // rounding at the primal parameters; elsewhere the step follows the moved surface to first order).
  const Var t = std::abs(den) > 0.0 ? Var(t0) - f / Var(den) : Var(t0);
  out.p = o + d * t;
  Vec3d n;
  if (!g.world_normal(S.grad, n)) {
    out.ng = out.ns = constant(Vec3d(si.ng));
  } else {
    const VV xs = grid_of(out.p) - constant(lo);
    Var gr[3];
    tf.gradient(xs.x, xs.y, xs.z, gr);
    out.ng = out.ns = normalize(mul(g.A_inv_t, VV(gr[0], gr[1], gr[2])));
  }
  const VV xg = grid_of(out.p);
  out.u = xg.x / Var(double(g.nx - 1));
  out.v = xg.y / Var(double(g.ny - 1));
  return out;
}

// ---- boundary segments ------------------------------------------------------------------------------
namespace {
void append_segments(const SdfGrid& g, int shape, bool moving, BoundaryPart part, std::vector<BoundarySegment>& out) {
  if (part == BoundaryPart::Interior) {
    for (const SdfGrid::Prim& p : g.prims) {
      const Trilinear<double> t = g.voxel_function(p.voxel);
      // Measure: 2 pi times the integral of the sampling Jacobian over the (a, b) square (Gauss-
      // Legendre; exact up to rounding where f_c keeps its sign over the voxel, as the axis choice
      // aims for). Weight: the part on the patch times a typical curvature, plus 10 % of the
      // measure, so every patch keeps a share (and the float sample space resolves its square finely
      // enough: at 1 %, the sample -> invert round trip of a patch clipped to a corner lost 3e-5).
      double measure = 0.0, on_patch = 0.0, kappa = 0.0;
      for (int i = 0; i < kGauss; ++i)
        for (int j = 0; j < kGauss; ++j) {
          GraphPoint gp;
          const bool valid = graph_point(g, t, p.axis, kGaussX[i], kGaussX[j], gp);
          const double w = kGaussW[i] * kGaussW[j];
          measure += w * gp.jac;
          if (!valid) continue;
          on_patch += w * gp.jac;
          Vec3d n;
          if (kappa == 0.0 && g.world_normal(gp.S.grad, n)) {
            Vec3d t1, t2;
            tangents(n, t1, t2);
            kappa = std::max(std::abs(normal_curvature(g, gp.S, t1)), std::abs(normal_curvature(g, gp.S, t2)));
          }
        }
      measure *= 2.0 * M_PI;
      const double typical = std::max(kappa, 0.1 / g.voxel_size);
      const double weight = (2.0 * M_PI * on_patch + 0.1 * measure) * typical;
      out.push_back({shape, interior_local(p.voxel, p.axis), float(measure), float(weight), moving, part});
    }
    return;
  }
  // Perimeter: every face a patch touches whose values straddle zero, once.
  std::vector<int> codes;
  for (const SdfGrid::Prim& p : g.prims) {
    int c[3];
    g.voxel_coords(p.voxel, c[0], c[1], c[2]);
    for (int d = 0; d < 3; ++d)
      for (int up = 0; up < 2; ++up) {
        int x[3] = {c[0], c[1], c[2]};
        x[d] += up;
        codes.push_back(sdf::Face{x[0], x[1], x[2], d}.code(g));
      }
  }
  std::sort(codes.begin(), codes.end());
  codes.erase(std::unique(codes.begin(), codes.end()), codes.end());
  constexpr int kLine = 8;  // Gauss-Legendre on [0, 1]
  static const double X8[kLine] = {0.019855071751231856, 0.10166676129318664, 0.23723379504183550, 0.40828267875217511,
                                   0.59171732124782489,  0.76276620495816450, 0.89833323870681336, 0.98014492824876814};
  static const double W8[kLine] = {0.050614268145188129, 0.11119051722668724, 0.15685332293894364, 0.18134189168918100,
                                   0.18134189168918100,  0.15685332293894364, 0.11119051722668724, 0.050614268145188129};
  for (int code : codes) {
    const sdf::Face f = sdf::Face::of_code(g, code);
    if (!face_straddles(g, f)) continue;
    const int along = face_along(g, f);
    double measure = 0.0, on_face = 0.0, sharp = -1.0;
    for (int i = 0; i < kLine; ++i) {
      sdf::CreasePoint cp;
      const bool valid = sdf::crease_point(g, f, along, X8[i], cp);
      const double L = crease_jacobian(g, f, along, X8[i], valid, cp);
      measure += W8[i] * L;
      if (!valid) continue;
      on_face += W8[i] * L;
      if (sharp < 0.0) {  // the dihedral angle between the two patches (pi for an open edge)
        long vox[2];
        face_voxels(g, f, vox[0], vox[1]);
        Vec3d n[2];
        int count = 0;
        for (int q = 0; q < 2; ++q)
          if (vox[q] >= 0 && g.world_normal(g.eval(uint32_t(vox[q]), cp.g - g.voxel_origin(uint32_t(vox[q]))).grad, n[count])) ++count;
        sharp = count == 2 ? std::acos(std::clamp(glm::dot(n[0], n[1]), -1.0, 1.0)) / M_PI : 1.0;
      }
    }
    measure *= 4.0 * M_PI;
    const double weight = 4.0 * M_PI * on_face * std::max(sharp, 0.0) + 0.01 * measure;
    out.push_back({shape, face_local(code, along), float(measure), float(weight), moving, part});
  }
}
}  // namespace

void BoundarySegments<SdfGrid>::append(const Scene&, const SdfGrid& g, int shape, bool moving, BoundaryPart part,
                                       std::vector<BoundarySegment>& out) {
  append_segments(g, shape, moving, part, out);
}

bool BoundarySegments<SdfGrid>::sample(const Scene&, const SdfGrid& g, const BoundarySegment& s, float f, float u1, float u2,
                                       float pdf_select, BoundaryPoint& out) {
  if (s.part == BoundaryPart::Interior) {
    uint32_t v;
    int axis;
    interior_of(s.local, v, axis);
    GraphPoint gp;
    const bool valid = graph_point(g, g.voxel_function(v), axis, f, u1, gp);
    out.pdf = float(double(pdf_select) / (2.0 * M_PI * gp.jac));
    if (!valid) return false;
    Vec3d n;
    if (!g.world_normal(gp.S.grad, n)) return false;
    const Frame frame{Vec3(n)};
    const float phi = 2.0f * kPi * u2;
    const Vec3 w = std::cos(phi) * frame.s + std::sin(phi) * frame.t;
    const double kappa = normal_curvature(g, gp.S, Vec3d(w));
    if (!(kappa > 0.0) || !std::isfinite(kappa)) return false;  // the line along w enters the surface: no silhouette
    out.xb = Vec3(g.world_from_grid(g.voxel_origin(v) + gp.s));
    out.w = w;
    out.n_b = Vec3(n);  // growing along n covers the background
    out.n_out = Vec3(n);
    out.jacobian = float(kappa);
    out.delta = probe_delta(g, out.xb);
    out.param = Vec3(f, u1, 0.0f);
    return std::isfinite(out.pdf) && out.pdf > 0.0f;
  }
  sdf::Face face;
  int along;
  face_of(g, s.local, face, along);
  sdf::CreasePoint cp;
  const bool valid = sdf::crease_point(g, face, along, f, cp);
  const double L = crease_jacobian(g, face, along, f, valid, cp);
  out.pdf = float(double(pdf_select) / L * warp::square_to_uniform_sphere_pdf());
  if (!valid) return false;
  const Vec3 w = warp::square_to_uniform_sphere(Vec2(u1, u2));
  Vec3d n_b, n_out;
  double sin_phi;
  if (!crease_silhouette(g, face, cp.g, cp.tangent, Vec3d(w), n_b, n_out, sin_phi)) return false;
  out.xb = Vec3(g.world_from_grid(cp.g));
  out.w = w;
  out.n_b = Vec3(n_b);
  out.n_out = Vec3(n_out);
  out.jacobian = float(sin_phi);
  out.delta = probe_delta(g, out.xb);
  out.param = Vec3(f, float(cp.o), 0.0f);
  return true;
}

Vec3 BoundarySegments<SdfGrid>::invert(const Scene&, const SdfGrid& g, const BoundarySegment& s, const Vec3& xb, const Vec3& w) {
  const float below_one = std::nextafter(1.0f, 0.0f);
  if (s.part == BoundaryPart::Interior) {
    uint32_t v;
    int axis;
    interior_of(s.local, v, axis);
    const Vec3d sl = g.grid_from_world(Vec3d(xb)) - g.voxel_origin(v);
    const float a = std::clamp(float(sl[(axis + 1) % 3]), 0.0f, below_one), b = std::clamp(float(sl[(axis + 2) % 3]), 0.0f, below_one);
    // The normal exactly as sample() finds it at (a, b).
    GraphPoint gp;
    graph_point(g, g.voxel_function(v), axis, a, b, gp);
    Vec3d n;
    if (!g.world_normal(gp.S.grad, n)) return Vec3(a, b, 0.0f);
    const Frame frame{Vec3(n)};
    const float phi = std::atan2(glm::dot(w, frame.t), glm::dot(w, frame.s));
    return Vec3(a, b, wrap_unit(phi * kInvTwoPi));
  }
  sdf::Face face;
  int along;
  face_of(g, s.local, face, along);
  const double r = g.grid_from_world(Vec3d(xb))[along] - Vec3d(face.i, face.j, face.k)[along];
  const Vec2 d = warp::uniform_sphere_to_square(w);
  return Vec3(std::clamp(float(r), 0.0f, below_one), d.x, d.y);
}

bool BoundarySegments<SdfGrid>::sample_delta(const Scene&, const SdfGrid& g, const BoundarySegment& s, float f, float pdf_select,
                                             const Emitter& light, BoundaryPoint& out) {
  const auto* point = std::get_if<PointEmitter>(&light.model);
  const auto* directional = std::get_if<DirectionalEmitter>(&light.model);
  if (!point && !directional) return false;
  if (s.part == BoundaryPart::Interior) {
    uint32_t v;
    int axis;
    interior_of(s.local, v, axis);
    // A point of the contour seen from the light (contour_point); the boundary curve's measure is
    // dl, its Jacobian sin(phi) between the contour and w.
    const Vec3d e = point ? g.grid_from_world(Vec3d(point->position)) : g.A_inv * Vec3d(directional->direction);
    ContourPoint cp;
    if (!contour_point(g, v, axis, f, e, directional != nullptr, cp)) return false;
    const Vec3d xg = g.voxel_origin(v) + cp.s;
    const Vec3 xb = Vec3(g.world_from_grid(xg));
    const Vec3 wl = point ? xb - point->position : directional->direction;
    if (!(glm::length(wl) > 0.0f)) return false;
    const Vec3d w = glm::normalize(Vec3d(wl));
    const SdfSample S = g.eval(v, cp.s);
    Vec3d n;
    if (!g.world_normal(S.grad, n)) return false;
    const double kappa = normal_curvature(g, S, w);
    if (!(kappa > 0.0)) return false;  // an inner contour: the light's ray passes through the solid
    const double sin_phi = glm::length(glm::cross(cp.tangent, w));
    if (!(sin_phi > 1e-6)) return false;
    out.xb = xb;
    out.w = Vec3(w);
    out.n_b = Vec3(n);
    out.n_out = Vec3(n);
    out.jacobian = float(sin_phi);
    out.delta = probe_delta(g, xb);
    out.param = Vec3(float(cp.s[(axis + 1) % 3]), float(cp.s[(axis + 2) % 3]), 0.0f);  // (a, b): attached_point
    out.pdf = float(double(pdf_select) * cp.pdf);
    return std::isfinite(out.pdf) && out.pdf > 0.0f;
  }
  sdf::Face face;
  int along;
  face_of(g, s.local, face, along);
  sdf::CreasePoint cp;
  if (!sdf::crease_point(g, face, along, f, cp)) return false;
  const Vec3 xb = Vec3(g.world_from_grid(cp.g));
  const Vec3 wl = point ? xb - point->position : directional->direction;
  if (!(glm::length(wl) > 0.0f)) return false;
  Vec3d n_b, n_out;
  double sin_phi;
  if (!crease_silhouette(g, face, cp.g, cp.tangent, glm::normalize(Vec3d(wl)), n_b, n_out, sin_phi)) return false;
  out.xb = xb;
  out.w = glm::normalize(wl);
  out.n_b = Vec3(n_b);
  out.n_out = Vec3(n_out);
  out.jacobian = float(sin_phi);
  out.delta = probe_delta(g, xb);
  out.param = Vec3(f, float(cp.o), 0.0f);
  out.pdf = float(double(pdf_select) / cp.dl_dr);
  return true;
}

VV BoundarySegments<SdfGrid>::attached_point(const DiffContext& c, const SdfGrid& g, const BoundarySegment& s, const BoundaryPoint& p) {
  if (s.part == BoundaryPart::Interior) {
    // Fixed (a, b) on the voxel's axis: c = -f(a, b, 0) / (f(a, b, 1) - f(a, b, 0)) on the tape
    // (f is linear along the axis), so x_b moves along the axis with normal velocity -(df/dtheta) / |grad f|.
    uint32_t v;
    int axis;
    interior_of(s.local, v, axis);
    const Trilinear<Var> tf = tape_voxel(c, g, s.shape, v);
    Vec3d s0(0.0);
    s0[(axis + 1) % 3] = p.param.x;
    s0[(axis + 2) % 3] = p.param.y;
    Vec3d s1 = s0;
    s1[axis] = 1.0;
    const Var f0 = tf.value(s0.x, s0.y, s0.z), f1 = tf.value(s1.x, s1.y, s1.z);
    const Var cc = -f0 / (f1 - f0);
    VV xg = constant(g.voxel_origin(v) + s0);
    (axis == 0 ? xg.x : axis == 1 ? xg.y : xg.z) += cc;
    return world_point(c, g, s.shape, xg);
  }
  // Fixed r along the crease: the other face coordinate solved on the tape (the crease moves in the face).
  sdf::Face face;
  int along;
  face_of(g, s.local, face, along);
  long vox[2];
  face_voxels(g, face, vox[0], vox[1]);
  const uint32_t v = uint32_t(vox[1] >= 0 ? vox[1] : vox[0]);
  const Trilinear<Var> tf = tape_voxel(c, g, s.shape, v);
  const Vec3d lo = g.voxel_origin(v);
  const int other = along == (face.d + 1) % 3 ? (face.d + 2) % 3 : (face.d + 1) % 3;
  Vec3d q0 = Vec3d(face.i, face.j, face.k) + double(p.param.x) * unit(along) - lo;
  Vec3d q1 = q0 + unit(other);
  const Var g0 = tf.value(q0.x, q0.y, q0.z), g1 = tf.value(q1.x, q1.y, q1.z);
  const Var o = -g0 / (g1 - g0);
  VV xg = constant(q0 + lo);
  (other == 0 ? xg.x : other == 1 ? xg.y : xg.z) += o;
  return world_point(c, g, s.shape, xg);
}

std::unique_ptr<ShapeProjector> BoundarySegments<SdfGrid>::projector(const Scene&, const SdfGrid& g, const SegmentSpace& space, int,
                                                                     const std::vector<int>& segments, MeshProjection) {
  return std::make_unique<SdfProjector>(g, space, segments);
}

// ---- camera silhouettes ------------------------------------------------------------------------------
namespace {
// Whether both radiance probes of the primary term (core/diff/terms/primary.cpp: film offsets of
// 1e-3 px either side of the curve; here 2e-3 px, so that no probe pair straddling the outline
// slips through) see the crease's own patches, within half a voxel of the crease point.
bool probes_see_patches(const Scene& scene, const SdfGrid& g, int shape, const Vec3d& xw, const Vec3d& tangent) {
  const CameraView view(scene.camera);
  glm::dvec2 s;
  if (!view.film_of(ad::V3<double>(xw.x, xw.y, xw.z), s)) return false;
  const glm::dvec2 ds = view.proj.film_derivative(view.proj.to_camera(ad::V3<double>(xw.x, xw.y, xw.z)),
                                                  ad::V3<double>(tangent.x, tangent.y, tangent.z));
  const double len = glm::length(ds);
  if (!(len > 0.0)) return false;
  const glm::dvec2 n(-ds.y / len, ds.x / len);
  for (const double side : {-2e-3, 2e-3}) {
    SurfaceInteraction si;
    if (!scene.intersect(scene.camera.generate_ray(Vec2(s + side * n)), si)) return false;
    if (si.shape != shape || !(glm::length(Vec3d(si.p) - xw) < 0.5 * g.voxel_size)) return false;
  }
  return true;
}
}  // namespace


// Curve codes: a crease is its segment code (>= 0), a voxel's contour -1 - (voxel * 3 + axis).
void CameraSilhouettes<SdfGrid>::append(const Scene&, const SdfGrid& g, int shape, const CameraView& view, std::vector<SilhouetteCurve>& out,
                                        uint64_t& skipped) {
  const Vec3d eye_w(view.eye.x, view.eye.y, view.eye.z);
  const Vec3d e = g.grid_from_world(eye_w);
  auto film = [&](const Vec3d& gp, glm::dvec2& s) {
    const Vec3d w = g.world_from_grid(gp);
    return view.film_of(ad::V3<double>(w.x, w.y, w.z), s);
  };
  // Creases: projected length from 4 chords.
  std::vector<BoundarySegment> faces;
  append_segments(g, shape, true, BoundaryPart::Perimeter, faces);
  for (const BoundarySegment& seg : faces) {
    sdf::Face face;
    int along;
    face_of(g, seg.local, face, along);
    double len = 0.0;
    bool any = false, behind = false;
    glm::dvec2 prev(0.0);
    bool have_prev = false;
    for (int k = 0; k <= 4; ++k) {
      sdf::CreasePoint cp;
      if (!sdf::crease_point(g, face, along, k / 4.0, cp)) {
        have_prev = false;
        continue;
      }
      glm::dvec2 s;
      if (!film(cp.g, s)) {
        behind = true;
        break;
      }
      if (have_prev) len += glm::length(s - prev);
      prev = s;
      have_prev = any = true;
    }
    if (behind) {
      ++skipped;  // limitation (as mesh edges): curves crossing the near plane are skipped and counted
      continue;
    }
    if (!any) len = 0.0;
    // Every crease keeps a share (a short piece may lie between the chord points).
    out.push_back({shape, seg.local, float(len + 1e-3)});
  }
  // Contours: voxels whose 8 x 8 sampled patch changes the sign of (x - eye) . grad f, weighted by
  // the voxel's projected size; the others by 1 % of it (a contour may pass between samples).
  for (const SdfGrid::Prim& p : g.prims) {
    const Trilinear<double> t = g.voxel_function(p.voxel);
    const Vec3d lo = g.voxel_origin(p.voxel);
    int pos = 0, neg = 0;
    for (int i = 0; i < 8; ++i)
      for (int j = 0; j < 8; ++j) {
        GraphPoint gp;
        if (!graph_point(g, t, p.axis, (i + 0.5) / 8.0, (j + 0.5) / 8.0, gp)) continue;
        const double v = glm::dot(gp.s + lo - e, gp.S.grad);
        pos += v > 0.0;
        neg += v < 0.0;
      }
    glm::dvec2 s0, s1;
    if (!film(lo, s0) || !film(lo + Vec3d(1.0), s1)) {
      ++skipped;
      continue;
    }
    const double size = glm::length(s1 - s0) + 1e-3;
    out.push_back({shape, -1 - interior_local(p.voxel, p.axis), float(pos > 0 && neg > 0 ? size : 0.01 * size)});
  }
}

bool CameraSilhouettes<SdfGrid>::point(const DiffContext& c, const SdfGrid& g, const SilhouetteCurve& curve, float u,
                                       const ad::V3<double>& eye, VV& P, ad::V3<double>& dP, double& pdf_param) {
  if (curve.local >= 0) {
    // A crease point at r = u; it moves in its face: by -(df/dtheta) / (grad f . m) along the
    // unit in-face direction m across the crease.
    sdf::Face face;
    int along;
    face_of(g, curve.local, face, along);
    sdf::CreasePoint cp;
    if (!sdf::crease_point(g, face, along, u, cp)) return false;
    long vox[2];
    face_voxels(g, face, vox[0], vox[1]);
    const uint32_t v = uint32_t(vox[1] >= 0 ? vox[1] : vox[0]);
    const Vec3d lo = g.voxel_origin(v);
    const SdfSample S = g.eval(v, cp.g - lo);
    const Vec3d face_n = glm::normalize(g.A_inv_t * unit(face.d));
    const Vec3d m = glm::normalize(glm::cross(face_n, cp.tangent));
    const double gm = glm::dot(g.A_inv_t * S.grad, m);
    if (!(std::abs(gm) > 0.0)) return false;
    // A crease that is not a silhouette from the eye has only its shading jump. Where the outline
    // passes within the probe offset of it (a patch beside it seen almost edge-on), the probes would
    // see the background as well and count that stretch of the outline a second time (the contours
    // and silhouette creases count it): such samples are dropped. Before, a 32^3 ball's outline was
    // 10 % high and a lit SDF's primary term 30 % high against finite differences.
    {
      const Vec3d xw = g.world_from_grid(cp.g);
      const Vec3d to_eye = glm::normalize(Vec3d(eye.x, eye.y, eye.z) - xw);
      Vec3d n_b, n_out;
      double sin_phi;
      if (!crease_silhouette(g, face, cp.g, cp.tangent, to_eye, n_b, n_out, sin_phi) &&
          !probes_see_patches(c.scene, g, curve.shape, xw, cp.tangent))
        return false;
    }
    const Trilinear<Var> tf = tape_voxel(c, g, curve.shape, v);
    const Vec3d sl = cp.g - lo;
    const Var df = derivative_part(tf.value(sl.x, sl.y, sl.z));
    P = world_point(c, g, curve.shape, constant(cp.g)) + constant(m) * (-df / Var(gm));
    const Vec3d dw = cp.tangent * cp.dl_dr;
    dP = ad::V3<double>(dw.x, dw.y, dw.z);
    pdf_param = 1.0;
    return true;
  }
  uint32_t v;
  int axis;
  interior_of(-1 - curve.local, v, axis);
  const Vec3d e = g.grid_from_world(Vec3d(eye.x, eye.y, eye.z));
  ContourPoint cp;
  if (!contour_point(g, v, axis, u, e, false, cp)) return false;
  const SdfSample S = g.eval(v, cp.s);
  Vec3d n;
  if (!g.world_normal(S.grad, n)) return false;
  // The contour of a smooth patch moves on the film as the surface moves along its normal there.
  const Trilinear<Var> tf = tape_voxel(c, g, curve.shape, v);
  const Var df = derivative_part(tf.value(cp.s.x, cp.s.y, cp.s.z));
  P = world_point(c, g, curve.shape, constant(g.voxel_origin(v) + cp.s)) + constant(n) * (-df / Var(glm::length(g.A_inv_t * S.grad)));
  dP = ad::V3<double>(cp.tangent.x, cp.tangent.y, cp.tangent.z);  // per unit length, the measure of cp.pdf
  pdf_param = cp.pdf;
  return true;
}

}  // namespace limn
