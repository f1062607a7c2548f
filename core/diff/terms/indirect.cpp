#include "core/diff/terms/indirect.h"

#include <cstring>
#include <map>
#include "core/diff/ad/film_projection.h"
#include "core/diff/shapes/all.h"
#include "core/math/warp.h"
#include "core/render/integrators/path.h"

namespace limn {
namespace {

using ad::Var;
using VV = ad::V3<Var>;

// Extra observing vertices traced for unbounded paths (importance beyond the first bounce); longer
// camera sub-paths are not traced (a truncation, said in docs/derivatives.md).
constexpr int kImportanceBounces = 4;

// f * d(film)/dA of a connection from observing vertex si to a pinhole at `eye` seen through
// `proj` (the camera, or a mirror chain's virtual camera), for light arriving from direction
// w_light (unit, pointing away from si): its film position and value; wc the unit direction to
// the eye. No visibility test.
bool pinhole_connection(const Scene& scene, const FilmProjection& proj, const Vec3& eye, const SurfaceInteraction& si, const Vec3& w_light,
                        glm::dvec2& film, Spectrum& value, Vec3& wc) {
  wc = eye - si.p;
  const float dist = glm::length(wc);
  if (!(dist > 0.0f)) return false;
  wc /= dist;
  double area_to_film;
  if (!proj.film_position(si.p, glm::dot(si.ng, wc), film, area_to_film) || !scene.camera.film_covers(film.x, film.y)) return false;
  const Vec3 wi = si.frame.to_local(wc), wo = si.frame.to_local(w_light);
  // Shading-normal leaks on the light side only, as in the path tracer (the viewer side is decided
  // by the geometric normal, `front`).
  if (glm::dot(w_light, si.ng) * wo.z <= 0.0f || wo.z == 0.0f) return false;
  const Bsdf& bsdf = scene.bsdfs[scene.shapes[si.shape].bsdf];
  const Spectrum f = bsdf.eval(wi, wo, si.uv, glm::dot(wc, si.ng) > 0.0f) / std::abs(wo.z);  // f alone: the ray measure has the cosine
  value = f * float(area_to_film);
  return !is_black(value);
}

// f * W_conn of the camera connection at observing vertex si (pinhole_connection with the camera
// and its visibility).
bool connect_to_camera(const Scene& scene, const FilmProjection& proj, const SurfaceInteraction& si, const Vec3& w_light,
                       glm::dvec2& film, Spectrum& value, uint64_t& rays) {
  const Vec3 eye = scene.camera.world_from_camera.point(Vec3(0.0f));
  Vec3 wc;
  if (!pinhole_connection(scene, proj, eye, si, w_light, film, value, wc)) return false;
  rays++;
  return !scene.occluded(spawn_ray_to(si, eye));
}

// The same through a refraction stack (core/diff/terms/delta_chains.h): f * T * d(film)/dA at si,
// with d(film)/dA = d(film)/d(omega at the eye) d(omega)/dA; d_last is the path's direction at si.
bool connect_through_stack(const Scene& scene, const RefractionStack& st, const FilmProjection& proj, const SurfaceInteraction& si,
                           const Vec3& w_light, glm::dvec2& film, Spectrum& value, Vec3& d_last, uint64_t& rays) {
  const Vec3 wl = si.frame.to_local(w_light);
  if (glm::dot(w_light, si.ng) * wl.z <= 0.0f || wl.z == 0.0f) return false;
  Vec3 d_eye;
  double domega_dA;
  Spectrum T;
  if (!connect_through_stack(scene, st, si, d_eye, d_last, domega_dA, T, rays)) return false;
  // Film area per solid angle at the eye: the area Jacobian of a point facing the eye at distance
  // r, times r^2 (r beyond the near plane).
  const double r = std::max(1.0, 2.0 * proj.near);
  const Vec3 eye = scene.camera.world_from_camera.point(Vec3(0.0f));
  double area_to_film;
  if (!proj.film_position(eye + float(r) * d_eye, 1.0, film, area_to_film) || !scene.camera.film_covers(film.x, film.y)) return false;
  const Vec3 wc = -d_last;
  const Bsdf& bsdf = scene.bsdfs[scene.shapes[si.shape].bsdf];
  const Spectrum f = bsdf.eval(si.frame.to_local(wc), wl, si.uv, glm::dot(wc, si.ng) > 0.0f) / std::abs(wl.z);
  value = f * T * float(area_to_film * r * r * domega_dA);
  return !is_black(value) && is_finite(value);
}

// The same through a flat mirror chain: the connection to its virtual camera (film position and
// Jacobian as for a camera there), times the chain's reflectance; d_last as above.
bool connect_through_mirrors(const Scene& scene, const MirrorChain& chain, const FilmProjection& proj, const Vec3& eye_virtual,
                             const SurfaceInteraction& si, const Vec3& w_light, glm::dvec2& film, Spectrum& value, Vec3& d_last,
                             uint64_t& rays) {
  Vec3 wc;
  if (!pinhole_connection(scene, proj, eye_virtual, si, w_light, film, value, wc)) return false;
  Spectrum R;
  if (!connect_through_mirrors(scene, chain, eye_virtual, si, R, rays)) return false;
  value *= R;
  d_last = -wc;
  return is_finite(value);
}

}  // namespace

IndirectBoundary::IndirectBoundary(const Scene& scene, const DiffParams& params, int max_depth, bool perimeter, bool interior)
    : m_scene(scene), m_params(params), m_space(scene, params, perimeter, interior), m_max_depth(max_depth) {
  for (size_t i = 0; i < scene.emitters.size(); ++i)
    if (scene.emitters[i].is_delta()) m_delta_lights.push_back(int(i));
  if (!m_space.empty()) {
    DeltaChains chains = find_delta_chains(scene, params);
    m_stacks = std::move(chains.stacks);
    m_mirror_chains = std::move(chains.mirror_chains);
    for (const Camera& c : chains.mirror_cameras) {
      m_mirror_proj.emplace_back(c);
      m_mirror_eye.push_back(c.world_from_camera.point(Vec3(0.0f)));
    }
  }
}

float IndirectBoundary::guide_value(const Vec3& u) const {
  // |L_d W sin(phi)| of the uniform-direction term, without the velocity (it depends on the
  // tangent or adjoint, unknown when the guide is built). Only the value is wanted: the nodes it
  // records are dropped again, or a guide's millions of evaluations would grow the thread's tape
  // by hundreds of megabytes (bunny, octree: 460 MB).
  struct Rewind {  // also when sample_at throws
    ad::Tape& tape;
    size_t mark;
    ~Rewind() { tape.truncate(mark); }
  } rewind{ad::Tape::current(), ad::Tape::current().size()};
  uint32_t bits[3];
  std::memcpy(bits, &u, sizeof(bits));
  Pcg32 rng(mix_bits((uint64_t(bits[0]) << 32 | bits[1]) ^ (uint64_t(bits[2]) * 0x9E3779B97F4A7C15ULL)), 0x6775696465ULL);
  // Scratch kept per thread: a guide's millions of calls otherwise spend ~4 % of the set-up in malloc.
  thread_local PathInputs in;
  thread_local std::vector<Splat> splats;
  thread_local std::vector<Var> vel;
  in.clear();
  splats.clear();
  vel.clear();
  uint64_t rays = 0;
  sample_at(u, 1.0f, 1.0f, rng, in, splats, vel, rays, /*delta_terms=*/false, /*value_only=*/true);
  float v = 0.0f;
  for (const Splat& sp : splats) v += luminance(glm::abs(sp.value));
  return v;
}

void IndirectBoundary::sample_at(const Vec3& u, float pdf_u, float pdf_u0, Pcg32& rng, PathInputs& in, std::vector<Splat>& splats,
                                 std::vector<Var>& velocities, uint64_t& rays, bool delta_terms) const {
  sample_at(u, pdf_u, pdf_u0, rng, in, splats, velocities, rays, delta_terms, false);
}

void IndirectBoundary::sample_at(const Vec3& u, float pdf_u, float pdf_u0, Pcg32& rng, PathInputs& in, std::vector<Splat>& splats,
                                 std::vector<Var>& velocities, uint64_t& rays, bool delta_terms, bool value_only) const {
  // pdf_u is the guide's density on [0,1)^3, pdf_u0 that of u.x alone (the delta-light terms use u.x only).
  // Radiance probes and importance paths need independent random numbers (E[L_d W] is wanted, not
  // a product of correlated estimates): a stream of their own for the importance paths.
  const uint64_t seed = (uint64_t(rng.next_u32()) << 32) | rng.next_u32();
  const Pcg32 importance_rng(seed, 0x696d706f7274616eULL);
  const Pcg32 base = rng;
  BoundaryPoint p;
  if (m_space.sample(u, pdf_u, p)) evaluate(p, -1, base, importance_rng, in, splats, velocities, rays, value_only);
  if (!delta_terms) return;
  for (int li : m_delta_lights)
    if (m_space.sample_delta(u.x, pdf_u0, m_scene.emitters[li], p))
      evaluate(p, li, base, importance_rng, in, splats, velocities, rays, value_only);
}

void IndirectBoundary::evaluate(const BoundaryPoint& p, int light, const Pcg32& rng0, const Pcg32& rng_importance, PathInputs& in,
                                std::vector<Splat>& splats, std::vector<Var>& velocities, uint64_t& rays, bool value_only) const {
  const bool delta_light = light >= 0;
  const Vec3 &xb = p.xb, &w = p.w, &n_b = p.n_b;
  const float delta = p.delta;
  // Importance: the observing surface along +w, connected to the camera.
  const int max_depth = m_max_depth;
  if (max_depth >= 0 && max_depth < 2) return;  // camera -> observer -> edge needs two segments
  Ray ray{xb + delta * p.n_out, w, 0.0f, kInfinity};
  SurfaceInteraction y;
  rays++;
  if (!m_scene.intersect(ray, y)) return;
  const float dist_y = y.t;

  struct Connection {
    glm::dvec2 film;  // where it lands on the film (spread over pixels by the filter)
    Spectrum value;
    int depth;  // segments from the camera to the observing vertex that sees the edge region
    int stack;  // -1 direct; seen directly through a stack or mirror chain: its slot in stack_dirs; -2 otherwise
  };
  thread_local std::vector<Vec3> stack_dirs;  // per stack, then per mirror chain: the last segment's direction at y (towards y)
  stack_dirs.assign(m_stacks.size() + m_mirror_chains.size(), Vec3(0.0f));
  thread_local std::vector<Connection> conns;  // scratch: no allocation per sample
  conns.clear();
  {
    Spectrum throughput(1.0f);
    SurfaceInteraction cur = y;
    Vec3 w_light = -w;  // at the observing vertex, light comes from the edge
    Pcg32 rng = rng_importance;
    // Bounded paths: camera -> ... -> observer (j segments) + probe segment + 1 more at least.
    const int bounces = max_depth < 0 ? kImportanceBounces : max_depth - 2;
    for (int j = 1;; ++j) {
      glm::dvec2 film;
      Spectrum v;
      if (connect_to_camera(m_scene, FilmProjection(m_scene.camera), cur, w_light, film, v, rays))
        conns.push_back({film, throughput * v, j, -1});
      for (size_t q = 0; q < m_stacks.size(); ++q) {
        Vec3 d_last;
        if (connect_through_stack(m_scene, m_stacks[q], FilmProjection(m_scene.camera), cur, w_light, film, v, d_last, rays)) {
          conns.push_back({film, throughput * v, j + int(m_stacks[q].offsets.size()), j == 1 ? int(q) : -2});
          if (j == 1) stack_dirs[q] = d_last;
        }
      }
      for (size_t q = 0; q < m_mirror_chains.size(); ++q) {
        Vec3 d_last;
        if (connect_through_mirrors(m_scene, m_mirror_chains[q], m_mirror_proj[q], m_mirror_eye[q], cur, w_light, film, v, d_last, rays)) {
          const size_t slot = m_stacks.size() + q;
          conns.push_back({film, throughput * v, j + int(m_mirror_chains[q].shapes.size()), j == 1 ? int(slot) : -2});
          if (j == 1) stack_dirs[slot] = d_last;
        }
      }
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

  // L_d: the jump of the path integrand across the boundary. The interior term attaches every
  // vertex after the camera ray to its surface (material form), so the occluder's own radiance is
  // already in it (its surface, not a direction range, is the integration domain) and the only
  // jump is the visibility of the segment from the observer to x_c past the boundary: blocked on
  // the occluder's side, L_bg on the other. L_d = 0 - L_bg, per path budget. (The primary term
  // differs: camera rays keep their direction, so there L_d = L_fg - L_bg.)
  std::map<int, Spectrum> delta_L;  // by remaining depth
  const Vec3 probe = xb + delta * n_b;  // beside the occluder, on its background side
  auto radiance_difference = [&](int budget) {
    auto it = delta_L.find(budget);
    if (it != delta_L.end()) return it->second;
    Spectrum L_bg(0.0f);
    if (delta_light) {
      // The light's delta along w reaches the probe unless something blocks it.
      const Emitter& em = m_scene.emitters[light];
      Ray shadow;
      Spectrum value;
      if (const auto* pl = std::get_if<PointEmitter>(&em.model)) {
        const Vec3 d = pl->position - probe;
        const float dist = glm::length(d);
        shadow = Ray{probe, d / dist, 0.0f, dist * (1.0f - 1e-4f)};
        value = pl->intensity_towards(probe) / (dist * dist);
      } else {
        shadow = Ray{probe, -w, 0.0f, kInfinity};
        value = std::get<DirectionalEmitter>(em.model).irradiance;
      }
      rays++;
      if (!m_scene.occluded(shadow)) L_bg = value;
    } else {
      // From half way towards the observer, along -w: the segment to the observer is empty.
      const float back = 0.5f * dist_y;
      Pcg32 r = rng0;
      PathCounters counters;
      L_bg = path_radiance(m_scene, Ray{probe + back * w, -w, 0.0f, kInfinity}, r, counters, PathLimits{budget, false});
      rays += counters.rays;
    }
    delta_L[budget] = -L_bg;
    return -L_bg;
  };

  // Normal velocity of the boundary relative to the segment (y, x_c) that grazes it. The interior
  // term moves both ends with their surfaces (y slides along the camera ray when the camera sees
  // it directly, and is attached to its surface when reached by a BSDF sample; x_c is attached), so
  // the boundary moves by v_b - (1 - s) v_y - s v_c along n_b, s = |x_b - y| / |x_c - y| (Zhang et
  // al. 2020's relative velocity; s = 0 when x_c is at infinity). Moving occluders, receivers and
  // self-shadowing shapes all go through this one expression.
  const VV nb(Var(n_b.x), Var(n_b.y), Var(n_b.z));
  const Var v_b = dot(m_space.attached_point(p, in), nb);
  // Only the value is wanted (guide_value): a moving x_b makes every velocity below non-constant
  // (a sum with a non-constant term is never folded to a constant, core/diff/ad/ad.h), so the
  // ray to x_c and y's attached point would change nothing. Curves, coil in the reflection scene:
  // that ray grazes the tube and is about a third of the guide's rays (issue 36).
  const bool values_alone = value_only && !v_b.is_constant();
  float s = 0.0f;
  Var v_c(0.0);
  if (values_alone) {
    // s and v_c enter the velocities alone.
  } else if (delta_light) {
    if (const auto* pl = std::get_if<PointEmitter>(&m_scene.emitters[light].model))
      s = dist_y / (dist_y + glm::length(pl->position - xb));
  } else {
    const float back = 0.5f * dist_y;
    SurfaceInteraction xc;
    rays++;
    if (m_scene.intersect(Ray{probe + back * w, -w, 0.0f, kInfinity}, xc)) {
      s = dist_y / (dist_y + std::max(xc.t - back, 0.0f));
      if (m_params.moves(xc.shape)) v_c = dot(attached_position(DiffContext{m_scene, m_params, in}, SurfacePoint::of(xc)), nb);
    }
  }
  const Var v_ends = v_b - Var(s) * v_c;
  int vi_slide = -1, vi_attached = -1;
  if (values_alone || !m_params.moves(y.shape)) {
    vi_slide = vi_attached = int(velocities.size());
    velocities.push_back(v_ends);
  } else {
    const VV y_att = attached_position(DiffContext{m_scene, m_params, in}, SurfacePoint::of(y));
    vi_attached = int(velocities.size());
    velocities.push_back(v_ends - Var(1.0f - s) * dot(y_att, nb));
    // Sliding along the camera ray d: y moves by d (u . n_y) / (d . n_y) for a surface velocity u.
    const Vec3 d = glm::normalize(y.p - m_scene.camera.world_from_camera.point(Vec3(0.0f)));
    const float dn = glm::dot(d, y.ng);
    vi_slide = int(velocities.size());
    velocities.push_back(v_ends - Var((1.0f - s) * glm::dot(d, n_b) / dn) * dot(y_att, VV(Var(y.ng.x), Var(y.ng.y), Var(y.ng.z))));
  }
  for (const Connection& c : conns) {
    int vi = c.depth == 1 ? vi_slide : vi_attached;
    if (c.stack >= 0 && m_params.moves(y.shape) && !values_alone) {
      // y seen through a stack slides along the stack's last segment (static interfaces).
      const Vec3& d = stack_dirs[size_t(c.stack)];
      const VV y_att = attached_position(DiffContext{m_scene, m_params, in}, SurfacePoint::of(y));
      vi = int(velocities.size());
      velocities.push_back(v_ends - Var((1.0f - s) * glm::dot(d, n_b) / glm::dot(d, y.ng)) *
                                        dot(y_att, VV(Var(y.ng.x), Var(y.ng.y), Var(y.ng.z))));
    }
    if (velocities[size_t(vi)].is_constant()) continue;  // nothing at either end of the segment moves
    const int budget = max_depth < 0 ? -1 : max_depth - c.depth;
    if (max_depth >= 0 && budget < 1) continue;
    const Spectrum dL = radiance_difference(budget);
    if (is_black(dL)) continue;
    const Spectrum value = dL * c.value * (p.jacobian / p.pdf);
    if (is_finite(value)) m_scene.camera.splat(c.film.x, c.film.y, [&](int pixel, float wf) { splats.push_back({pixel, value * wf, vi}); });
  }
}

}  // namespace limn
