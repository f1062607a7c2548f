// Heightfield shape (heightfield paper, Tong et al. 2023): a grid of control heights under a uniform
// cubic B-spline surface, so heights and normals are C2 (the estimator needs no normal
// discontinuities, paper section 2.2), plus its maximum mipmap (Tevs et al. 2008) for ray traversal
// and for the peak search (peak_search.h).
//
// Local frame: x across the width, y across the depth, z up; the surface is
//   z(x, y) = height_scale * sum_ab B_a(fc) B_b(fr) H[r0 - 1 + b][c0 - 1 + a]
// over grid coordinates c = (x / W + 1/2) (nx - 1), r = (1/2 - y / D) (ny - 1): row 0 of the
// height array (and of a displacement image) is the far edge y = +D/2, column 0 is x = -W/2.
// Control indices outside the grid are clamped (the edge rows repeat). world_from_local is a
// similarity (rotation, uniform scale, translation), so angles are the same in both frames.
#pragma once
#include <embree3/rtcore.h>
#include <string>
#include <vector>
#include "core/geometry/parameter.h"
#include "core/geometry/ray.h"
#include "core/geometry/transform.h"

namespace limn {

// Uniform cubic B-spline basis at f in [0, 1] and its first two derivatives (de Boor).
template <typename T>
inline void bspline_basis(const T& f, T b[4], T db[4], T d2b[4]) {
  const T g = T(1.0) - f;
  b[0] = g * g * g / T(6.0);
  b[1] = (T(3.0) * f * f * f - T(6.0) * f * f + T(4.0)) / T(6.0);
  b[2] = (T(-3.0) * f * f * f + T(3.0) * f * f + T(3.0) * f + T(1.0)) / T(6.0);
  b[3] = f * f * f / T(6.0);
  db[0] = -g * g / T(2.0);
  db[1] = (T(3.0) * f * f - T(4.0) * f) / T(2.0);
  db[2] = (T(-3.0) * f * f + T(2.0) * f + T(1.0)) / T(2.0);
  db[3] = f * f / T(2.0);
  d2b[0] = g;
  d2b[1] = T(3.0) * f - T(2.0);
  d2b[2] = T(-3.0) * f + T(1.0);
  d2b[3] = f;
}

// Height and derivatives at a local point, in local units (d/dx, d/dy).
struct HeightSample {
  double z = 0, dx = 0, dy = 0, dxx = 0, dxy = 0, dyy = 0;
};

// The 4x4 control points of the patch holding a grid position, and the position inside it.
struct PatchCoords {
  int c0, r0;        // patch (cell) index: columns c0..c0+1, rows r0..r0+1 of the grid
  double fc, fr;     // position inside the cell, in [0, 1]
  int index[4][4];   // index[b][a]: flat height index of control point (row r0-1+b, column c0-1+a)
};

struct Heightfield;

// One cell's 4x4 control heights, loaded once for repeated evaluations inside that cell (the ray
// solver's and the peak search's inner loops).
struct CellPatch {
  int i = -1, j = -1;  // cell column, row
  double control[4][4];
  void load(const Heightfield& hf, int cell_i, int cell_j);
  // Height and slopes (local units) at local (x, y), clamped into the cell.
  HeightSample eval(const Heightfield& hf, double x, double y) const;
};

struct Heightfield {
  static constexpr const char* kind_name = "heightfield";
  // Not an area emitter (the loader refuses one): nothing samples points on it.
  static constexpr bool can_emit = false;

  int nx = 0, ny = 0;              // columns, rows (>= 2 each)
  std::vector<float> heights;      // ny * nx control heights, row-major (row 0: y = +D/2)
  float width = 2.0f, depth = 2.0f;  // W, D: extent in local x and y
  float height_scale = 1.0f;       // > 0
  Transform world_from_local;      // similarity
  float scale = 1.0f;              // its uniform scale factor

