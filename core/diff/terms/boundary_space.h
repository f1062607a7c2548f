// Boundary sample space of the indirect boundary term (projective-sampling paper, Eq. 4 and
// section 5.2): [0,1)^3 -> (segment, boundary point x_b, direction w), with an exact inverse.
//
// u.x chooses a segment in proportion to its weight and is remapped to a coordinate along it;
// what a segment is, and how its coordinates map to (x_b, w), belongs to its shape kind
// (BoundarySegments<G>, core/diff/shapes/): mesh edges (the perimeter part of Eq. 4) and sphere
// surfaces (the interior part). Perimeter segments come first, then interior ones; within each,
// moving shapes before static ones.
// Static shapes take part too (a segment grazing a static silhouette moves when it ends on a moving
// surface); together they get at most a quarter of the first coordinate.
// Point and directional lights put Dirac deltas into the integrand; sample_delta() maps u.x alone
// onto the curve where the light's direction grazes the boundary, measure dl.
//
// Projective sampling (core/diff/projection.h) finds (segment, x_b, w) by projection and stores
// invert(...) in a guiding structure; sample() must reproduce the same point from it.
#pragma once
#include <string>
#include <utility>
#include "core/diff/shapes/interface.h"
#include "core/math/distribution.h"

namespace limn {

class BoundarySpace final : public SegmentSpace {
 public:
  // Throws std::invalid_argument naming a moving shape whose kind has no boundary segments.
  // `perimeter` / `interior`: whether Eq. 4's part takes part (DiffOptions::boundary_parts).
  BoundarySpace(const Scene& scene, const DiffParams& params, bool perimeter = true, bool interior = true);

  bool empty() const { return m_segments.empty(); }
  size_t static_count() const;  // segments of shapes that do not move
  // (segment name, count) per kind present, e.g. ("edges", 12), ("sphere surfaces", 1).
  std::vector<std::pair<std::string, size_t>> segment_counts() const;
  const std::vector<BoundarySegment>& segments() const override { return m_segments; }
  // Static shapes left out because their kind has no boundary segments (said in the summary).
  const std::vector<std::string>& left_out() const { return m_left_out; }

  // The point for u, drawn with density pdf_u on [0,1)^3. False where the integrand is zero by
  // construction (w does not see the edge as a silhouette) or the point is degenerate.
  bool sample(const Vec3& u, float pdf_u, BoundaryPoint& out) const override;
  // Exact inverse of sample() for a point x_b on `segment` and a direction w (sample(invert(..))
  // gives back x_b and w up to rounding).
  Vec3 invert(int segment, const Vec3& xb, const Vec3& w) const override;

  // The delta-light point for u0 (density pdf_u0 of the first coordinate): w is the light's
  // direction through x_b. False when that direction does not graze the boundary there.
  bool sample_delta(float u0, float pdf_u0, const Emitter& light, BoundaryPoint& out) const;

  // x_b attached to the differentiable geometry (edge barycentric or sphere direction fixed).
  ad::V3<ad::Var> attached_point(const BoundaryPoint& p, PathInputs& in) const;

 private:
  float select(float u0, size_t* segment) const;

  const Scene& m_scene;
  const DiffParams& m_params;
  std::vector<BoundarySegment> m_segments;
  std::vector<std::string> m_left_out;
  Distribution1D m_select;
};

}  // namespace limn
