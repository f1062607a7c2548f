#include "core/diff/terms/delta_chains.h"

#include <algorithm>
#include <map>
#include <set>
#include "core/render/bsdfs/fresnel.h"
#include "core/math/frame.h"

namespace limn {
namespace {

// Camera rays on a kGrid^2 grid over the image, followed through at most kMaxChain delta
// vertices; at most kMaxChains chains of each sort (those hit by most rays).
constexpr int kGrid = 64, kMaxChain = 4;
constexpr size_t kMaxChains = 16;
// A plane needs this many grid rays on it: a curved mirror gives every ray a plane of its own.
constexpr int kMinPlaneHits = 3;
// Two hits are on one plane when their normals differ by less than 1e-5 rad (float normals of one
// flat facet agree to ~1e-7; neighbouring grid rays on a curved mirror differ by ~1e-3) and their
// plane offsets by 1e-5 of the distance from the origin (float positions).
constexpr double kPlaneAngle = 1e-5, kPlaneOffset = 1e-5;

struct Plane {
  int shape;
  Vec3d n0;  // first hit's normal and offset: the cluster's key
  double d0;
  Vec3d n_sum{0.0};
  double d_sum = 0.0;
  int hits = 0;
  Vec3d n() const { return glm::normalize(n_sum); }
  double d() const { return d_sum / hits; }
};

class Planes {
 public:
  int add(const SurfaceInteraction& si) {
    const Vec3d n = glm::normalize(Vec3d(si.ng)), p(si.p);
    const double d = glm::dot(n, p);
    int found = -1;
    for (size_t q = 0; q < m_planes.size() && found < 0; ++q) {
      const Plane& pl = m_planes[q];
      if (pl.shape == si.shape && glm::length(glm::cross(pl.n0, n)) < kPlaneAngle && glm::dot(pl.n0, n) > 0.0 &&
          std::abs(pl.d0 - d) < kPlaneOffset * (1.0 + glm::length(p)))
        found = int(q);
    }
    if (found < 0) {
      found = int(m_planes.size());
      m_planes.push_back(Plane{si.shape, n, d});
    }
    Plane& pl = m_planes[size_t(found)];
    pl.n_sum += n;
    pl.d_sum += d;
    pl.hits++;
    return found;
  }
  const Plane& operator[](int q) const { return m_planes[size_t(q)]; }
  const std::vector<Plane>& all() const { return m_planes; }

 private:
  std::vector<Plane> m_planes;
};

// Reflection across the plane n . x = d (a 4x4 affine matrix, glm's column-major order).
Mat4d reflection(const Vec3d& n, double d) {
  Mat4d m(1.0);
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) m[c][r] -= 2.0 * n[r] * n[c];
  for (int r = 0; r < 3; ++r) m[3][r] = 2.0 * d * n[r];
  return m;
}

bool flat_facet(const SurfaceInteraction& si) {
  return std::abs(glm::dot(si.ns, si.ng)) >= 1.0f - 1e-6f;  // 1e-6: float rounding of two unit vectors of one facet
}

struct Vertex {
  int plane;
  double ior_after;  // refraction chains: index of the layer after the crossing
};

// Traces the grid, reflecting (refract = false) or refracting (true) at every delta vertex, and
// counts the chains of planes met.
std::map<std::vector<int>, int> trace_chains(const Scene& scene, bool refract, Planes& planes, std::set<int>& curved,
                                             std::map<int, double>& ior_after) {
  std::map<std::vector<int>, int> chains;
  const Camera& cam = scene.camera;
  for (int j = 0; j < kGrid; ++j)
    for (int i = 0; i < kGrid; ++i) {
      Ray ray = cam.generate_ray(Vec2(float((i + 0.5) * cam.width / kGrid), float((j + 0.5) * cam.height / kGrid)));
      std::vector<int> chain;
      double ior = 1.0;
      for (int k = 0; k < kMaxChain; ++k) {
        SurfaceInteraction si;
        if (!scene.intersect(ray, si)) break;
        const Shape& shape = scene.shapes[si.shape];
        if (shape.bsdf < 0) break;
        const Bsdf& bsdf = scene.bsdfs[shape.bsdf];
        if (!bsdf.is_delta()) break;
        const auto* diel = std::get_if<Dielectric>(&bsdf.model);
        if (refract && !diel) break;
        if (!flat_facet(si)) {
          curved.insert(si.shape);
          break;
        }
        const int q = planes.add(si);
        Vec3 wo;
        if (refract) {
          const float cos_i = -glm::dot(ray.d, si.ng);
          const DielectricFresnel fr = fresnel_dielectric(cos_i, diel->eta);
          if (fr.cos_t == 0.0f) break;  // total internal reflection
          ior *= fr.eta_it;
          // Refraction about ng: wo = -eta_ti (-d) + (eta_ti cos_i + cos_t) ng, cos_t signed.
          wo = glm::normalize(fr.eta_ti * ray.d + (fr.eta_ti * cos_i + fr.cos_t) * si.ng);
          chain.push_back(q);
          ior_after[q] = ior;  // the same for every ray crossing this plane the same way round
        } else {
          wo = reflect(-ray.d, si.ng);
          chain.push_back(q);
        }
        chains[chain]++;
        ray = spawn_ray(si, wo);
      }
    }
  return chains;
}

}  // namespace

