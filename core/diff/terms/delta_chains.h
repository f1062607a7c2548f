// Chains of delta (specular) vertices between the pinhole camera and what it sees, for the
// boundary terms (docs/derivatives.md, "Boundary terms through delta surfaces"). A pinhole sees
// through delta vertices along one path per direction, so a boundary point behind them has a
// camera connection only where that path is found deterministically:
// - planar mirror chains (reflections at flat delta conductors or dielectrics): the camera
//   reflected across the planes is a virtual pinhole; a point x seen through planes 1..k lands
//   where the camera sees R_1 .. R_k x (used by the primary term);
// - refraction stacks (transmission through parallel flat dielectric interfaces, e.g. a glass
//   slab): the path from a point to the eye keeps n_i sin(theta_i) along the stack and is found
//   by a 1D root search (used by the indirect term's camera connections).
// Both are found by tracing a grid of camera rays; surfaces hit by too few rays per plane (curved)
// or reflecting through interpolated normals get no chain, and `notes` names them.
#pragma once
#include <string>
#include <vector>
#include "core/diff/ad/diff_params.h"
#include "core/render/scene.h"

namespace limn {

struct RefractionStack {
  Vec3d n;                     // common unit normal, along the camera rays' direction
  std::vector<double> offsets;  // n . x of each plane, in the order the camera crosses them
  std::vector<double> ior;      // refractive index of each layer: [0] at the eye, back() beyond the last plane (equal)
  std::vector<int> shapes;      // the shape of each plane
};

// One planar mirror chain: its planes in the order the camera meets them.
struct MirrorChain {
  std::vector<Vec3d> n;  // unit normals (the shapes' geometric ones)
  std::vector<double> d;  // plane offsets n . x
  std::vector<int> shapes;
};

struct DeltaChains {
  std::vector<Camera> mirror_cameras;
  std::vector<MirrorChain> mirror_chains;  // the same chains' planes
  std::vector<RefractionStack> stacks;
  std::vector<std::string> notes;
};

DeltaChains find_delta_chains(const Scene& scene, const DiffParams& params);

// The camera connection of surface point `si` through `stack`: the direction leaving the eye, the
// last segment's direction (towards si), the Jacobian d(solid angle at the eye)/d(area at si) and
// the transmittance (Fresnel, specular_transmittance; the eta^2 radiance scales cancel between
// equal end media). False when no such path exists or something blocks it.
bool connect_through_stack(const Scene& scene, const RefractionStack& stack, const SurfaceInteraction& si, Vec3& d_eye, Vec3& d_last,
                           double& domega_dA, Spectrum& transmittance, uint64_t& rays);

// Whether the segment from surface point `si` towards the chain's virtual eye `eye_virtual` is
// the reflection path to the camera: it meets the chain's planes in reverse order on their
// shapes, each a delta surface, and then reaches the eye unblocked. `reflectance` is the product
// of the delta reflections' values (Fresnel times specular_reflectance).
bool connect_through_mirrors(const Scene& scene, const MirrorChain& chain, const Vec3& eye_virtual, const SurfaceInteraction& si,
                             Spectrum& reflectance, uint64_t& rays);

}  // namespace limn
