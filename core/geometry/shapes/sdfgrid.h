// Signed-distance grid (Mitsuba 3's `sdfgrid`): samples of a signed function f on the corners of a
// regular grid over the unit cube [0,1]^3 of its local frame, interpolated trilinearly; the surface
// is the zero set, f > 0 outside (the normal, grad f / |grad f|, points there).
//
// Frames: sample (x, y, z) of the nz x ny x nx array (indexed [z][y][x], as Mitsuba) sits at local
// (x / (nx - 1), y / (ny - 1), z / (nz - 1)): corner samples, no half-voxel offset. Most code works
// in grid coordinates g = (x, y, z) in sample units, where voxel (i, j, k) is the unit cube at
// (i, j, k); world = A g + origin with A = to_world's linear part times diag(1 / (n - 1)). A may be
// any invertible affine map (non-uniform scales included): every condition below that involves
// directions (tangency, the side of a plane) is affine invariant, and lengths, areas, normals and
// curvatures are mapped with A explicitly.
//
// Intersection: per voxel, f along the ray is a cubic in t (Hansson-Soderlund, Evans, Akenine-Moller,
// "Ray Tracing of Signed Distance Function Grids", JCGT 11(3), 2022); the roots of its derivative
// split the ray's span in the voxel into monotone pieces (Marmitt, Kleer, Wald, Friedrich,
// Slusallek, "Fast and Accurate Ray-Voxel Intersection Techniques for Iso-Surface Ray Tracing",
// VMV 2004), and the first piece with a sign change holds the first root, refined by bracketed
// Newton iterations to double precision. Only voxels the surface passes through are Embree user
// primitives, each bounded by the sub-cells (4 x 4 x 4 per voxel) whose corner values straddle
// zero: a trilinear function takes its extremes over a box at the box's corners, so those
// sub-cells hold the whole patch.
#pragma once
#include <embree3/rtcore.h>
#include <array>
#include <cstdint>
#include <string>
#include <vector>
#include "core/geometry/parameter.h"
#include "core/geometry/ray.h"
#include "core/geometry/shapes/mesh.h"
#include "core/geometry/transform.h"

namespace limn {

// The trilinear interpolant of one voxel in monomial form, f = k0 + k1 x + k2 y + k3 z + k4 xy +
// k5 yz + k6 xz + k7 xyz over the voxel's local coordinates s in [0,1]^3. T = double, or the AD
// scalar of the derivative code (corner values on the tape).
template <typename T>
struct Trilinear {
  T k[8];
  // c[i]: corner (i & 1, (i >> 1) & 1, (i >> 2) & 1).
  static Trilinear from_corners(const T c[8]) {
    Trilinear t;
    t.k[0] = c[0];
    t.k[1] = c[1] - c[0];
    t.k[2] = c[2] - c[0];
    t.k[3] = c[4] - c[0];
    t.k[4] = c[3] - c[2] - c[1] + c[0];
    t.k[5] = c[6] - c[4] - c[2] + c[0];
    t.k[6] = c[5] - c[4] - c[1] + c[0];
    t.k[7] = c[7] - c[6] - c[5] - c[3] + c[1] + c[2] + c[4] - c[0];
    return t;
  }
  template <typename S>
  T value(const S& x, const S& y, const S& z) const {
    return k[0] + k[1] * x + k[2] * y + k[3] * z + k[4] * x * y + k[5] * y * z + k[6] * x * z + k[7] * x * y * z;
  }
  template <typename S>
  void gradient(const S& x, const S& y, const S& z, T g[3]) const {
    g[0] = k[1] + k[4] * y + k[6] * z + k[7] * y * z;
    g[1] = k[2] + k[4] * x + k[5] * z + k[7] * x * z;
    g[2] = k[3] + k[5] * y + k[6] * x + k[7] * x * y;
  }
  // The Hessian's off-diagonal entries (its diagonal is zero): f_xy, f_yz, f_xz.
  template <typename S>
  void hessian(const S& x, const S& y, const S& z, T& fxy, T& fyz, T& fxz) const {
    fxy = k[4] + k[7] * z;
    fyz = k[5] + k[7] * x;
    fxz = k[6] + k[7] * y;
  }
};

// Grid-space quantities of one voxel at a point, in double.
struct SdfSample {
  double f = 0.0;
  Vec3d grad{0.0};
  glm::dmat3 hess{0.0};  // symmetric, zero diagonal
};

struct SdfGrid {
  static constexpr const char* kind_name = "sdfgrid";
  // Not an area emitter (the loader refuses one): nothing samples points on it.
  static constexpr bool can_emit = false;

  int nx = 0, ny = 0, nz = 0;     // samples per axis (>= 2 each)
  std::vector<float> values;      // nz * ny * nx, [z][y][x]: "<id>.data"
  Transform world_from_local;     // places the unit cube

  // Derived (build_derived, update_voxels): world = A g + origin.
  glm::dmat3 A{1.0}, A_inv{1.0}, A_inv_t{1.0};
  Vec3d origin{0.0};
  double det_A = 1.0;
  double voxel_size = 1.0;        // cube root of |det A|: a typical voxel edge in world units

