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
//
// Planar delta reflections (docs/derivatives.md, "Silhouettes seen in mirrors"): a silhouette
// seen in a flat mirror, or in a chain of them, is a silhouette seen directly by the virtual
// camera, the camera reflected across the mirror planes (the camera's film position of a point x
// seen through planes 1..k is that of R_1 R_2 .. R_k x). Its curves are collected from that
// virtual eye and projected with it; the two radiances are path traced from the real camera at
// the two film positions, so the mirror's reflectance, its extent and whatever blocks the path
// come out of the path tracer (a film position where the camera does not see the mirror has the
// same radiance on both sides). The chains come from core/diff/terms/delta_chains.h; curved or
// smooth-shaded mirrors have none, and the summary says so.
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
  size_t mirror_views() const { return m_views.size() - 1; }  // virtual cameras of planar mirror chains
  const std::vector<std::string>& notes() const { return m_notes; }  // delta surfaces left out, and why

  // One sample. Returns false when it reaches no pixel. Otherwise `film_position` is where it
  // falls on the film (Camera::splat spreads it over the pixels by the filter), `delta_L` = L(s - delta n) - L(s + delta n) divided by the sample's film-length pdf,
  // and the tape holds `normal_velocity` = ds/dtheta . n as a function of the shape parameters.
  bool sample(Pcg32& rng, PathInputs& inputs, glm::dvec2& film_position, Spectrum& delta_L, ad::Var& normal_velocity,
              uint64_t& rays) const;

 private:
  const Scene& m_scene;
  const DiffParams& m_params;
  std::vector<SilhouetteCurve> m_curves;
  std::vector<CameraView> m_views;  // [0] the camera, then one virtual camera per planar mirror chain
  std::vector<int> m_view_of;       // per curve: its view
  std::vector<std::string> m_notes;
  Distribution1D m_select;
  uint64_t m_skipped = 0;
  int m_max_depth;
};

}  // namespace limn
