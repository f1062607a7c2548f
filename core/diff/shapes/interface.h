// The shape interface, derivative half (the geometry half is core/geometry/shapes/shape.h). Each shape
// kind G specialises three groups in core/diff/shapes/<kind>.h, grouped as Mitsuba 3 groups its
// silhouette API:
//
//   SurfaceDiff<G>        points attached to the surface as functions of the parameters (the
//                         interior term's material form; Mitsuba's differential_motion)
//   BoundarySegments<G>   the kind's segments of the boundary sample space (projective-sampling
//                         paper Eq. 4): sample, exact inverse, the delta-light curve, the attached
//                         boundary point, and projection of path segments onto its silhouettes
//                         (Mitsuba's sample_silhouette, invert_silhouette_sample,
//                         sample_precomputed_silhouette, primitive_silhouette_projection)
//   CameraSilhouettes<G>  silhouette curves seen by the camera, for the primary term (Mitsuba's
//                         precompute_silhouette)
//
// A kind without a group derives that specialisation from Unsupported and states the reason; the
// callers then refuse with the shape named instead of contributing zero. core/diff/shapes/all.h
// checks every alternative of ShapeGeometry against the concepts at the end of this file.
#pragma once
#include <concepts>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include "core/diff/ad/diff_params.h"
#include "core/diff/ad/film_projection.h"
#include "core/math/rng.h"