DeltaChains find_delta_chains(const Scene& scene, const DiffParams& params) {
  DeltaChains out;
  bool any_delta = false;
  for (const Shape& s : scene.shapes) any_delta = any_delta || (s.bsdf >= 0 && scene.bsdfs[s.bsdf].is_delta());
  if (!any_delta) return out;
  std::set<int> curved, few, moving;
  auto usable = [&](const Planes& planes, const std::vector<int>& chain) {
    bool ok = true;
    for (int q : chain) {
      if (planes[q].hits < kMinPlaneHits) {
        few.insert(planes[q].shape);
        ok = false;
      }
      if (params.moves(planes[q].shape)) {
        moving.insert(planes[q].shape);
        ok = false;
      }
    }
    return ok;
  };
  size_t dropped = 0;
  {  // mirror chains
    Planes planes;
    std::map<int, double> unused;
    std::vector<std::pair<int, std::vector<int>>> ranked;
    for (const auto& [chain, count] : trace_chains(scene, false, planes, curved, unused))
      if (usable(planes, chain)) ranked.push_back({count, chain});
    std::stable_sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    for (size_t v = 0; v < ranked.size(); ++v) {
      if (v >= kMaxChains) {
        dropped++;
        continue;
      }
      Mat4d m = scene.camera.world_from_camera.matrix();
      MirrorChain mc;
      for (int q : ranked[v].second) {
        m = reflection(planes[q].n(), planes[q].d()) * m;
        mc.n.push_back(planes[q].n());
        mc.d.push_back(planes[q].d());
        mc.shapes.push_back(planes[q].shape);
      }
      Camera c = scene.camera;
      c.world_from_camera = Transform(m);
      out.mirror_cameras.push_back(c);
      out.mirror_chains.push_back(mc);
    }
  }
  {  // refraction stacks: parallel planes, the same medium at both ends
    Planes planes;
    std::map<int, double> ior_after;
    std::vector<std::pair<int, std::vector<int>>> ranked;
    for (const auto& [chain, count] : trace_chains(scene, true, planes, curved, ior_after)) {
      if (!usable(planes, chain)) continue;
      bool parallel = true;
      for (int q : chain) parallel = parallel && glm::length(glm::cross(planes[q].n(), planes[chain[0]].n())) < kPlaneAngle;
      // Unequal end media (a camera in air looking into water) would need the eta^2 radiance scale.
      if (parallel && std::abs(ior_after[chain.back()] - 1.0) < 1e-4) ranked.push_back({count, chain});
    }
    std::stable_sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    for (size_t v = 0; v < ranked.size(); ++v) {
      if (v >= kMaxChains) {
        dropped++;
        continue;
      }
      const std::vector<int>& chain = ranked[v].second;
      RefractionStack st;
      // Orient the normal along the camera rays: the eye is on the negative side of every plane.
      const Vec3d eye(scene.camera.world_from_camera.point(Vec3(0.0f)));
      const Vec3d n0 = planes[chain[0]].n();
      const double sign = glm::dot(n0, eye) < planes[chain[0]].d() ? 1.0 : -1.0;
      st.n = sign * n0;
      st.ior.push_back(1.0);
      for (int q : chain) {
        const double dq = planes[q].d() * (glm::dot(planes[q].n(), n0) > 0.0 ? 1.0 : -1.0);  // offset along n0
        st.offsets.push_back(sign * dq);
        st.ior.push_back(ior_after[q]);
        st.shapes.push_back(planes[q].shape);
      }
      bool increasing = true;
      for (size_t i = 1; i < st.offsets.size(); ++i) increasing = increasing && st.offsets[i] > st.offsets[i - 1];
      if (increasing) out.stacks.push_back(st);
    }
  }
  for (int sh : curved)
    out.notes.push_back("delta surface '" + scene.shapes[sh].id + "' reflects through interpolated normals: what is seen in or through it has no boundary term");
  for (int sh : few)
    if (!curved.count(sh)) out.notes.push_back("delta surface '" + scene.shapes[sh].id + "' is curved: what is seen in or through it has no boundary term");
  for (int sh : moving)
    out.notes.push_back("delta surface '" + scene.shapes[sh].id + "' moves: what is seen in or through it has no boundary term");
  if (dropped)
    out.notes.push_back(std::to_string(dropped) + " chains of delta vertices seen by fewer camera rays left out (at most " +
                        std::to_string(kMaxChains) + " of each sort)");
  return out;
}

