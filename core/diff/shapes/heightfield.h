// Heightfields in the derivative interface (core/diff/shapes/interface.h): the surface as a
// function of the parameters on the AD tape (heights of the 4x4 control points around a point, the
// "<id>.heights" slots, the local<->world similarity and the shape's translation parameter), and
// points attached at fixed grid coordinates. Heightfields have no boundary segments and no camera
// silhouettes: their visibility derivatives come from the heightfield estimator
// (core/diff/estimators/heightfield.h).
#pragma once
#include "core/diff/shapes/interface.h"

namespace limn {

struct DiffHeightfieldFrame {
  const Heightfield& hf;
  ad::Var scale;              // constant
  Mat4d world, local;         // world_from_local and its inverse (similarities)
  ad::V3<ad::Var> offset;     // translation parameter (value 0) or constant 0
  long heights_slot;          // first slot of the heights, or -1

  DiffHeightfieldFrame(const Scene& scene, const DiffParams& params, PathInputs& in, int shape);

  ad::V3<ad::Var> to_world_point(const ad::V3<ad::Var>& p) const;
  ad::V3<ad::Var> to_world_vector(const ad::V3<ad::Var>& v) const;  // not normalised
  ad::V3<ad::Var> to_local_point(const ad::V3<ad::Var>& p) const;
  ad::V3<ad::Var> to_local_vector(const ad::V3<ad::Var>& v) const;

  // Local height and slopes at local (x, y); (x, y) may depend on the parameters. The patch is
  // the one holding the primal point.
  void height(PathInputs& in, const ad::Var& x, const ad::Var& y, ad::Var& z, ad::Var& zx, ad::Var& zy) const;
  // World point and unit up-facing normal at local (x, y).
  void surface(PathInputs& in, const ad::Var& x, const ad::Var& y, ad::V3<ad::Var>& p, ad::V3<ad::Var>& n) const;
  // Distance along the world ray (o, d) to the surface, first-order exact around the primal
  // root t0 (one Newton step of z_ray - z_surface, whose value is 0 there).
  ad::Var ray_t(PathInputs& in, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d, double t0) const;
};

template <>
struct SurfaceDiff<Heightfield> {
  // Material point: fixed grid coordinates (SurfacePoint::bary = (c, r)), so fixed local (x, y).
  static ad::V3<ad::Var> position(const DiffContext& c, const Heightfield& hf, const SurfacePoint& sp);
  static DiffVertex attach(const DiffContext& c, const Heightfield& hf, const SurfacePoint& sp);
  static DiffVertex ray_hit(const DiffContext& c, const Heightfield& hf, const ad::V3<ad::Var>& o, const ad::V3<ad::Var>& d,
                            const SurfaceInteraction& si, const Ray& primal_ray);
};

template <>
struct BoundarySegments<Heightfield> : Unsupported {
  static constexpr const char* reason =
      "its visibility derivatives come from the heightfield estimator (Tong et al. 2023), which splits sampled directions at "
      "the discontinuities instead of integrating over boundary segments";
};

template <>
struct CameraSilhouettes<Heightfield> : Unsupported {
  static constexpr const char* reason = BoundarySegments<Heightfield>::reason;
};

}  // namespace limn
