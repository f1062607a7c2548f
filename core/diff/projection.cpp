#include "core/diff/projection.h"

#include <algorithm>
#include <map>
#include <tuple>
#include "core/math/frame.h"

namespace limn {
namespace {

constexpr int kWalkSteps = 30;  // the paper's hybrid: 30 WALK, 1 JUMP, 30 WALK

// Cosine between triangle f's oriented normal and the direction from its centroid to xa.
double facing(const Mesh& m, int f, const Vec3& xa) {
  const uint32_t* i = &m.indices[3 * size_t(f)];
  const Vec3d c = (Vec3d(m.vertex(i[0])) + Vec3d(m.vertex(i[1])) + Vec3d(m.vertex(i[2]))) / 3.0;
  const Vec3d d = Vec3d(xa) - c;
  const double len = glm::length(d);
  return len > 0.0 ? glm::dot(m.oriented_normal(f), d) / len : 0.0;
}

// Whether segment s's edge is a silhouette seen from xa, by the boundary sample space's own rule
// (edge_side). The plane through the edge and xa - x is the same for every x on the edge, so the
// answer holds along the whole edge.
bool silhouette_from(const Mesh& m, const BoundarySegment& s, const Vec3& xa) {
  return edge_side(m, m.edges[size_t(s.edge)], xa - m.vertex(s.a)) != 0;
}

Vec3 closest_on_segment(const Vec3& a, const Vec3& b, const Vec3& p, float& lambda) {
  const Vec3 ab = b - a;
  // Kept 1e-4 away from the vertices: the edge's two faces decide the silhouette test there.
  lambda = std::clamp(glm::dot(p - a, ab) / glm::dot(ab, ab), 1e-4f, 1.0f - 1e-4f);
  return a + lambda * ab;
}

}  // namespace

Projector::Projector(const Scene& scene, const BoundarySpace& space, MeshProjection mode)
    : m_scene(scene), m_space(space), m_mode(mode) {
  std::map<std::tuple<int, uint32_t, uint32_t>, int> edge_segment;
  const auto& segs = space.segments();
  for (size_t i = 0; i < segs.size(); ++i) {
    const BoundarySegment& s = segs[i];
    if (s.kind == BoundarySegment::Kind::SphereSurface) m_sphere_segment[s.shape] = int(i);
    else edge_segment[{s.shape, std::min(s.a, s.b), std::max(s.a, s.b)}] = int(i);
  }
  for (const BoundarySegment& s : segs) {
    if (s.kind != BoundarySegment::Kind::MeshEdge || m_meshes.count(s.shape)) continue;
    const Mesh& m = scene.shapes[s.shape].mesh();
    MeshTopology& t = m_meshes[s.shape];
    const size_t F = m.triangle_count();
    t.neighbour.assign(3 * F, -1);
    t.segment.assign(3 * F, -1);
    auto local_edge = [&](int f, uint32_t a, uint32_t b) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t p = m.indices[3 * size_t(f) + k], q = m.indices[3 * size_t(f) + (k + 1) % 3];
        if ((p == a && q == b) || (p == b && q == a)) return k;
      }
      return -1;
    };
    t.normals.assign(m.vertex_count(), Vec3(0.0f));
    for (size_t f = 0; f < F; ++f) {
      if (m.distinct[f] != int(f)) continue;  // a duplicate in the other winding would cancel its twin
      const uint32_t* i = &m.indices[3 * f];
      const Vec3 c = float(m.orientation[f]) * glm::cross(m.vertex(i[1]) - m.vertex(i[0]), m.vertex(i[2]) - m.vertex(i[0]));
      if (std::isfinite(c.x + c.y + c.z))
        for (int k = 0; k < 3; ++k) t.normals[i[k]] += c;
    }
    for (Vec3& n : t.normals) n = glm::length(n) > 0.0f ? glm::normalize(n) : Vec3(0.0f);
    for (const MeshEdge& e : m.edges) {
      auto it = edge_segment.find({s.shape, std::min(e.a, e.b), std::max(e.a, e.b)});
      const int seg = it == edge_segment.end() ? -1 : it->second;
      for (int f : {e.face0, e.face1}) {
        if (f < 0) continue;
        const int k = local_edge(f, e.a, e.b);
        if (k < 0) continue;
        t.segment[3 * size_t(f) + k] = seg;
        if (e.face_count == 2) t.neighbour[3 * size_t(f) + k] = f == e.face0 ? e.face1 : e.face0;
      }
    }
  }
}