bool connect_through_stack(const Scene& scene, const RefractionStack& st, const SurfaceInteraction& si, Vec3& d_eye_out, Vec3& d_last_out,
                           double& domega_dA, Spectrum& transmittance, uint64_t& rays) {
  const Vec3d eye(scene.camera.world_from_camera.point(Vec3(0.0f))), y(si.p);
  const size_t k = st.offsets.size();
  // Layer thicknesses along n: eye -> plane 1, between planes, last plane -> y.
  std::vector<double> h(k + 1);
  h[0] = st.offsets[0] - glm::dot(st.n, eye);
  for (size_t i = 1; i < k; ++i) h[i] = st.offsets[i] - st.offsets[i - 1];
  h[k] = glm::dot(st.n, y) - st.offsets[k - 1];
  for (double hi : h)
    if (!(hi > 0.0)) return false;
  const Vec3d lateral = (y - eye) - glm::dot(y - eye, st.n) * st.n;
  const double H = glm::length(lateral);
  const Vec3d u = H > 0.0 ? lateral / H : Vec3d(0.0);
  // Snell: s = n_i sin(theta_i) along the stack; H(s) = sum h_i s / sqrt(n_i^2 - s^2) increases
  // from 0 to infinity on [0, min n_i): Newton steps kept inside a bisection bracket.
  double s_hi = st.ior[0];
  for (double n : st.ior) s_hi = std::min(s_hi, n);
  double lo = 0.0, hi = s_hi, s = 0.0;
  auto sums = [&](double s_, double& S1, double& S2) {  // S1 = sum h / c, S2 = sum h n^2 / c^3, c = sqrt(n^2 - s^2)
    S1 = S2 = 0.0;
    for (size_t i = 0; i <= k; ++i) {
      const double n2 = st.ior[i] * st.ior[i], c = std::sqrt(n2 - s_ * s_);
      S1 += h[i] / c;
      S2 += h[i] * n2 / (c * c * c);
    }
  };
  double S1, S2;
  for (int it = 0; it < 100; ++it) {
    sums(s, S1, S2);
    const double f = s * S1 - H;
    if (std::abs(f) <= 1e-12 * (H + h[0])) break;
    (f > 0.0 ? hi : lo) = s;
    const double next = s - f / S2;  // dH/ds = S2
    s = next > lo && next < hi ? next : 0.5 * (lo + hi);
  }
  sums(s, S1, S2);
  if (!(std::abs(s * S1 - H) <= 1e-9 * (H + h[0]))) return false;
  auto direction = [&](size_t i) {
    const double si_ = s / st.ior[i];
    return si_ * u + std::sqrt(std::max(0.0, 1.0 - si_ * si_)) * st.n;
  };
  const double cos0 = std::sqrt(std::max(0.0, 1.0 - s * s / (st.ior[0] * st.ior[0])));
  const Vec3d d_last = direction(k);
  const double cos_y = std::abs(glm::dot(Vec3d(si.ng), d_last));
  // d omega / dA_y: 1 / (cos_0 S1 S2) per area across n at y (with n_0 = 1), times the area
  // projection |cos_y| / cos_k (docs/derivatives.md).
  const double cos_k = glm::dot(d_last, st.n);
  domega_dA = cos_y / (cos0 * S1 * S2 * cos_k);
  // Trace the path from the eye: every crossing must be the stack's plane on its shape.
  Ray ray{Vec3(eye), Vec3(direction(0)), 0.0f, kInfinity};
  Spectrum T(1.0f);
  for (size_t i = 0; i < k; ++i) {
    SurfaceInteraction c;
    rays++;
    if (!scene.intersect(ray, c) || c.shape != st.shapes[i]) return false;
    // 1e-4: the hit's offset along n agrees with the plane to float rounding of the scene's scale.
    if (std::abs(glm::dot(st.n, Vec3d(c.p)) - st.offsets[i]) > 1e-4 * (1.0 + glm::length(Vec3d(c.p)))) return false;
    const auto* diel = std::get_if<Dielectric>(&scene.bsdfs[scene.shapes[c.shape].bsdf].model);
    if (!diel) return false;
    const double n_lo = std::min(st.ior[i], st.ior[i + 1]), n_hi = std::max(st.ior[i], st.ior[i + 1]);
    const double cos_lo = std::sqrt(std::max(0.0, 1.0 - s * s / (n_lo * n_lo)));
    T *= diel->specular_transmittance * (1.0f - fresnel_dielectric(float(cos_lo), float(n_hi / n_lo)).F);
    ray = spawn_ray(c, Vec3(direction(i + 1)));
  }
  // The last segment reaches y unblocked (1e-4: y itself is not an occluder).
  const Vec3 to_y = si.p - ray.o;
  const float dist = glm::length(to_y);
  rays++;
  if (scene.occluded(Ray{ray.o, to_y / dist, 0.0f, dist * (1.0f - 1e-4f)})) return false;
  d_eye_out = Vec3(direction(0));
  d_last_out = Vec3(d_last);
  transmittance = T;
  return std::isfinite(domega_dA) && domega_dA > 0.0;
}

