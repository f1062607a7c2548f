// Indirect boundary term (projective-sampling paper, Eq. 4), both parts:
//     perimeter: integral over edges, integral over S^2 of
//                L_d(x_b, w) W(x_b, w) sin(phi) (d x_b/d theta . n_b) dw dl(x_b),
//     interior:  integral over sphere surfaces, integral over the tangent directions of
//                L_d(x_b, w) W(x_b, w) kappa (d x_b/d theta . n_b) dphi dA(x_b),
// where w points from x_b towards the observing side y, and L_d = -L_bg is the jump of the path
// integrand in the material form of the interior term (docs/derivatives.md): the radiance arriving
// along -w from beside x_b on the background side (path traced), lost when the segment from y to
// the background point x_c is blocked. W is the importance of the ray, traced along +w to y and
// connected to the camera there and at further BSDF-sampled vertices. The velocity is relative to
// the segment (y, x_c), whose ends move with their surfaces.
// For edges sin(phi) = |t x w| and n_b = +-(t x w) / |t x w| away from the occluder; for spheres
// kappa = 1/r and n_b is the surface normal.
//
// Sampling: core/diff/boundary_space.h maps [0,1)^3 onto (segment, x_b, w); "guiding: none"
// samples it uniformly, "grid" with core/guiding/grid.h. Point and directional lights put a Dirac
// delta into L_d: for each of them the light's own direction through a point of the same segment
// is evaluated as a term of its own (shadow edges and sphere shadow outlines of delta lights).
//
// Creases of flat-shaded meshes need no term here: in the material form they stay where they are.
// Camera connections through delta vertices (core/diff/terms/delta_chains.h): through chains of
// flat mirrors (to the virtual camera) and stacks of parallel flat dielectric interfaces (glass
// slabs); not through curved ones (docs/derivatives.md).
#pragma once
#include "core/diff/ad/film_projection.h"
#include "core/diff/terms/boundary_space.h"
#include "core/diff/terms/delta_chains.h"
#include "core/math/rng.h"

namespace limn {

class IndirectBoundary {
 public:
  IndirectBoundary(const Scene& scene, const DiffParams& params, int max_depth, bool perimeter = true, bool interior = true);

  bool empty() const { return m_space.empty(); }
  const BoundarySpace& space() const { return m_space; }
  size_t refraction_stacks() const { return m_stacks.size(); }  // camera connections through flat glass
  size_t mirror_chains() const { return m_mirror_chains.size(); }  // camera connections through flat mirrors

  // One boundary sample at the point u of the boundary sample space [0,1)^3, chosen with density
  // pdf_u (pdf_u0: density of u.x alone, used by the delta-light terms that ignore u.y, u.z). Every
  // camera connection adds (pixel, value) to `splats`; the sample's contribution to that pixel is
  // value * normal_velocity, normal_velocity = d x_b/d theta . n_b recorded on the tape (one per
  // direction evaluated, so splats carry its index into `velocities`).
  struct Splat {
    int pixel;
    Spectrum value;
    int velocity;
  };
  void sample_at(const Vec3& u, float pdf_u, float pdf_u0, Pcg32& rng, PathInputs& inputs, std::vector<Splat>& splats,
                 std::vector<ad::Var>& velocities, uint64_t& rays, bool delta_terms = true) const;
  // Magnitude of the uniform-direction term at u: the integrand the guides are built from, with
  // its random numbers seeded from u's bits (the same value for the same point).
  float guide_value(const Vec3& u) const;

 private:
  // Evaluates one boundary point (light = -1: any light, else that delta light alone); appends
  // splats with values already divided by the point's pdf. value_only (guide_value): the splats'
  // values are exact but their velocities only say whether they are constant, which skips the
  // background point's ray and the observer's attached point whenever the boundary point moves.
  void evaluate(const BoundaryPoint& p, int light, const Pcg32& rng_probes, const Pcg32& rng_importance, PathInputs& in,
                std::vector<Splat>& splats, std::vector<ad::Var>& velocities, uint64_t& rays, bool value_only = false) const;
  void sample_at(const Vec3& u, float pdf_u, float pdf_u0, Pcg32& rng, PathInputs& inputs, std::vector<Splat>& splats,
                 std::vector<ad::Var>& velocities, uint64_t& rays, bool delta_terms, bool value_only) const;

  const Scene& m_scene;
  const DiffParams& m_params;
  BoundarySpace m_space;
  std::vector<int> m_delta_lights;
  std::vector<RefractionStack> m_stacks;
  std::vector<MirrorChain> m_mirror_chains;
  std::vector<FilmProjection> m_mirror_proj;  // the chains' virtual cameras
  std::vector<Vec3> m_mirror_eye;
  int m_max_depth;
};

}  // namespace limn
