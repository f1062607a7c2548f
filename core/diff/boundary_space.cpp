#include "core/diff/boundary_space.h"

#include <algorithm>

#include "core/math/frame.h"
#include "core/math/warp.h"

namespace limn {
namespace {

uint32_t opposite_vertex(const Mesh& m, int f, uint32_t a, uint32_t b) {
  for (int k = 0; k < 3; ++k) {
    const uint32_t v = m.indices[3 * f + k];
    if (v != a && v != b) return v;
  }
  return a;
}

// Probe offset: a fraction of the local feature size keeps the probes beside this boundary only;
// the second term (~8 ulps of |x_b|) keeps them above float resolution.
float probe_offset(float feature_size, const Vec3& xb) { return 1e-4f * feature_size + 1e-6f * max_component(glm::abs(xb)); }

// 30-bit Morton code of p inside the cube at lo with the box [lo, hi]'s largest side (10 bits per
// axis; one scale for all axes, so that a thin axis does not split patches as a full one would).
uint32_t morton_code(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  const float extent = max_component(hi - lo);
  auto spread = [](uint32_t v) {  // 10 bits -> every third bit
    v = (v | (v << 16)) & 0x030000FFu;
    v = (v | (v << 8)) & 0x0300F00Fu;
    v = (v | (v << 4)) & 0x030C30C3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
  };
  uint32_t code = 0;
  for (int a = 0; a < 3; ++a) {
    const float f = extent > 0.0f ? std::clamp((p[a] - lo[a]) / extent, 0.0f, 1.0f) : 0.0f;
    code |= spread(std::min(1023u, uint32_t(f * 1024.0f))) << a;
  }
  return code;
}

float wrap_unit(float x) {
  x -= std::floor(x);
  return std::min(x, std::nextafter(1.0f, 0.0f));
}

}  // namespace

bool edge_can_be_silhouette(const Mesh& m, const MeshEdge& e) {
  if (e.face_count != 2) return true;
  // Convex and not flat: the third vertex of one face lies strictly below the other's plane (1e-6 of
  // the edge length: below that the dihedral angle is numerically flat).
  const Vec3d n0 = m.oriented_normal(e.face0);
  const Vec3 c = m.vertex(opposite_vertex(m, e.face1, e.a, e.b));
  const double h = glm::dot(n0, Vec3d(c - m.vertex(e.a)));
  return h < -1e-6 * glm::length(Vec3d(m.vertex(e.b) - m.vertex(e.a)));
}

int edge_side(const Mesh& m, const MeshEdge& e, const Vec3& d) {
  // The side of each triangle's third vertex c: the sign of (b - a) x d . (c - a).
  const Vec3 a = m.vertex(e.a), n = glm::cross(m.vertex(e.b) - a, d);
  int below = 0, above = 0;
  m.for_each_edge_face(e, [&](int f) {
    const float side = glm::dot(n, m.vertex(opposite_vertex(m, f, e.a, e.b)) - a);
    below += side < 0.0f;
    above += side > 0.0f;
  });
  if (below + above != e.face_count || (below > 0 && above > 0)) return 0;  // straddled, or edge-on
  return above > 0 ? 1 : -1;
}

BoundarySpace::BoundarySpace(const Scene& scene, const DiffParams& params) : m_scene(scene), m_params(params) {
  // Moving shapes first, then static ones: a static silhouette matters too when a segment grazing
  // it ends on a moving surface (a receiver moving under a static occluder).
  std::vector<int> order = params.moving_shapes();
  const size_t moving_count = order.size();
  for (size_t i = 0; i < scene.shapes.size(); ++i)
    if (!moves_geometry(params, int(i))) order.push_back(int(i));
  double moving_measure = 0.0, static_measure = 0.0;
  for (int pass = 0; pass < 2; ++pass)  // meshes, then spheres
    for (size_t oi = 0; oi < order.size(); ++oi) {
      const int si = order[oi];
      const Shape& shape = scene.shapes[si];
      const bool moving = oi < moving_count;
      if (pass == 0 && shape.is_mesh()) {
        const Mesh& m = shape.mesh();
        // Edges in Morton order of their midpoints: neighbouring u.x then means neighbouring edges,
        // so a guide's slab or cell along the first axis holds one patch of the surface instead of
        // edges from all over it (a scanned mesh's edge order is nearly random in space).
        Vec3 lo(kInfinity), hi(-kInfinity);
        for (size_t v = 0; v < m.vertex_count(); ++v) {
          lo = glm::min(lo, m.vertex(uint32_t(v)));
          hi = glm::max(hi, m.vertex(uint32_t(v)));
        }
        std::vector<std::pair<uint32_t, const MeshEdge*>> ordered;
        for (const MeshEdge& e : m.edges) {
          if (!edge_can_be_silhouette(m, e)) continue;
          const float len = glm::length(m.vertex(e.b) - m.vertex(e.a));
          if (!(len > 0.0f)) continue;
          ordered.push_back({morton_code(0.5f * (m.vertex(e.a) + m.vertex(e.b)), lo, hi), &e});
        }
        std::stable_sort(ordered.begin(), ordered.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
        for (const auto& [code, ep] : ordered) {
          const MeshEdge& e = *ep;
          m_segments.push_back({BoundarySegment::Kind::MeshEdge, si, moving, e.a, e.b, e.face0, e.face_count == 2 ? e.face1 : -1,
                                int(ep - m.edges.data())});
          m_measure.push_back(4.0f * kPi * glm::length(m.vertex(e.b) - m.vertex(e.a)));
          (moving ? moving_measure : static_measure) += m_measure.back();
        }
      } else if (pass == 1 && shape.is_sphere()) {  // heightfields: their own estimator (core/heightfield)
        m_segments.push_back({BoundarySegment::Kind::SphereSurface, si, moving});
        m_measure.push_back(8.0f * kPi * kPi * shape.sphere().radius);
        (moving ? moving_measure : static_measure) += m_measure.back();
      }
    }
  m_edges = 0;
  for (const BoundarySegment& seg : m_segments) m_edges += seg.kind == BoundarySegment::Kind::MeshEdge;
  // Static segments get at most a quarter of the samples: they contribute only where a moving
  // surface ends the segment, moving ones wherever they are seen.
  if (moving_measure > 0.0 && static_measure > 0.0) {
    const double scale = std::min(1.0, (0.25 / 0.75) * moving_measure / static_measure);
    for (size_t i = 0; i < m_segments.size(); ++i)
      if (!m_segments[i].moving) m_measure[i] = float(m_measure[i] * scale);
  }
  if (!m_measure.empty()) m_select = Distribution1D(m_measure);
}

size_t BoundarySpace::static_count() const {
  size_t n = 0;
  for (const BoundarySegment& seg : m_segments) n += !seg.moving;
  return n;
}

bool BoundarySpace::finish_edge(const BoundarySegment& s, float lambda, const Vec3& w, BoundaryPoint& out) const {
  const Mesh& m = m_scene.shapes[s.shape].mesh();
  const Vec3 a = m.vertex(s.a), b = m.vertex(s.b);
  const float len = glm::length(b - a);
  const Vec3 t = (b - a) / len;
  const Vec3 txw = glm::cross(t, w);
  const float sin_phi = glm::length(txw);
  if (!(sin_phi > 1e-6f)) return false;  // w along the edge: the edge is invisible in that direction
  const MeshEdge& e = m.edges[size_t(s.edge)];
  const int side = edge_side(m, e, w);
  if (side == 0) return false;
  out.n_b = txw / sin_phi * float(-side);  // away from the occluder
  const Vec3d n0 = m.oriented_normal(s.face0);
  if (e.face_count == 1) out.n_out = Vec3(n0) * (glm::dot(n0, Vec3d(w)) >= 0.0 ? 1.0f : -1.0f);
  else if (e.face_count == 2) out.n_out = Vec3(glm::normalize(n0 + m.oriented_normal(e.face1)));
  else out.n_out = out.n_b;  // the side no triangle is on
  out.xb = a + lambda * (b - a);
  out.w = w;
  out.jacobian = sin_phi;
  out.delta = probe_offset(len, out.xb);
  out.param = Vec3(lambda, 0.0f, 0.0f);
  return true;
}

void BoundarySpace::finish_sphere(const BoundarySegment& s, const Vec3& n, const Vec3& w, BoundaryPoint& out) const {
  const Sphere& sp = m_scene.shapes[s.shape].sphere();
  out.xb = sp.center + sp.radius * n;
  out.w = w;
  out.n_b = n;  // growing along n covers the background with the sphere
  out.n_out = n;
  out.jacobian = 1.0f / sp.radius;  // normal curvature, the same in every direction
  out.delta = probe_offset(sp.radius, out.xb);
  out.param = n;
}

// The segment for u0 and the offset along it, kept below 1 after rounding to float.
float BoundarySpace::select(float u0, size_t* k) const { return float(std::min(m_select.sample_remapped(u0, k), 1.0 - 1e-7)); }

bool BoundarySpace::sample(const Vec3& u, float pdf_u, BoundaryPoint& out) const {
  size_t k;
  const float f = select(u.x, &k);
  const BoundarySegment& s = m_segments[k];
  out.segment = int(k);
  if (s.kind == BoundarySegment::Kind::MeshEdge) {
    const Vec3 w = warp::square_to_uniform_sphere(Vec2(u.y, u.z));
    if (!finish_edge(s, f, w, out)) return false;
    const Mesh& m = m_scene.shapes[s.shape].mesh();
    const float len = glm::length(m.vertex(s.b) - m.vertex(s.a));
    out.pdf = pdf_u * m_select.pmf(k) / len * warp::square_to_uniform_sphere_pdf();
    return true;
  }
  const Sphere& sp = m_scene.shapes[s.shape].sphere();
  const Vec3 n = warp::square_to_uniform_sphere(Vec2(f, u.y));
  const Frame frame(n);
  const float phi = 2.0f * kPi * u.z;
  finish_sphere(s, n, std::cos(phi) * frame.s + std::sin(phi) * frame.t, out);
  out.pdf = pdf_u * m_select.pmf(k) / sp.area() * kInvTwoPi;
  return true;
}

Vec3 BoundarySpace::invert(int segment, const Vec3& xb, const Vec3& w) const {
  const BoundarySegment& s = m_segments[size_t(segment)];
  if (s.kind == BoundarySegment::Kind::MeshEdge) {
    const Mesh& m = m_scene.shapes[s.shape].mesh();
    const Vec3 a = m.vertex(s.a), ab = m.vertex(s.b) - a;
    const float lambda = std::clamp(glm::dot(xb - a, ab) / glm::dot(ab, ab), 0.0f, std::nextafter(1.0f, 0.0f));
    const Vec2 d = warp::uniform_sphere_to_square(w);
    return Vec3(m_select.invert_remapped(size_t(segment), lambda), d.x, d.y);
  }
  const Sphere& sp = m_scene.shapes[s.shape].sphere();
  const Vec3 n = glm::normalize(xb - sp.center);
  const Vec2 q = warp::uniform_sphere_to_square(n);
  const Frame frame(n);
  const float phi = std::atan2(glm::dot(w, frame.t), glm::dot(w, frame.s));
  return Vec3(m_select.invert_remapped(size_t(segment), q.x), q.y, wrap_unit(phi * kInvTwoPi));
}

bool BoundarySpace::sample_delta(float u0, float pdf_u0, const Emitter& light, BoundaryPoint& out) const {
  size_t k;
  const float f = select(u0, &k);
  const BoundarySegment& s = m_segments[k];
  out.segment = int(k);
  const auto* point = std::get_if<PointEmitter>(&light.model);
  const auto* directional = std::get_if<DirectionalEmitter>(&light.model);
  if (!point && !directional) return false;
  if (s.kind == BoundarySegment::Kind::MeshEdge) {
    const Mesh& m = m_scene.shapes[s.shape].mesh();
    const Vec3 a = m.vertex(s.a), b = m.vertex(s.b);
    const Vec3 xb = a + f * (b - a);
    const Vec3 wl = point ? xb - point->position : directional->direction;
    if (!(glm::length(wl) > 0.0f) || !finish_edge(s, f, glm::normalize(wl), out)) return false;
    out.pdf = pdf_u0 * m_select.pmf(k) / glm::length(b - a);
    return true;
  }
  // The sphere's silhouette circle seen from the light: normals n with n . a_hat = cos(alpha),
  // a_hat towards the light, cos(alpha) = r / (distance to the light) (0 for directional lights).
  const Sphere& sp = m_scene.shapes[s.shape].sphere();
  Vec3 a_hat;
  float cos_alpha = 0.0f;
  if (point) {
    const Vec3 a = point->position - sp.center;
    const float dist = glm::length(a);
    if (!(dist > sp.radius * (1.0f + 1e-4f))) return false;  // the light is (almost) inside the sphere
    a_hat = a / dist;
    cos_alpha = sp.radius / dist;
  } else {
    a_hat = -directional->direction;
  }
  const float sin_alpha = safe_sqrt(1.0f - cos_alpha * cos_alpha);
  const Frame frame(a_hat);
  const float psi = 2.0f * kPi * f;
  const Vec3 n = glm::normalize(cos_alpha * a_hat + sin_alpha * (std::cos(psi) * frame.s + std::sin(psi) * frame.t));
  const Vec3 xb = sp.center + sp.radius * n;
  const Vec3 w = point ? glm::normalize(xb - point->position) : directional->direction;
  finish_sphere(s, n, w, out);
  out.jacobian = 1.0f;  // the circle's tangent is perpendicular to w: sin(phi) = 1
  out.pdf = pdf_u0 * m_select.pmf(k) / (2.0f * kPi * sp.radius * sin_alpha);
  return out.pdf > 0.0f && std::isfinite(out.pdf);
}

ad::V3<ad::Var> BoundarySpace::attached_point(const BoundaryPoint& p, PathInputs& in) const {
  const BoundarySegment& s = m_segments[size_t(p.segment)];
  if (s.kind == BoundarySegment::Kind::MeshEdge) {
    const ad::V3<ad::Var> va = diff_vertex(m_scene, m_params, in, s.shape, s.a), vb = diff_vertex(m_scene, m_params, in, s.shape, s.b);
    return va + (vb - va) * ad::Var(p.param.x);
  }
  const ad::V3<ad::Var> c = diff_sphere_center(m_scene, m_params, in, s.shape);
  const ad::Var r = diff_sphere_radius(m_scene, m_params, in, s.shape);
  return c + ad::V3<ad::Var>(ad::Var(p.param.x), ad::Var(p.param.y), ad::Var(p.param.z)) * r;
}

}  // namespace limn