std::optional<Projection> Projector::project(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const {
  if (!hit.valid()) return std::nullopt;
  if (m_sphere_segment.count(hit.shape)) return project_sphere(xa, hit);
  if (m_meshes.count(hit.shape)) return project_mesh(xa, hit, rng);
  return std::nullopt;
}

std::optional<Projection> Projector::finish(int segment, const Vec3& xa, const Vec3& near, bool found, const Vec3& w_orig) const {
  const BoundarySegment& s = m_space.segments()[size_t(segment)];
  Vec3 xb = near;
  if (s.kind == BoundarySegment::Kind::MeshEdge) {
    const Mesh& m = m_scene.shapes[s.shape].mesh();
    const Vec3 a = m.vertex(s.a), b = m.vertex(s.b);
    if (found && !silhouette_from(m, s, xa)) return std::nullopt;
    float lambda;
    xb = closest_on_segment(a, b, near, lambda);
  }
  // Section 5: an approximate boundary segment x'_a -> x'_b suffices. Keeping the original direction
  // (made tangential on spheres) and letting x_a slide keeps what the segment saw at x_a, e.g. a
  // near-specular reflection towards the camera; the direction to x_a itself is the second choice.
  Vec3 first = w_orig;
  if (s.kind == BoundarySegment::Kind::SphereSurface) {
    const Vec3 n = glm::normalize(xb - m_scene.shapes[s.shape].sphere().center);
    first = w_orig - glm::dot(w_orig, n) * n;
  }
  for (const Vec3& d : {first, xa - xb}) {
    if (!(glm::length(d) > 0.0f) || !std::isfinite(d.x + d.y + d.z)) continue;
    const Vec3 w = glm::normalize(d);
    const Vec3 u = m_space.invert(segment, xb, w);
    BoundaryPoint check;
    if (m_space.sample(u, 1.0f, check) && check.segment == segment) return Projection{u, segment, check.xb, check.w, found};
  }
  return std::nullopt;  // neither direction sees a silhouette there
}

std::optional<Projection> Projector::project_sphere(const Vec3& xa, const SurfaceInteraction& hit) const {
  // Listing 1: the silhouette point seen from xa in the plane of xa, the centre and the hit.
  const Sphere& sp = m_scene.shapes[hit.shape].sphere();
  const int segment = m_sphere_segment.at(hit.shape);
  const Vec3 co = xa - sp.center;
  const float dist = glm::length(co);
  const Vec3 n = glm::normalize(hit.p - sp.center);
  if (!(dist > sp.radius * (1.0f + 1e-4f))) {
    // xa (almost) inside: no silhouette; keep x_b, take the tangential direction closest to xa - x_b.
    const Vec3 w0 = glm::normalize(xa - hit.p);
    const Vec3 t = w0 - glm::dot(w0, n) * n;
    if (!(glm::length(t) > 1e-6f)) return std::nullopt;
    const Vec3 xb = sp.center + sp.radius * n;
    return Projection{m_space.invert(segment, xb, glm::normalize(t)), segment, xb, glm::normalize(t), false};
  }
  const Vec3 co_dir = co / dist;
  Vec3 side = n - glm::dot(n, co_dir) * co_dir;
  if (!(glm::length(side) > 1e-6f)) {  // the hit faces xa head-on: any side will do
    const Frame f(co_dir);
    side = f.s;
  }
  side = glm::normalize(side);
  const float sin_phi = sp.radius / dist;
  const Vec3 nb = co_dir * sin_phi + side * safe_sqrt(1.0f - sin_phi * sin_phi);
  return finish(segment, xa, sp.center + sp.radius * nb, true, glm::normalize(xa - hit.p));
}

int Projector::walk(int shape, const Vec3& xa, const Vec3& near, int& f, int steps, Pcg32& rng, int& taken) const {
  const Mesh& m = m_scene.shapes[shape].mesh();
  const MeshTopology& t = m_meshes.at(shape);
  int previous = -1;  // not straight back: on bumps two triangles can otherwise trade places forever
  for (int step = 0; step < steps; ++step) {
    // Towards the other facing than the current triangle's: after crossing a concave fold (not a
    // silhouette) onto a back-facing triangle, the crest beside it is the silhouette to find.
    const double s0 = facing(m, f, xa) >= 0.0 ? 1.0 : -1.0;
    // A silhouette edge of f: the face across looks the other way, or an open edge in the space.
    // When f has several (a corner of a flat-shaded box), the one nearest to the hit: taking the
    // first in index order sent every hit on a face to the same edge.
    double score[3];
    int found = -1;
    float found_dist = kInfinity;
    for (int k = 0; k < 3; ++k) {
      const int g = t.neighbour[3 * size_t(f) + k], seg = t.segment[3 * size_t(f) + k];
      const Vec3 a = m.vertex(m.indices[3 * size_t(f) + k]), b = m.vertex(m.indices[3 * size_t(f) + (k + 1) % 3]);
      if (seg >= 0 && silhouette_from(m, m_space.segments()[size_t(seg)], xa)) {  // ranked by its point nearest to `near`
        float lambda;
        const float dist = glm::length(closest_on_segment(a, b, near, lambda) - near);
        if (found < 0 || dist < found_dist) found = seg, found_dist = dist;
      }
      if (g < 0) {
        score[k] = -1.0;
        continue;
      }
      const double c = s0 * facing(m, g, xa);
      score[k] = g == previous ? 0.0 : std::acos(std::clamp(c, -1.0, 1.0));  // the angle to increase towards 90 degrees
    }
    if (found >= 0) return found;
    // Between the two best neighbours, in proportion to their angles.
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int a, int b) { return score[a] > score[b]; });
    if (score[order[0]] <= 0.0) return -1;
    int next = order[0];
    if (score[order[1]] > 0.0 && rng.next_float() * (score[order[0]] + score[order[1]]) >= score[order[0]]) next = order[1];
    previous = f;
    f = t.neighbour[3 * size_t(f) + next];
    ++taken;
  }
  return -1;
}

