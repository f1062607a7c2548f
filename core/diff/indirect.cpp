#include "core/diff/indirect.h"

#include <map>
#include "core/diff/film_projection.h"
#include "core/math/warp.h"
#include "core/render/integrators/path.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;

// Extra observing vertices traced for unbounded paths (importance beyond the first bounce); longer
// camera sub-paths are not traced (a truncation, said in docs/derivatives.md).
constexpr int kImportanceBounces = 4;

uint32_t opposite_vertex(const Mesh& m, int f, uint32_t a, uint32_t b) {
  for (int k = 0; k < 3; ++k) {
    const uint32_t v = m.indices[3 * f + k];
    if (v != a && v != b) return v;
  }
  return a;
}

// f * W_conn of the camera connection at observing vertex si, for light arriving from direction
// w_light (unit, pointing away from si): adds the pixel and value, returns false if none.
bool connect_to_camera(const Scene& scene, const FilmProjection& proj, const SurfaceInteraction& si, const Vec3& w_light,
                       int& pixel, Spectrum& value, uint64_t& rays) {
  const Vec3 eye = scene.camera.world_from_camera.point(Vec3(0.0f));
  Vec3 wc = eye - si.p;
  const float dist = glm::length(wc);
  if (!(dist > 0.0f)) return false;
  wc /= dist;
  double area_to_film;
  pixel = proj.pixel(si.p, glm::dot(si.ng, wc), area_to_film);
  if (pixel < 0) return false;
  const Vec3 wi = si.frame.to_local(wc), wo = si.frame.to_local(w_light);
  // Shading-normal leaks on the light side only, as in the path tracer (the viewer side is decided
  // by the geometric normal, `front`).
  if (glm::dot(w_light, si.ng) * wo.z <= 0.0f || wo.z == 0.0f) return false;
  const Bsdf& bsdf = scene.bsdfs[scene.shapes[si.shape].bsdf];
  const Spectrum f = bsdf.eval(wi, wo, si.uv, glm::dot(wc, si.ng) > 0.0f) / std::abs(wo.z);  // f alone: the ray measure has the cosine
  if (is_black(f)) return false;
  rays++;
  if (scene.occluded(spawn_ray_to(si, eye))) return false;
  value = f * float(area_to_film);
  return true;
}

}  // namespace

IndirectBoundary::IndirectBoundary(const Scene& scene, const DiffParams& params) : m_scene(scene), m_params(params) {
  std::vector<float> lengths;
  for (int si : params.moving_shapes()) {
    const Shape& shape = scene.shapes[si];
    if (!shape.is_mesh()) continue;  // spheres: their term is the curvature part of Eq. 4, not implemented yet
    const Mesh& m = shape.mesh();
    for (const MeshEdge& e : m.edges) {
      const uint32_t a = e.a, b = e.b;
      bool keep = e.face_count != 2;
      if (!keep) {
        // Convex and not flat: the third vertex of one face lies strictly below the other's plane
        // (1e-6 of the edge length: below that the dihedral angle is numerically flat).
        const Vec3d n0 = m.face_normal(e.face0);
        const Vec3 c = m.vertex(opposite_vertex(m, e.face1, a, b));
        const double h = glm::dot(n0, Vec3d(c - m.vertex(a)));
        keep = h < -1e-6 * glm::length(Vec3d(m.vertex(b) - m.vertex(a)));
      }
      if (!keep) continue;
      const float len = glm::length(m.vertex(b) - m.vertex(a));
      if (!(len > 0.0f)) continue;
      m_edges.push_back({si, a, b, e.face0, e.face_count == 2 ? e.face1 : -1});
      lengths.push_back(len);
      m_total_length += len;
    }
  }
  if (!lengths.empty()) m_select = Distribution1D(lengths);
  for (size_t i = 0; i < scene.emitters.size(); ++i)
    if (scene.emitters[i].is_delta()) m_delta_lights.push_back(int(i));
}

void IndirectBoundary::sample(Pcg32& rng, PathInputs& in, std::vector<Splat>& splats, std::vector<Var>& velocities,
                              uint64_t& rays) const {
  const Vec3 u(rng.next_float(), rng.next_float(), rng.next_float());
  sample_at(u, 1.0f, 1.0f, rng, in, splats, velocities, rays);
}

float IndirectBoundary::guide_value(const Vec3& u, uint64_t seed) const {
  // |L_d W sin(phi)| of the uniform-direction term, without the velocity (it depends on the
  // tangent or adjoint, unknown when the guide is built).
  Pcg32 rng(seed, 0x6775696465ULL);
  PathInputs in;
  std::vector<Splat> splats;
  std::vector<Var> vel;
  uint64_t rays = 0;
  sample_at(u, 1.0f, 1.0f, rng, in, splats, vel, rays, /*delta_terms=*/false);
  float v = 0.0f;
  for (const Splat& sp : splats) v += luminance(glm::abs(sp.value));
  return v;
}