  // Maximum (and minimum) mipmap over the patches: level 0 holds, per cell, the extreme control
  // heights of its 4x4 support (the convex-hull property of B-splines bounds the surface by them),
  // level l the extremes of 2x2 cells of level l-1.
  // Each node also bounds the surface's second derivatives (local units) over its cells, from
  // the second differences of the control heights (B-spline derivatives are convex combinations
  // of them): the peak search's curvature test (peak_search.cpp).
  // One node's bounds, kept together: a search step reads them all, and on a 2048^2 field separate
  // arrays cost one cache miss each.
  struct NodeBounds {
    float lo, hi;          // local z (height_scale applied)
    float zxx, zyy, zxy;   // bounds on |d2z/dx2|, |d2z/dy2|, |d2z/dxdy|
    bool operator==(const NodeBounds&) const = default;
  };
  struct Level {
    int w, h;
    std::vector<NodeBounds> node;  // row-major, w x h
  };
  std::vector<Level> mip;
  std::vector<float> mip_heights;  // the heights the mipmap was built from (what update_mipmap diffs against)

  int cells_x() const { return nx - 1; }
  int cells_y() const { return ny - 1; }
  float max_height() const { return mip.back().node[0].hi; }
  float min_height() const { return mip.back().node[0].lo; }

  // Builds the mipmap from scratch; update_mipmap() recomputes only what changed since.
  void build_mipmap();
  // Returns the number of level-0 cells recomputed (0 when nothing changed).
  size_t update_mipmap();

  // Parameter range [t0, t1] (narrowed in place) of the 2D line (ox, oy) + t (dx, dy) inside mipmap
  // node (level l, column i, row j), which covers level-0 cells [i 2^l, (i+1) 2^l) x [j 2^l, ...).
  bool node_span(int l, int i, int j, double ox, double oy, double dx, double dy, double& t0, double& t1) const;

  // Grid coordinates of a local (x, y), clamped to the domain.
  double grid_c(double x) const { return (x / width + 0.5) * (nx - 1); }
  double grid_r(double y) const { return (0.5 - y / depth) * (ny - 1); }
  double local_x(double c) const { return (c / (nx - 1) - 0.5) * width; }
  double local_y(double r) const { return (0.5 - r / (ny - 1)) * depth; }
  bool inside(double x, double y) const { return std::abs(x) <= 0.5 * width && std::abs(y) <= 0.5 * depth; }
  PatchCoords patch(double x, double y) const;
  HeightSample eval(double x, double y) const;

  // Nearest hit of a local-frame ray with t in (tmin, tmax) (t is the same in world space when
  // the ray direction is mapped without normalising). `cells` counts level-0 cells solved.
  bool intersect_local(const Vec3d& o, const Vec3d& d, double tmin, double tmax, double& t_hit, size_t* cells = nullptr) const;
  bool intersect(const Ray& ray, float& t_hit) const;
  // Surface record at local (x, y); bary holds the grid coordinates (c, r), the material point.
  void fill_interaction(double x, double y, SurfaceInteraction& si) const;
  void fill_interaction_world(const Vec3& p_world, SurfaceInteraction& si) const;
  // World-space bounds of the whole surface.
  void bounds(Vec3& lo, Vec3& hi) const;
  // Surface area (sum over cells of the bilinear patch through the cell's surface corners).
  float area() const;
  // The surface sampled at every grid point (as a mesh would show it): n x ny local heights.
  std::vector<float> surface_heights() const;

  // ---- the shape interface (core/geometry/shapes/shape.h) ----
  void build_derived() { build_mipmap(); }
  RTCGeometry create_embree_geometry(RTCDevice device) const;
  void update_embree_geometry(RTCGeometry) const {}  // the bounds callback reads the mipmap's top level
  void fill_hit(const Ray& ray, float t, unsigned, const Vec2&, SurfaceInteraction& si) const { fill_interaction_world(ray(t), si); }
  // "<id>.heights" (ny x nx control heights before height_scale).
  void list_parameters(const std::string& id, int index, std::vector<Parameter>& out);
  void validate_parameter(const Parameter& p, const std::string& where) const;
  void apply_parameter(const Parameter&) { update_mipmap(); }  // only the cells around changed heights
  void translate(const Vec3& delta) { world_from_local = Transform::translate(Vec3d(delta)) * world_from_local; }
  void geometry_state(std::vector<float>& values, Vec3& lo, Vec3& hi) const;
};

}  // namespace limn