bool Projector::jump(int shape, const Vec3& xa, int& f, Vec3& p) const {
  const Mesh& m = m_scene.shapes[shape].mesh();
  const uint32_t* idx = &m.indices[3 * size_t(f)];
  const Vec3d v0(m.vertex(idx[0])), e1 = Vec3d(m.vertex(idx[1])) - v0, e2 = Vec3d(m.vertex(idx[2])) - v0;
  const std::vector<Vec3>& vn = m_meshes.at(shape).normals;
  const Vec3d n0(vn[idx[0]]), dn1 = Vec3d(vn[idx[1]]) - n0, dn2 = Vec3d(vn[idx[2]]) - n0;
  // Barycentrics of p, then the linear model p + u e1 + v e2 with normal N(p) + u dn1 + v dn2.
  const double g11 = glm::dot(e1, e1), g12 = glm::dot(e1, e2), g22 = glm::dot(e2, e2), det = g11 * g22 - g12 * g12;
  if (!(det > 0.0)) return false;
  const Vec3d rp = Vec3d(p) - v0;
  const double r1 = glm::dot(rp, e1), r2 = glm::dot(rp, e2);
  const double b1 = (g22 * r1 - g12 * r2) / det, b2 = (g11 * r2 - g12 * r1) / det;
  const Vec3d np = n0 + b1 * dn1 + b2 * dn2;
  const Vec3d d = Vec3d(p) - Vec3d(xa);  // the viewing direction, held fixed
  // Silhouette line a + b u + c v = 0; its point nearest to p in the surface metric G.
  const double a = glm::dot(np, d), b = glm::dot(dn1, d), c = glm::dot(dn2, d);
  const double gi11 = g22 / det, gi12 = -g12 / det, gi22 = g11 / det;
  const double q1 = gi11 * b + gi12 * c, q2 = gi12 * b + gi22 * c, denom = b * q1 + c * q2;
  if (!(std::abs(denom) > 1e-20)) return false;
  const double u = -a * q1 / denom, v = -a * q2 / denom;
  const Vec3d q = Vec3d(p) + u * e1 + v * e2;
  const Vec3d nq = np + u * dn1 + v * dn2;
  if (!(glm::length(nq) > 0.0) || !std::isfinite(q.x + q.y + q.z)) return false;
  const Vec3 nqf = Vec3(glm::normalize(nq));
  // Back onto the surface along -n from above the model point (the surface may lie on either side).
  const float h = float(glm::length(q - Vec3d(p))) + 1e-3f * float(std::sqrt(std::max(g11, g22)));
  SurfaceInteraction si;
  if (!m_scene.intersect(Ray{Vec3(q) + h * nqf, -nqf, 0.0f, 2.0f * h}, si) || si.shape != shape) return false;
  f = m.distinct[size_t(si.prim)];
  p = si.p;
  return true;
}

