#include "core/diff/terms/primary.h"

#include "core/diff/ad/film_projection.h"
#include "core/diff/ad/local_derivatives.h"
#include "core/diff/shapes/all.h"
#include "core/diff/terms/delta_chains.h"
#include "core/render/integrators/path.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;
using Vec2d = glm::dvec2;

// Offset of the two radiance probes from the curve, in pixels: far above the float resolution of
// camera ray directions (~4e-5 px at 256 px across 40 degrees), far below any image feature.
constexpr double kProbeOffset = 1e-3;

}  // namespace

PrimaryBoundary::PrimaryBoundary(const Scene& scene, const DiffParams& params, int max_depth)
    : m_scene(scene), m_params(params), m_max_depth(max_depth) {
  m_views.emplace_back(scene.camera);
  DeltaChains chains = find_delta_chains(scene, params);
  for (const Camera& c : chains.mirror_cameras) m_views.emplace_back(c);
  m_notes = std::move(chains.notes);
  for (size_t v = 0; v < m_views.size(); ++v)
    for (int si : params.moving_shapes()) {
      with_group<CameraSilhouettes>(scene, si, "camera silhouettes",
                                    [&](auto group, const auto& g) { group.append(scene, g, si, m_views[v], m_curves, m_skipped); });
      m_view_of.resize(m_curves.size(), int(v));
    }
  std::vector<float> weights;
  for (const SilhouetteCurve& c : m_curves) weights.push_back(c.weight);
  if (!weights.empty()) m_select = Distribution1D(weights);
}

bool PrimaryBoundary::sample(Pcg32& rng, PathInputs& in, glm::dvec2& film_position, Spectrum& delta_L, Var& normal_velocity,
                             uint64_t& rays) const {
  const size_t k = m_select.sample_discrete(rng.next_float());
  const double pmf = m_select.pmf(k);
  const float u = rng.next_float();
  const SilhouetteCurve& c = m_curves[k];
  const bool mirrored = m_view_of[k] > 0;  // seen through planar delta reflections
  const CameraView& view = m_views[size_t(m_view_of[k])];
  const FilmProjection& proj = view.proj;
  const ad::V3<double>& eye = view.eye;

  VV P;                    // the curve point as a function of the parameters
  ad::V3<double> dP;       // d(point)/d(curve parameter)
  double pdf_param;        // density of the curve parameter
  const DiffContext ctx{m_scene, m_params, in};
  if (!with_group<CameraSilhouettes, bool>(m_scene, c.shape, "camera silhouettes", [&](auto group, const auto& g) {
        return group.point(ctx, g, c, u, eye, P, dP, pdf_param);
      }))
    return false;

  const ad::V3<Var> pc = proj.to_camera(P);
  if (pc.z.v <= proj.near) return false;
  Var fx, fy;
  proj.film(pc, fx, fy);
  if (!m_scene.camera.film_covers(fx.v, fy.v)) return false;  // reaches no pixel through the filter
  const Vec2d ds = proj.film_derivative(ad::values(pc), dP);
  const double ds_len = glm::length(ds);
  if (!(ds_len > 0.0)) return false;
  const Vec2d n(-ds.y / ds_len, ds.x / ds_len);
  const double pdf_length = pmf * pdf_param / ds_len;  // per unit of film length
  film_position = Vec2d(fx.v, fy.v);

  // The surfaces meeting at P (a mesh edge's triangles): a side of the curve that one of them
  // covers is shaded on that surface at P, not through a probe ray beside the curve, which passes
  // a triangle seen nearly edge-on and lands on whatever lies beyond it (the outline of a finely
  // tessellated mesh was counted once for its silhouette and again for the crease next to it).
  PathCounters counters;
  const Vec3 p_value(float(P.x.v), float(P.y.v), float(P.z.v));
  CurveSides sides;
  // Seen through mirrors both sides are probed: shading on a side's surface would need the
  // reflection chain in front of it (a mesh's outline can be double counted there, see above).
  if (!mirrored)
    with_group<CameraSilhouettes>(m_scene, c.shape, "camera silhouettes",
                                  [&](auto group, const auto& g) { group.sides(m_scene, g, c, p_value, eye, sides); });
  const Ray centre = m_scene.camera.generate_ray(Vec2(float(fx.v), float(fy.v)));
  const SurfaceInteraction* side_surface[2] = {nullptr, nullptr};
  int chosen[2] = {-1, -1};
  if (sides.count > 0) {
    // P must be what the camera sees there: an occluder in front, another shape or another part
    // of this one, takes both sides alike (1e-4: the faces at P are hit at t_p up to rounding).
    const float t_p = glm::dot(p_value - centre.o, centre.d);
    SurfaceInteraction first;
    counters.rays++;
    if (m_scene.intersect(Ray{centre.o, centre.d, centre.tmin, t_p * (1.0f - 1e-4f)}, first)) {
      rays += counters.rays;
      return false;
    }
    for (int j = 0; j < sides.count; ++j) {
      // The film side a surface covers: where its far corner projects (a point just inside a
      // triangle seen nearly edge-on projects onto the curve within rounding).
      glm::dvec2 q;
      const Vec3 inside = p_value + sides.inward[j];
      if (!view.film_of(ad::V3<double>(inside.x, inside.y, inside.z), q)) continue;
      const int side = glm::dot(q - Vec2d(fx.v, fy.v), n) < 0.0 ? 0 : 1;
      // Of two surfaces on one side (a silhouette: the other folds away behind), the one facing the eye.
      if (chosen[side] < 0 || (sides.facing[j] && !sides.facing[chosen[side]])) chosen[side] = j;
    }
    for (int side = 0; side < 2; ++side)
      if (chosen[side] >= 0) {
        sides.surface[chosen[side]].t = t_p;
        side_surface[side] = &sides.surface[chosen[side]];
      }
  }
  // Radiance on both sides with the same random numbers.
  const Pcg32 rng_paths = rng;
  Spectrum L[2];
  for (int side = 0; side < 2; ++side) {
    Pcg32 r = rng_paths;
    if (side_surface[side]) {
      L[side] = path_radiance(m_scene, centre, r, counters, PathLimits{m_max_depth, true, side_surface[side]});
      continue;
    }
    const double sign = side == 0 ? -1.0 : 1.0;
    const Vec2 film(float(fx.v + sign * kProbeOffset * n.x), float(fy.v + sign * kProbeOffset * n.y));
    L[side] = path_radiance(m_scene, m_scene.camera.generate_ray(film), r, counters, PathLimits{m_max_depth, true});
  }
  rays += counters.rays;
  delta_L = (L[0] - L[1]) / float(pdf_length);
  normal_velocity = fx * Var(n.x) + fy * Var(n.y);
  return is_finite(delta_L);
}

}  // namespace limn