bool connect_through_mirrors(const Scene& scene, const MirrorChain& chain, const Vec3& eye_virtual, const SurfaceInteraction& si,
                             Spectrum& reflectance, uint64_t& rays) {
  const Vec3 eye = scene.camera.world_from_camera.point(Vec3(0.0f));
  Vec3 d = glm::normalize(eye_virtual - si.p);
  Ray ray = spawn_ray(si, d);
  Spectrum R(1.0f);
  for (size_t i = chain.shapes.size(); i-- > 0;) {
    SurfaceInteraction c;
    rays++;
    if (!scene.intersect(ray, c) || c.shape != chain.shapes[i]) return false;
    // 1e-4: the hit agrees with the plane to float rounding of the scene's scale.
    if (std::abs(glm::dot(chain.n[i], Vec3d(c.p)) - chain.d[i]) > 1e-4 * (1.0 + glm::length(Vec3d(c.p)))) return false;
    const Bsdf& bsdf = scene.bsdfs[scene.shapes[c.shape].bsdf];
    const float cos_i = glm::dot(-d, c.ng);  // towards where the light came from
    if (const auto* m = std::get_if<Conductor>(&bsdf.model)) {
      if (cos_i <= 0.0f && !bsdf.twosided) return false;  // one-sided conductors reflect on the front only
      R *= m->specular_reflectance * fresnel_conductor(std::abs(cos_i), m->eta, m->k);
    } else if (const auto* g = std::get_if<Dielectric>(&bsdf.model)) {
      R *= g->specular_reflectance * fresnel_dielectric(cos_i, g->eta).F;
    } else {
      return false;
    }
    d = reflect(-d, c.ng);
    ray = spawn_ray(c, d);
  }
  // The last segment reaches the eye (1e-4: the eye is a point, not an occluder).
  const Vec3 to_eye = eye - ray.o;
  const float dist = glm::length(to_eye);
  if (glm::dot(to_eye / dist, d) < 1.0f - 1e-5f) return false;  // the chain's planes were not these (1e-5: float directions)
  rays++;
  if (scene.occluded(Ray{ray.o, to_eye / dist, 0.0f, dist * (1.0f - 1e-4f)})) return false;
  reflectance = R;
  return !is_black(R);
}

}  // namespace limn
