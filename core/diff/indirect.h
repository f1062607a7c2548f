// Indirect boundary term, perimeter part for triangle meshes (projective-sampling paper, Eq. 4):
//     dI/dtheta = integral over edges, integral over S^2 of
//                 L_d(x_b, w) W(x_b, w) sin(phi) (d x_b/d theta . n_b) dw dl(x_b),
// where w points from the edge point x_b towards the observing side, L_d is the radiance on the
// occluder's side of the edge minus the radiance passing beside it (both path traced, with the same
// random numbers, along -w from just beside the edge), W is the importance of the ray, traced
// along +w to the observing surface and connected to the camera there (and, for unbounded paths,
// at further BSDF-sampled vertices), sin(phi) = |t x w| and n_b = (t x w) / |t x w|.
//
// Sampling: boundary sample space [0,1)^3 = (edge point by length, direction on the sphere);
// "guiding: none" samples it uniformly, "grid" with core/guiding/grid.h. Point and directional lights put a Dirac
// delta into L_d: for each of them a second direction, the one from the light through x_b, is
// evaluated as its own term (shadow edges of delta lights).
//
// Edges that can be silhouettes: boundary, non-manifold and convex non-flat edges of the
// differentiable meshes. Not covered: the interior (curvature) term for spheres, creases of
// flat-shaded meshes seen indirectly, and importance beyond the first observing vertex when the
// path length is bounded.
#pragma once
#include "core/diff/diff_params.h"
#include "core/math/distribution.h"
#include "core/math/rng.h"

namespace limn {

struct BoundaryEdge {
  int shape;
  uint32_t a, b;
  int face0, face1;  // adjacent triangles (face1 = -1 on a boundary edge)
};

class IndirectBoundary {
 public:
  IndirectBoundary(const Scene& scene, const DiffParams& params);

  bool empty() const { return m_edges.empty(); }
  size_t edge_count() const { return m_edges.size(); }

  // One boundary sample. Every camera connection adds (pixel, value) to `splats`; the sample's
  // contribution to that pixel is value * normal_velocity, normal_velocity = d x_b/d theta . n_b
  // recorded on the tape (one per direction evaluated, so splats carry its index into `velocities`).
  struct Splat {
    int pixel;
    Spectrum value;
    int velocity;
  };
  void sample(Pcg32& rng, PathInputs& inputs, std::vector<Splat>& splats, std::vector<ad::Var>& velocities,
              uint64_t& rays) const;
  // The same at a given point u of the boundary sample space [0,1)^3, chosen with density pdf_u
  // (pdf_u0: density of u.x alone, used by the delta-light terms that ignore u.y, u.z).
  void sample_at(const Vec3& u, float pdf_u, float pdf_u0, Pcg32& rng, PathInputs& inputs, std::vector<Splat>& splats,
                 std::vector<ad::Var>& velocities, uint64_t& rays, bool delta_terms = true) const;
  // Magnitude of the uniform-direction term at u (what grid guiding tabulates).
  float guide_value(const Vec3& u, uint64_t seed) const;

 private:
  // Evaluates one direction w at edge point x_b; appends splats (value already divided by pdf_w).
  void evaluate_direction(const BoundaryEdge& e, const Vec3& xb, const Vec3& w, float pdf_w, bool delta_light, int light,
                          const Pcg32& rng_probes, const Pcg32& rng_importance, PathInputs& in,
                          const ad::V3<ad::Var>& xb_var, std::vector<Splat>& splats,
                          std::vector<ad::Var>& velocities, uint64_t& rays) const;

  const Scene& m_scene;
  const DiffParams& m_params;
  std::vector<BoundaryEdge> m_edges;
  Distribution1D m_select;       // by edge length
  double m_total_length = 0.0;
  std::vector<int> m_delta_lights;
};

}  // namespace limn