  // A voxel the surface passes through: an Embree primitive.
  struct Prim {
    uint32_t voxel;               // i + (nx - 1) (j + (ny - 1) k)
    uint8_t axis;                 // the interior parameterisation's axis (voxel_axis)
    float lo[3], hi[3];           // grid-space box of the patch
  };
  std::vector<Prim> prims;        // sorted by voxel
  std::vector<float> built_values;  // the values the prims were built from (update_voxels diffs against them)

  int cells_x() const { return nx - 1; }
  int cells_y() const { return ny - 1; }
  int cells_z() const { return nz - 1; }
  size_t voxel_count() const { return size_t(nx - 1) * (ny - 1) * (nz - 1); }
  size_t sample_index(int x, int y, int z) const { return (size_t(z) * ny + y) * nx + x; }
  uint32_t voxel_index(int i, int j, int k) const { return uint32_t(i + (nx - 1) * (j + (ny - 1) * k)); }
  void voxel_coords(uint32_t v, int& i, int& j, int& k) const {
    i = int(v % uint32_t(nx - 1));
    j = int((v / uint32_t(nx - 1)) % uint32_t(ny - 1));
    k = int(v / (uint32_t(nx - 1) * uint32_t(ny - 1)));
  }
  // The 8 corner values of voxel v (corner order of Trilinear::from_corners).
  void corners(uint32_t v, double c[8]) const;
  Trilinear<double> voxel_function(uint32_t v) const;
  // f, gradient and Hessian of voxel v's interpolant at voxel-local s (extrapolated outside [0,1]^3).
  SdfSample eval(uint32_t v, const Vec3d& s) const;
  // The voxel holding grid point g (clamped to the grid), and g's coordinates inside it.
  uint32_t locate(const Vec3d& g, Vec3d& s) const;

  Vec3d grid_from_world(const Vec3d& p) const { return A_inv * (p - origin); }
  Vec3d world_from_grid(const Vec3d& g) const { return A * g + origin; }
  // Unit world normal from a grid-space gradient (false if the gradient vanishes).
  bool world_normal(const Vec3d& grad, Vec3d& n) const;

  // The axis (0, 1, 2) along which voxel v's surface is parameterised as a graph over the other two
  // (the projective-sampling paper, section 5.4): the axis whose four voxel edges change f by the
  // same sign and most, relative to the largest change (there f is monotone along the axis on every
  // line through the voxel, so each line meets the surface at most once).
  static int voxel_axis(const double c[8]);
  // Whether the surface can pass through a box with these corner values (min <= 0 <= max; a
  // voxel whose values are all zero has no surface, the whole box being the zero set).
  static bool straddles(const double c[8]);

  // Recomputes the prims of the voxels around samples that changed since the last build; returns
  // the number of voxels recomputed (every voxel when `all`).
  size_t update_voxels(bool all);
  bool build_prim(uint32_t v, Prim& out) const;

  // Nearest root along a grid-space ray (o, d) in voxel v with t in (tmin, tmax) and inside the voxel.
  bool intersect_voxel(uint32_t v, const Vec3d& o, const Vec3d& d, double tmin, double tmax, double& t_hit) const;
  // Surface record at grid point g on voxel v's patch; `toward` (world, or 0) orients the fallback
  // normal where the gradient vanishes.
  void fill_interaction(uint32_t v, const Vec3d& g, const Vec3& toward, SurfaceInteraction& si) const;

  // ---- the shape interface (core/geometry/shapes/shape.h) ----
  void build_derived();
  RTCGeometry create_embree_geometry(RTCDevice device) const;
  void update_embree_geometry(RTCGeometry g) const;  // the primitive count; bounds come from `prims`
  void fill_hit(const Ray& ray, float t, unsigned prim, const Vec2&, SurfaceInteraction& si) const;
  float area() const;  // approximate (a midpoint rule over each patch): summaries only
  // "<id>.data" (nz x ny x nx).
  void list_parameters(const std::string& id, int index, std::vector<Parameter>& out);
  void validate_parameter(const Parameter& p, const std::string& where) const;
  void apply_parameter(const Parameter&) { update_voxels(false); }  // only voxels around changed samples
  void translate(const Vec3& delta);
  void bounds(Vec3& lo, Vec3& hi) const;  // world box of the patches (empty: lo > hi)
  void geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const;

  // Material coordinates of a surface point (SurfaceInteraction::uv = local (x, y), bary = (local
  // z, 0), prim = voxel): the local unit-cube position, from which the derivative code re-solves the
  // attached point.
  Vec3d local_of(const Vec2& uv, const Vec2& bary) const { return Vec3d(uv.x, uv.y, bary.x); }
  Vec3d grid_of_local(const Vec3d& l) const { return Vec3d(l.x * (nx - 1), l.y * (ny - 1), l.z * (nz - 1)); }

  // The voxel's box corner in grid coordinates.
  Vec3d voxel_origin(uint32_t v) const {
    int i, j, k;
    voxel_coords(v, i, j, k);
    return Vec3d(i, j, k);
  }
};

// The first root of c0 + c1 t + c2 t^2 + c3 t^3 in [t0, t1] (Marmitt et al. 2004: the derivative's
// roots split the interval into monotone pieces), refined to double precision. False if none.
bool first_cubic_root(double c0, double c1, double c2, double c3, double t0, double t1, double& t);

}  // namespace limn