void IndirectBoundary::sample_at(const Vec3& u, float pdf_u, float pdf_u0, Pcg32& rng, PathInputs& in, std::vector<Splat>& splats,
                                 std::vector<Var>& velocities, uint64_t& rays, bool delta_terms) const {
  // Boundary sample space: u.x picks the edge by length and the point on it, (u.y, u.z) the
  // direction (uniform on the sphere). pdf_u is the guide's density on [0,1)^3, pdf_u0 that of u.x.
  size_t k;
  const float lambda = m_select.sample_remapped(u.x, &k);
  const BoundaryEdge& e = m_edges[k];
  const Mesh& m = m_scene.shapes[e.shape].mesh();
  const Vec3 a = m.vertex(e.a), b = m.vertex(e.b);
  const Vec3 xb = a + lambda * (b - a);
  // x_b on the tape; the edge point is chosen per unit length: pdf = 1 / total length.
  const VV va = diff_vertex(m_scene, m_params, in, e.shape, e.a), vb = diff_vertex(m_scene, m_params, in, e.shape, e.b);
  const VV xb_var = va + (vb - va) * Var(lambda);
  const float pdf_point = float(1.0 / m_total_length);

  // Uniform directions for everything but the Dirac deltas of point and directional lights.
  const Vec3 w = warp::square_to_uniform_sphere(Vec2(u.y, u.z));
  // Radiance probes and importance paths need independent random numbers (E[L_d W] is wanted, not
  // a product of correlated estimates): a stream of their own for the importance paths.
  const uint64_t seed = (uint64_t(rng.next_u32()) << 32) | rng.next_u32();
  const Pcg32 importance_rng(seed, 0x696d706f7274616eULL);
  const Pcg32 base = rng;
  evaluate_direction(e, xb, w, pdf_u * pdf_point * warp::square_to_uniform_sphere_pdf(), false, -1, base, importance_rng, in,
                     xb_var, splats, velocities, rays);
  if (!delta_terms) return;
  for (int li : m_delta_lights) {
    Vec3 wl;  // from the light through x_b, towards the observing side
    if (const auto* p = std::get_if<PointEmitter>(&m_scene.emitters[li].model)) wl = xb - p->position;
    else wl = std::get<DirectionalEmitter>(m_scene.emitters[li].model).direction;
    if (!(glm::length(wl) > 0.0f)) continue;
    evaluate_direction(e, xb, glm::normalize(wl), pdf_u0 * pdf_point, true, li, base, importance_rng, in, xb_var, splats,
                       velocities, rays);
  }
}