namespace limn {


// What every per-kind derivative routine works with: the scene, which parameters are
// differentiable, and the tape inputs of the current path or sample.
struct DiffContext {
  const Scene& scene;
  const DiffParams& params;
  PathInputs& in;
};

// A path vertex as a function of the parameters.
struct DiffVertex {
  ad::V3<ad::Var> p, ng, ns;  // position, geometric normal, shading normal (ns on ng's side)
  ad::Var jacobian{1.0};      // area of the attached surface element relative to its primal area
  ad::Var u{0.0}, v{0.0};     // texture coordinates
};

// Where a point sits on its surface independently of the parameters: what attaching holds fixed.
struct SurfacePoint {
  int shape = -1;
  int prim = 0;       // triangle (meshes)
  Vec2 bary{0.0f};    // triangle barycentrics (b1, b2); heightfield grid coordinates (c, r)
  Vec3 n{0.0f};       // unit direction from a sphere's centre (the primal normal)
  Vec2 uv{0.0f};      // texture coordinates of the primal point
  static SurfacePoint of(const SurfaceInteraction& si) { return {si.shape, si.prim, si.bary, si.ng, si.uv}; }
};

// ---- boundary sample space (core/diff/boundary_space.h) ----------------------------------------
// Eq. 4 has a perimeter part (curves where the surface ends or creases: mesh edges) and an
// interior part (smooth surfaces with normal curvature: spheres).
enum class BoundaryPart { Perimeter, Interior };

// One segment of the boundary sample space; its kind's code says what `local` means (a mesh
// edge index, 0 for a sphere's surface).
struct BoundarySegment {
  int shape;
  int local;
  float measure;   // of its domain, in the measure its pdfs are stated in (dl dw, dA dphi)
  float weight;    // selection weight: the measure times a typical Jacobian (static segments scaled down, see BoundarySpace)
  bool moving;     // the shape's geometry is differentiable
  BoundaryPart part;
};

struct BoundaryPoint {
  int segment = -1;
  Vec3 xb{0.0f};     // point on the boundary
  Vec3 w{0.0f};      // unit direction from x_b towards the observing side
  Vec3 n_b{0.0f};    // unit normal of the boundary, perpendicular to w, pointing away from the occluder
  Vec3 n_out{0.0f};  // offset that moves a ray start off the surface (importance rays)
  float jacobian = 0.0f;  // sin(phi) between edge and w (perimeter), or the normal curvature (interior)
  float pdf = 0.0f;       // density per unit measure (dl dw, dA dphi, or dl for delta lights)
  float delta = 0.0f;     // radiance probe offset along n_b
  Vec3 param{0.0f};       // where x_b sits on its segment: (lambda, 0, 0) on an edge, the unit normal on a sphere
};

// Probe offset beside a boundary point: a fraction of the local feature size keeps the probes
// beside this boundary only; the second term (~8 ulps of |x_b|) keeps them above float resolution.
inline float probe_offset(float feature_size, const Vec3& xb) { return 1e-4f * feature_size + 1e-6f * max_component(glm::abs(xb)); }

// ---- projection (core/diff/projection.h) --------------------------------------------------------
struct Projection {
  Vec3 u;            // point of the boundary sample space
  int segment;       // its segment in the boundary space
  Vec3 xb, w;        // the boundary point and the direction from it towards (a slightly shifted) x_a
  bool found;        // a true silhouette; false: the snapped fallback
};

enum class MeshProjection { Walk, Jump, Hybrid };

// What a kind's projector needs of the boundary sample space (core/diff/terms/boundary_space.h).
class SegmentSpace {
 public:
  virtual ~SegmentSpace() = default;
  virtual const std::vector<BoundarySegment>& segments() const = 0;
  virtual bool sample(const Vec3& u, float pdf_u, BoundaryPoint& out) const = 0;
  virtual Vec3 invert(int segment, const Vec3& xb, const Vec3& w) const = 0;
};

// The projection's boundary point x_b on `segment`, with the first direction that sees a
// silhouette there: `w_first` (section 5: an approximate boundary segment x'_a -> x'_b suffices;
// keeping the original direction and letting x_a slide keeps what the segment saw at x_a, e.g. a
// near-specular reflection towards the camera), else the direction to x_a itself.
std::optional<Projection> finish_projection(const SegmentSpace& space, int segment, const Vec3& xa, const Vec3& xb, bool found,
                                            const Vec3& w_first);

// Projects path segments that end on one shape onto that shape's silhouettes.
class ShapeProjector {
 public:
  virtual ~ShapeProjector() = default;
  virtual std::optional<Projection> project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const = 0;
};

// ---- primary visibility (core/diff/primary.h) ---------------------------------------------------
struct SilhouetteCurve {
  int shape;
  int local;      // its kind's curve index (a mesh edge; 0 for a sphere's outline)
  float weight;   // selection weight: projected length in pixels
};

// The surfaces that meet at a point of a camera curve (a mesh edge's triangles), each with a world
// direction into it: the primary term shades each side on its own surface instead of through a
// probe ray beside the curve, which crosses a face seen nearly edge-on and double counts.
struct CurveSides {
  int count = 0;
  SurfaceInteraction surface[2];
  Vec3 inward[2];      // from the point into that surface
  bool facing[2];      // the surface faces the eye (its oriented normal)
};

// The pinhole camera as the primary term sees it.
struct CameraView {
  FilmProjection proj;
  Vec3 eye_world;       // the camera centre (float, as camera rays start there)
  ad::V3<double> eye;   // the same point in double
  explicit CameraView(const Camera& c);
  // Film position of world point p; false behind the near plane.
  bool film_of(const ad::V3<double>& p, glm::dvec2& s) const {
    const auto pc = proj.to_camera(p);
    if (pc.z <= proj.near) return false;
    double fx, fy;
    proj.film(pc, fx, fy);
    s = glm::dvec2(fx, fy);
    return true;
  }
};

// ---- the per-kind groups -------------------------------------------------------------------------
template <typename G> struct SurfaceDiff;
template <typename G> struct BoundarySegments;
template <typename G> struct CameraSilhouettes;

// Base of a group's specialisation for a kind that lacks it; the specialisation's `reason` says why.
struct Unsupported {};
template <typename Group>
inline constexpr bool is_unsupported = std::is_base_of_v<Unsupported, Group>;

// Parameter offsets of a shape's translation: the stored geometry already includes it, so it
// enters with value 0.
inline ad::V3<ad::Var> plus_translation(const DiffParams& params, PathInputs& in, int shape, ad::V3<ad::Var> p) {
  const long t = params.slot(Parameter::Kind::Translation, shape);
  if (t < 0) return p;
  return p + ad::V3<ad::Var>(in.make(0.0, t), in.make(0.0, t + 1), in.make(0.0, t + 2));
}

template <typename G>
concept SurfaceDiffKind = requires(const DiffContext& c, const G& g, const SurfacePoint& sp, const ad::V3<ad::Var>& o,
                                   const SurfaceInteraction& si, const Ray& ray) {
  // The attached point alone (cheap: no normals), and the whole attached vertex.
  { SurfaceDiff<G>::position(c, g, sp) } -> std::same_as<ad::V3<ad::Var>>;
  { SurfaceDiff<G>::attach(c, g, sp) } -> std::same_as<DiffVertex>;
  // Where the differentiated ray (o, d) meets the primal hit's surface (vertices not sampled
  // from a BSDF: camera rays, delta bounces).
  { SurfaceDiff<G>::ray_hit(c, g, o, o, si, ray) } -> std::same_as<DiffVertex>;
};

template <typename G>
concept BoundarySegmentsKind = requires(const Scene& scene, const G& g, const BoundarySegment& s, std::vector<BoundarySegment>& out,
                                        BoundaryPoint& p, const Emitter& light, const DiffContext& c, const SegmentSpace& space,
                                        const std::vector<int>& segments) {
  { BoundarySegments<G>::segment_name } -> std::convertible_to<const char*>;
  // Appends the shape's segments of one part (none where it has no such part).
  BoundarySegments<G>::append(scene, g, 0, true, BoundaryPart::Perimeter, out);
  // (f, u1, u2): the segment's own coordinates, f from the first axis after choosing the segment;
  // pdf_select = the density of choosing it; false where the integrand is zero by construction.
  // p.pdf is set also then, so that E[1/pdf] over all of [0,1)^3 is the space's measure.
  { BoundarySegments<G>::sample(scene, g, s, 0.5f, 0.5f, 0.5f, 1.0f, p) } -> std::same_as<bool>;
  // Exact inverse: (f, u1, u2) of the point x_b with direction w.
  { BoundarySegments<G>::invert(scene, g, s, Vec3(0.0f), Vec3(0.0f)) } -> std::same_as<Vec3>;
  // The point light's or directional light's own direction through the boundary at f.
  { BoundarySegments<G>::sample_delta(scene, g, s, 0.5f, 1.0f, light, p) } -> std::same_as<bool>;
  // x_b attached to the differentiable geometry.
  { BoundarySegments<G>::attached_point(c, g, s, p) } -> std::same_as<ad::V3<ad::Var>>;
  // Projection of path segments ending on the shape onto its silhouettes (segments: the shape's
  // segment indices in the space).
  { BoundarySegments<G>::projector(scene, g, space, 0, segments, MeshProjection::Hybrid) } -> std::same_as<std::unique_ptr<ShapeProjector>>;
};

template <typename G>
concept CameraSilhouettesKind = requires(const Scene& scene, const G& g, const CameraView& view, std::vector<SilhouetteCurve>& out,
                                         uint64_t& skipped, const DiffContext& c, const SilhouetteCurve& curve,
                                         ad::V3<ad::Var>& P, ad::V3<double>& dP, double& pdf) {
  // Appends the curves that can be silhouettes from the camera (`skipped` counts those it cannot use).
  CameraSilhouettes<G>::append(scene, g, 0, view, out, skipped);
  // The point at parameter u in [0, 1) of a curve as a function of the parameters, dP/du, and the
  // density of u.
  { CameraSilhouettes<G>::point(c, g, curve, 0.5f, view.eye, P, dP, pdf) } -> std::same_as<bool>;
  // The surfaces meeting at the point (none: both sides are shaded by probe rays).
  CameraSilhouettes<G>::sides(scene, g, curve, Vec3(0.0f), view.eye, std::declval<CurveSides&>());
};

template <typename G>
concept DifferentiableShapeKind =
    SurfaceDiffKind<G> &&
    (is_unsupported<BoundarySegments<G>> || BoundarySegmentsKind<G>) &&
    (is_unsupported<CameraSilhouettes<G>> || CameraSilhouettesKind<G>);

}  // namespace limn