std::optional<Projection> Projector::snap(int shape, int f, const Vec3& xa, const Vec3& p) const {
  const Mesh& m = m_scene.shapes[shape].mesh();
  const MeshTopology& t = m_meshes.at(shape);
  int best = -1;
  float best_dist = kInfinity;
  Vec3 best_point(0.0f);
  for (int k = 0; k < 3; ++k) {
    const int seg = t.segment[3 * size_t(f) + k];
    if (seg < 0) continue;
    float lambda;
    const Vec3 q = closest_on_segment(m.vertex(m.indices[3 * size_t(f) + k]), m.vertex(m.indices[3 * size_t(f) + (k + 1) % 3]), p, lambda);
    if (glm::length(q - p) < best_dist) best_dist = glm::length(q - p), best = seg, best_point = q;
  }
  if (best < 0) return std::nullopt;
  const BoundarySegment& s = m_space.segments()[size_t(best)];
  const Vec3 w0 = glm::normalize(xa - best_point);
  if (s.face1 < 0) return finish(best, xa, best_point, false, w0);
  // Both faces see w0 alike: tilt w0 just past the plane of the face it is closest to.
  const Vec3 n0 = Vec3(m.oriented_normal(s.face0)), n1 = Vec3(m.oriented_normal(s.face1));
  const Vec3 nk = std::abs(glm::dot(n0, w0)) < std::abs(glm::dot(n1, w0)) ? n0 : n1;
  const Vec3 w = glm::normalize(w0 - (1.0f + 1e-3f) * glm::dot(nk, w0) * nk);
  const Vec3 u = m_space.invert(best, best_point, w);
  BoundaryPoint check;
  if (!m_space.sample(u, 1.0f, check) || check.segment != best) return std::nullopt;
  return Projection{u, best, check.xb, check.w, false};
}

std::optional<Projection> Projector::project_mesh(const Vec3& xa, const SurfaceInteraction& hit, Pcg32& rng) const {
  int f = m_scene.shapes[hit.shape].mesh().distinct[size_t(hit.prim)], taken = 0;  // a duplicate has no neighbours of its own
  Vec3 p = hit.p;
  int seg = -1;
  if (m_mode != MeshProjection::Jump) seg = walk(hit.shape, xa, hit.p, f, kWalkSteps, rng, taken);
  if (seg < 0 && m_mode != MeshProjection::Walk) {
    if (m_mode == MeshProjection::Hybrid && taken > 0) {  // jump from where the walk stopped
      const uint32_t* i = &m_scene.shapes[hit.shape].mesh().indices[3 * size_t(f)];
      const Mesh& m = m_scene.shapes[hit.shape].mesh();
      p = (m.vertex(i[0]) + m.vertex(i[1]) + m.vertex(i[2])) / 3.0f;
    }
    if (jump(hit.shape, xa, f, p))
      seg = walk(hit.shape, xa, p, f, m_mode == MeshProjection::Jump ? 1 : kWalkSteps, rng, taken);
  }
  std::optional<Projection> r;
  // The point on the edge nearest to the hit itself, also after a JUMP: placing it nearest to the
  // landing point instead was measured worse (torus, 64 spp: relative RMSE 1.6 against 0.4).
  if (seg >= 0) r = finish(seg, xa, hit.p, true, glm::normalize(xa - hit.p));
  return r ? r : snap(hit.shape, f, xa, p);
}

}  // namespace limn