void IndirectBoundary::evaluate_direction(const BoundaryEdge& e, const Vec3& xb, const Vec3& w, float pdf_w, bool delta_light,
                                          int light, const Pcg32& rng0, const Pcg32& rng_importance, PathInputs& in, const VV& xb_var,
                                          std::vector<Splat>& splats, std::vector<Var>& velocities, uint64_t& rays) const {
  const Mesh& m = m_scene.shapes[e.shape].mesh();
  const Vec3 t = glm::normalize(m.vertex(e.b) - m.vertex(e.a));
  const Vec3 txw = glm::cross(t, w);
  const float sin_phi = glm::length(txw);
  if (!(sin_phi > 1e-6f)) return;  // w along the edge: the edge is invisible in that direction
  const Vec3 n_b = txw / sin_phi;

  // Only silhouettes for rays along w matter: one face towards w, the other away (or an open edge).
  const Vec3d n0 = m.face_normal(e.face0);
  Vec3 n_out;
  if (e.face1 >= 0) {
    const Vec3d n1 = m.face_normal(e.face1);
    if ((glm::dot(n0, Vec3d(w)) > 0.0) == (glm::dot(n1, Vec3d(w)) > 0.0)) return;
    n_out = Vec3(glm::normalize(n0 + n1));
  } else {
    n_out = Vec3(n0) * (glm::dot(n0, Vec3d(w)) >= 0.0 ? 1.0f : -1.0f);
  }

  // Probe offsets: 1e-4 of the edge length keeps the probes beside this edge only; the second
  // term (~8 ulps of |x_b|) keeps them above float resolution.
  const float edge_len = glm::length(m.vertex(e.b) - m.vertex(e.a));
  const float delta = 1e-4f * edge_len + 1e-6f * max_component(glm::abs(xb));

  // Importance: the observing surface along +w, connected to the camera.
  const int max_depth = m_scene.integrator.max_depth;
  if (max_depth >= 0 && max_depth < 2) return;  // camera -> observer -> edge needs two segments
  Ray ray{xb + delta * n_out, w, 0.0f, kInfinity};
  SurfaceInteraction y;
  rays++;
  if (!m_scene.intersect(ray, y)) return;
  const float dist_y = y.t;

  struct Connection {
    int pixel;
    Spectrum value;
    int depth;  // segments from the camera to the observing vertex that sees the edge region
  };
  std::vector<Connection> conns;
  {
    Spectrum throughput(1.0f);
    SurfaceInteraction cur = y;
    Vec3 w_light = -w;  // at the observing vertex, light comes from the edge
    Pcg32 rng = rng_importance;
    // Bounded paths: camera -> ... -> observer (j segments) + probe segment + 1 more at least.
    const int bounces = max_depth < 0 ? kImportanceBounces : max_depth - 2;
    for (int j = 1;; ++j) {
      int pixel;
      Spectrum v;
      if (connect_to_camera(m_scene, FilmProjection(m_scene.camera), cur, w_light, pixel, v, rays))
        conns.push_back({pixel, throughput * v, j});
      if (j > bounces) break;
      // Continue the importance path by BSDF sampling (adjoint of reflection; reciprocal BSDFs).
      const Bsdf& bsdf = m_scene.bsdfs[m_scene.shapes[cur.shape].bsdf];
      // Sampled from the light side (reciprocal reflection); the leak test belongs to the light side
      // and the sampled, viewer-side direction must stay on the same geometric side.
      const Vec3 wl_local = cur.frame.to_local(w_light);
      const bool light_front = glm::dot(w_light, cur.ng) > 0.0f;
      if ((light_front ? 1.0f : -1.0f) * wl_local.z <= 0.0f) break;
      const auto bs = bsdf.sample(wl_local, rng.next_float(), rng.next_2d(), cur.uv, light_front);
      if (!bs) break;
      const Vec3 wo = cur.frame.to_world(bs->wo);
      if ((glm::dot(wo, cur.ng) > 0.0f) != light_front) break;
      throughput *= bs->weight;
      SurfaceInteraction next;
      rays++;
      if (!m_scene.intersect(spawn_ray(cur, wo), next)) break;
      w_light = -wo;
      cur = next;
    }
  }
  if (conns.empty()) return;

  // L_d = L(x_b - delta n_b) - L(x_b + delta n_b) for light travelling along +w, per path budget.
  std::map<int, Spectrum> delta_L;  // by remaining depth
  auto radiance_difference = [&](int budget) {
    auto it = delta_L.find(budget);
    if (it != delta_L.end()) return it->second;
    Spectrum L[2];
    for (int side = 0; side < 2; ++side) {
      const Vec3 probe = xb + (side == 0 ? -delta : delta) * n_b;
      if (delta_light) {
        // The light's delta along w reaches the probe unless something blocks it.
        const Emitter& em = m_scene.emitters[light];
        Ray shadow;
        Spectrum value;
        if (const auto* p = std::get_if<PointEmitter>(&em.model)) {
          const Vec3 d = p->position - probe;
          const float dist = glm::length(d);
          shadow = Ray{probe, d / dist, 0.0f, dist * (1.0f - 1e-4f)};
          value = p->intensity / (dist * dist);
        } else {
          shadow = Ray{probe, -w, 0.0f, kInfinity};
          value = std::get<DirectionalEmitter>(em.model).irradiance;
        }
        rays++;
        L[side] = m_scene.occluded(shadow) ? Spectrum(0.0f) : value;
      } else {
        // From beside x_b, half way towards the observer, along -w: the segment to the observer is
        // empty, and starting that far out the occluder-side probe cannot begin inside the occluder
        // (a start close to x_b does for faces nearly parallel to w).
        const float back = 0.5f * dist_y;
        Pcg32 r = rng0;
        PathCounters counters;
        L[side] = path_radiance(m_scene, Ray{probe + back * w, -w, 0.0f, kInfinity}, r, counters, PathLimits{budget, false});
        rays += counters.rays;
      }
    }
    const Spectrum d = L[0] - L[1];
    delta_L[budget] = d;
    return d;
  };

  const int vi = int(velocities.size());
  velocities.push_back(dot(xb_var, VV(Var(n_b.x), Var(n_b.y), Var(n_b.z))));
  for (const Connection& c : conns) {
    const int budget = max_depth < 0 ? -1 : max_depth - c.depth;
    if (max_depth >= 0 && budget < 1) continue;
    const Spectrum dL = radiance_difference(budget);
    if (is_black(dL)) continue;
    const Spectrum value = dL * c.value * (sin_phi / pdf_w);
    if (is_finite(value)) splats.push_back({c.pixel, value, vi});
  }
}

}  // namespace limn
