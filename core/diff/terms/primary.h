// Primary-visibility boundary term: derivatives caused by silhouettes seen directly by the pinhole
// camera (the boundary integral of the projective-sampling paper, Eq. 4, with the direction fixed
// towards the camera; docs/derivatives.md). In film space,
//     dI_p/dtheta (boundary) = integral over the silhouette curves inside pixel p of
//                              (L(s - delta n) - L(s + delta n)) (ds/dtheta . n) dl(s),
// for a unit normal n of the projected curve. The curves of the differentiable shapes come from
// their kinds (CameraSilhouettes<G>, core/diff/shapes/): mesh edges that can be silhouettes from
// the camera centre and creases of flat-shaded meshes, the outline circles of spheres. A curve is
// chosen with
// probability proportional to its projected length, a point on it uniformly in its parameter, and
// the pdf is converted to film length; both radiances are path traced with the same random
// numbers, so occluded stretches of a curve contribute nothing.
#pragma once
#include "core/diff/shapes/interface.h"
#include "core/math/distribution.h"
#include "core/math/rng.h"

namespace limn {

class PrimaryBoundary {
 public:
  // Collects the candidate curves of the differentiable shapes as seen from the camera. Throws
  // std::invalid_argument naming a differentiable shape whose kind has no camera silhouettes.
  PrimaryBoundary(const Scene& scene, const DiffParams& params, int max_depth);

  bool empty() const { return m_curves.empty(); }
  size_t curve_count() const { return m_curves.size(); }
  uint64_t skipped_edges() const { return m_skipped; }  // candidate edges behind the near plane

  // One sample. Returns false when it reaches no pixel. Otherwise `film_position` is where it
  // falls on the film (Camera::splat spreads it over the pixels by the filter), `delta_L` = L(s - delta n) - L(s + delta n) divided by the sample's film-length pdf,
  // and the tape holds `normal_velocity` = ds/dtheta . n as a function of the shape parameters.
  bool sample(Pcg32& rng, PathInputs& inputs, glm::dvec2& film_position, Spectrum& delta_L, ad::Var& normal_velocity,
              uint64_t& rays) const;

 private:
  const Scene& m_scene;
  const DiffParams& m_params;
  std::vector<SilhouetteCurve> m_curves;
  Distribution1D m_select;
  uint64_t m_skipped = 0;
  int m_max_depth;
};

}  // namespace limn
