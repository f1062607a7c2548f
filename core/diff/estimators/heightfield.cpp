#include "core/diff/estimators/heightfield.h"

#include <algorithm>
#include <array>
#include "core/diff/terms/replay.h"
#include "core/render/integrators/path.h"

namespace limn {

using namespace replay;

void HeightfieldCounters::add(const HeightfieldCounters& o) {
  rays += o.rays;
  searches += o.searches;
  search.nodes += o.search.nodes;
  search.cells += o.search.cells;
  search.curvature_hidden += o.search.curvature_hidden;
  search.curvature_rising += o.search.curvature_rising;
  other_shape_hits += o.other_shape_hits;
  delta_light_samples += o.delta_light_samples;
  empty_ranges += o.empty_ranges;
  edge_samples += o.edge_samples;
  edge_splats += o.edge_splats;
  other_shadow_blocks += o.other_shadow_blocks;
  if (shadow_blockers.size() < o.shadow_blockers.size()) shadow_blockers.resize(o.shadow_blockers.size(), 0);
  for (size_t i = 0; i < o.shadow_blockers.size(); ++i) shadow_blockers[i] |= o.shadow_blockers[i];
}

HeightfieldEstimator::HeightfieldEstimator(const Scene& scene, const DiffParams& params, const HeightfieldOptions& options,
                                           int max_depth)
    : m_scene(scene), m_params(params), m_opt(options), m_max_depth(max_depth) {
  const std::string where = scene.source + ": heightfield estimator: ";
  if (!(options.interval_uniform_share >= 0.0f && options.interval_uniform_share <= 1.0f))
    throw std::invalid_argument(where + "interval_uniform_share must be in [0, 1] (got " +
                                std::to_string(options.interval_uniform_share) + ")");
  for (size_t i = 0; i < scene.shapes.size(); ++i) {
    const Shape& s = scene.shapes[i];
    if (const auto* hf = std::get_if<Heightfield>(&s.geometry)) {
      // Directions are global spherical coordinates around the first heightfield's up axis; a
      // vertical slice of it is a vertical slice of every other field (and theta is the same in
      // each local frame: similarities keep angles) only when their up axes are parallel.
      const Vec3d up = glm::normalize(Vec3d(hf->world_from_local.vector(Vec3(0, 0, 1))));
      if (m_shape >= 0) {
        const Heightfield& first = std::get<Heightfield>(scene.shapes[m_shape].geometry);
        const Vec3d up0 = glm::normalize(Vec3d(first.world_from_local.vector(Vec3(0, 0, 1))));
        if (glm::dot(up, up0) < 1.0 - 1e-6)  // ~0.08 degrees: beyond float rounding of a rotation
          throw std::invalid_argument(where + "heightfield '" + s.id + "' has its up axis (" + std::to_string(up.x) + ", " +
                                      std::to_string(up.y) + ", " + std::to_string(up.z) + ") not along that of heightfield '" +
                                      scene.shapes[m_shape].id + "' (" + std::to_string(up0.x) + ", " + std::to_string(up0.y) +
                                      ", " + std::to_string(up0.z) + "); the estimator splits vertical slices, so all "
                                      "heightfields of a scene must share their up direction (rotations about it are fine)");
      } else {
        m_shape = int(i);
      }
      m_shapes.push_back(int(i));
    }
    const Bsdf& b = scene.bsdfs[s.bsdf];
    if (b.is_delta() || b.transmits())
      throw std::invalid_argument(where + "shape '" + s.id + "' uses bsdf '" + b.id + "', which is " +
                                  (b.is_delta() ? "a delta (smooth) BSDF" : "transmissive") +
                                  "; directions are sampled uniformly in global spherical coordinates (paper App. A.2), so "
                                  "only rough reflective BSDFs (diffuse, roughconductor) can be used");
  }
  if (m_shape < 0) throw std::invalid_argument(where + "the scene has no heightfield");
  for (int si : params.moving_shapes()) {
    const Shape& s = scene.shapes[si];
    if (!std::holds_alternative<Heightfield>(s.geometry) && !(std::holds_alternative<Mesh>(s.geometry) && s.emitter >= 0))
      throw std::invalid_argument(where + "shape '" + s.id + "' is differentiable; with heightfields only their heights and "
                                  "area emitters (meshes) may move, because other shapes' silhouettes are not split");
  }
  for (size_t i = 0; i < scene.emitters.size(); ++i) {
    const Emitter& e = scene.emitters[i];
    if (const auto* a = std::get_if<AreaEmitter>(&e.model)) {
      const Shape& s = scene.shapes[a->shape];
      const Mesh* mesh = std::get_if<Mesh>(&s.geometry);
      if (!mesh)
        throw std::invalid_argument(where + "emitter '" + e.id + "' is attached to " + s.type + " '" + s.id +
                                    "'; only mesh area emitters are supported");
      if (a->radiance.bitmap)
        throw std::invalid_argument(where + "emitter '" + e.id + "' has a bitmap radiance; with a heightfield only constant "
                                    "radiance is supported");
      EmitterTriangles t{int(i), a->shape, {}};
      for (size_t f = 0; f < mesh->triangle_count(); ++f) t.prims.push_back(int(f));
      m_area_emitters.push_back(std::move(t));
    } else if (std::holds_alternative<PointEmitter>(e.model) || std::holds_alternative<DirectionalEmitter>(e.model)) {
      m_delta_emitters.push_back(int(i));
      // Shadow edges of both kinds of light (delta_edge_sample); a directional light travelling
      // upwards (lighting the fields' undersides) is left out: its grazing rays are not records
      // of z - k t from above (summary).
      const auto* dir = std::get_if<DirectionalEmitter>(&e.model);
      if (!dir || glm::dot(glm::normalize(Vec3d(std::get<Heightfield>(scene.shapes[m_shape].geometry).world_from_local.vector(
                                              Vec3(0, 0, 1)))),
                           Vec3d(dir->direction)) < 0.0)
        m_edge_lights.push_back(int(i));
    }
  }
}

namespace {

constexpr double kPiD = 3.14159265358979323846;

// A theta at which the slice is split: its primal value and its taped value.
struct Split {
  double v;
  Var var;
};

bool by_value(const Split& a, const Split& b) { return a.v < b.v; }

// Slope of the direction with zenith angle theta (k = cot theta), clamped away from infinity.
double slope_of(double theta) {
  const double s = std::sin(theta), c = std::cos(theta);
  if (s < 1e-15) return c > 0.0 ? 1e30 : -1e30;
  return c / s;
}

// Eq. 6: chooses one of the intervals between the sorted, distinct cut points (primal values) with
// probability p_j = (1 - m) w_j / W + m / M. p_j is primal, so it is not differentiated. Width
// alone (m = 0) gives the reparameterised derivative (r_{j+1}' - r_j') f / p_j a 1 / w_j tail: a
// sliver between a silhouette and a range end is chosen rarely and then weighted by W / w_j. The
// uniform share m bounds that weight by M / m. u is uniform in [0, 1); returns j, p_j and the
// position in the interval, in [0, 1].
struct IntervalChoice {
  size_t j;
  double p, u;
};
template <typename Cut>
IntervalChoice choose_interval(const std::vector<Cut>& cut, double share, double u) {
  const size_t M = cut.size() - 1;
  const double W = cut.back().v - cut.front().v, m = M > 1 ? share : 0.0;
  double c = 0.0;
  for (size_t j = 0;; ++j) {
    const double p = (1.0 - m) * (cut[j + 1].v - cut[j].v) / W + m / double(M);
    if (u < c + p || j + 1 == M) return {j, p, std::clamp((u - c) / p, 0.0, 1.0)};
    c += p;
  }
}

// The uniform share of the choice among an emitter's azimuth sub-intervals. Near-radial edges
// (phi slivers) are rare, so a small share bounds their weight (M / 0.1) while keeping phi nearly
// uniform: on the cone, shares 0.1 / 0.25 / 0.5 gave summed per-pixel variance 127 / 134 / 150
// (uniform phi over the hull: 124-130 plus single samples of 100x the pixel's mean).
constexpr double kAzimuthUniformShare = 0.1;

// The origin of a slice, in the first heightfield's local frame, and in the world.
struct Origin {
  VV p;          // taped
  Vec3d p0;      // primal
  VV world;      // taped
};

}  // namespace

struct HeightfieldPath {
  const HeightfieldEstimator& E;
  const Scene& scene;
  PathInputs& in;
  HeightfieldCounters& cnt;
  Pcg32& rng;
  std::vector<DiffHeightfieldFrame> frames;  // one per heightfield, E.m_shapes' order
  const DiffHeightfieldFrame& F;             // the first: its local frame holds (phi, theta)
  Replay R;

  static std::vector<DiffHeightfieldFrame> make_frames(const HeightfieldEstimator& e, PathInputs& inputs) {
    std::vector<DiffHeightfieldFrame> f;
    f.reserve(e.m_shapes.size());
    for (int s : e.m_shapes) f.emplace_back(e.m_scene, e.m_params, inputs, s);
    return f;
  }

  HeightfieldPath(const HeightfieldEstimator& e, PathInputs& inputs, HeightfieldCounters& counters, Pcg32& r)
      : E(e), scene(e.m_scene), in(inputs), cnt(counters), rng(r), frames(make_frames(e, inputs)), F(frames[0]),
        R{e.m_scene, e.m_params, inputs} {}

  const Heightfield& hf() const { return F.hf; }

  Origin origin(const VV& p_world) const {
    Origin o;
    o.p = F.to_local_point(p_world);
    o.p0 = Vec3d(o.p.x.v, o.p.y.v, o.p.z.v);
    o.world = p_world;
    return o;
  }

  VV world_direction(const Var& phi, const Var& theta) const {
    const Var st = sin(theta);
    return F.to_world_vector(VV(st * cos(phi), st * sin(phi), cos(theta))) / F.scale;
  }

  // Emitter k's triangles in the local frame (taped vertices), built once per path: every slice
  // of the path splits at their edges.
  std::vector<std::vector<std::array<VV, 3>>> emitter_tris;
  const std::vector<std::array<VV, 3>>& emitter_triangles(size_t k) {
    if (emitter_tris.empty()) emitter_tris.resize(E.m_area_emitters.size());
    std::vector<std::array<VV, 3>>& out = emitter_tris[k];
    const auto& et = E.m_area_emitters[k];
    if (!out.empty() || et.prims.empty()) return out;
    const Mesh& m = std::get<Mesh>(scene.shapes[et.shape].geometry);
    const DiffContext ctx{scene, E.m_params, in};
    for (int f : et.prims) {
      std::array<VV, 3> t;
      for (int c = 0; c < 3; ++c) t[c] = F.to_local_point(mesh_vertex(ctx, et.shape, m.indices[3 * f + c]));
      out.push_back(t);
    }
    return out;
  }

  // Thetas where the half-plane at azimuth phi from o crosses the edges of the triangles.
  static void crossings(const Origin& o, const Var& phi, const std::vector<std::array<VV, 3>>& tris, std::vector<Split>& out) {
    const Var c = cos(phi), s = sin(phi);
    for (const auto& t : tris)
      for (int e = 0; e < 3; ++e) {
        const VV& a = t[e];
        const VV& b = t[(e + 1) % 3];
        const Var sa = -s * (a.x - o.p.x) + c * (a.y - o.p.y), sb = -s * (b.x - o.p.x) + c * (b.y - o.p.y);
        if ((sa.v > 0.0) == (sb.v > 0.0)) continue;
        const Var f = sa / (sa - sb);
        const VV p = a + (b - a) * f;
        const Var r = c * (p.x - o.p.x) + s * (p.y - o.p.y);
        if (!(r.v > 0.0)) continue;  // the other half of the plane
        const Var th = atan2(r, p.z - o.p.z);
        out.push_back({th.v, th});
      }
  }

  // Whether the vertical line through o meets triangle t, and at which height.
  static bool vertical_hit(const Origin& o, const std::array<VV, 3>& t, double& z) {
    const Vec3d a(t[0].x.v, t[0].y.v, t[0].z.v), b(t[1].x.v, t[1].y.v, t[1].z.v), c(t[2].x.v, t[2].y.v, t[2].z.v);
    const double d = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
    if (std::abs(d) < 1e-300) return false;
    const double u = ((o.p0.x - a.x) * (c.y - a.y) - (c.x - a.x) * (o.p0.y - a.y)) / d;
    const double v = ((b.x - a.x) * (o.p0.y - a.y) - (o.p0.x - a.x) * (b.y - a.y)) / d;
    if (u < 0.0 || v < 0.0 || u + v > 1.0) return false;
    z = a.z + u * (b.z - a.z) + v * (c.z - a.z);
    return true;
  }

  // Horizontal distance from og along (dx, dy) to the footprint edge that the primal border point
  // at distance t0 lies on (the nearer of the x and y edges).
  static Var border_t(const Heightfield& hf, const VV& og, const Var& dx, const Var& dy, double t0) {
    const double x = og.x.v + dx.v * t0, y = og.y.v + dy.v * t0;
    const double ex = std::abs(std::abs(x) - 0.5 * hf.width), ey = std::abs(std::abs(y) - 0.5 * hf.depth);
    if (ex <= ey && std::abs(dx.v) > 1e-12) return (Var(std::copysign(0.5 * hf.width, x)) - og.x) / dx;
    if (std::abs(dy.v) > 1e-12) return (Var(std::copysign(0.5 * hf.depth, y)) - og.y) / dy;
    return Var(t0);  // a slice along the edge itself: measure zero
  }

  // Samples theta in [lo, hi] for the slice at azimuth phi (Eq. 10-11): split at the peaks (and at
  // every emitter edge), choose one interval (choose_interval) and map linearly between its
  // taped end points. weight = 1 / pdf(theta) with the end points' motion in it.
  // visible_only (emitter sampling, where a ray that meets the field contributes nothing): the
  // range ends at the steepest peak, above which no ray meets the field; when the field blocks
  // the whole range the sample is 0 without a ray. The dropped part's integral is 0 for every
  // value of the parameters, so this only removes zero-valued samples.
  // every != nullptr: every interval instead of one (Eq. 5), all at one uniform position, as
  // (theta, weight) pairs; theta and weight are then not set.
  bool sample_theta(const Origin& o, const Var& phi, Var lo, Var hi, Var& theta, Var& weight, bool visible_only = false,
                    std::vector<std::pair<Var, Var>>* every = nullptr) {
    if (!(hi.v > lo.v)) return false;
    double inv_p = 1.0;  // 1 / probability of the sub-range
    if (E.m_opt.theta_subrange_degrees > 0.0f) {  // App. C: search one sub-range only
      const int n = std::max(1, int(std::ceil((hi.v - lo.v) / (E.m_opt.theta_subrange_degrees * kPiD / 180.0))));
      const int k = std::min(n - 1, int(double(rng.next_float()) * n));
      const Var a = lo + (hi - lo) * Var(double(k) / n), b = lo + (hi - lo) * Var(double(k + 1) / n);
      lo = a;
      hi = b;
      inv_p = n;
    }
    // Peaks with theta in (lo, hi): slopes in (cot hi, cot lo), in every heightfield's slice at
    // phi (each in its own local frame; theta is the same there, the up axes being parallel).
    std::vector<Split> splits;
    Split steepest{1e30, Var(0.0)};  // the smallest theta of a field's steepest peak
    for (size_t f = 0; f < frames.size(); ++f) {
      const DiffHeightfieldFrame& G = frames[f];
      const VV og = f == 0 ? o.p : G.to_local_point(o.world);
      Var dx = cos(phi), dy = sin(phi);
      if (f > 0) {  // the horizontal direction at phi in this field's frame (a rotation about up, or a mirror)
        const VV h = G.to_local_vector(F.to_world_vector(VV(dx, dy, Var(0.0))));
        const Var n = sqrt(h.x * h.x + h.y * h.y);
        dx = h.x / n;
        dy = h.y / n;
      }
      ++cnt.searches;
      bool blocked = false;
      const std::vector<SlicePeak> peaks = find_peaks(G.hf, Vec3d(og.x.v, og.y.v, og.z.v), glm::dvec2(dx.v, dy.v), slope_of(hi.v),
                                                      slope_of(lo.v), E.m_opt.search, &cnt.search, &blocked);
      if (visible_only && blocked) return false;
      for (const SlicePeak& p : peaks) {
        // The peak at fixed horizontal distance: k is stationary in t there (Eq. 12), so its
        // derivative is the partial at fixed t. A border point stays on its footprint edge, so
        // its t follows the origin (which moves in this frame with the vertex, or when the field
        // itself is translated).
        const Var t = p.border ? border_t(G.hf, og, dx, dy, p.t) : Var(p.t);
        Var z, zx, zy;
        G.height(in, og.x + dx * t, og.y + dy * t, z, zx, zy);
        const Var th = atan2(t, z - og.z);
        splits.push_back({th.v, th});
      }
      // The last peak is this field's steepest: every direction below it meets this field.
      if (!peaks.empty() && splits.back().v < steepest.v) steepest = splits.back();
    }
    if (visible_only && steepest.v < hi.v) hi = steepest.var;
    if (!(hi.v > lo.v)) return false;
    for (size_t k = 0; k < E.m_area_emitters.size(); ++k) crossings(o, phi, emitter_triangles(k), splits);
    // The intervals of (lo, hi), end points sorted by primal value; coinciding splits are merged
    // (an interval of zero width holds no sample).
    std::vector<Split> cut{{lo.v, lo}};
    std::sort(splits.begin(), splits.end(), by_value);
    for (const Split& s : splits)
      if (s.v > cut.back().v && s.v < hi.v) cut.push_back(s);
    cut.push_back({hi.v, hi});
    if (!E.m_opt.reparameterize)
      for (Split& c : cut) c.var = Var(c.v);
    if (every) {
      const Var u(double(rng.next_float()));
      for (size_t j = 0; j + 1 < cut.size(); ++j) {
        const Var width = cut[j + 1].var - cut[j].var;
        every->push_back({cut[j].var + width * u, Var(inv_p) * width});
      }
      return true;
    }
    // Every interval has a positive width (strict merge above), so p_j > 0.
    const IntervalChoice ch = choose_interval(cut, E.m_opt.interval_uniform_share, double(rng.next_float()));
    const Var width = cut[ch.j + 1].var - cut[ch.j].var;
    theta = cut[ch.j].var + width * Var(ch.u);
    weight = Var(inv_p / ch.p) * width;
    return true;
  }

  // Continuation range of a surface vertex: above the tangent plane for the heightfield (below it
  // a reflective BSDF is zero and the surface hides everything), the whole sphere elsewhere.
  Var horizon(const DiffVertex& x, const SurfaceInteraction& si, const Var& phi) const {
    if (!std::holds_alternative<Heightfield>(scene.shapes[si.shape].geometry)) return Var(kPiD);
    const VV n = F.to_local_vector(x.ng);  // (-zx, -zy, 1) / norm, scaled by 1 / scale (any field: the up axes agree)
    const Var k0 = -(n.x * cos(phi) + n.y * sin(phi)) / n.z;
    return atan2(Var(1.0), k0);
  }

  void note_hit(const SurfaceInteraction& si) {
    const Shape& s = scene.shapes[si.shape];
    if (!std::holds_alternative<Heightfield>(s.geometry) && s.emitter < 0) ++cnt.other_shape_hits;
  }

  // Area emitters through emitter-domain sampling (App. A.1).
  VV area_emitter_sample(const DiffVertex& x, const SurfaceInteraction& si, const VV& wi, int bsdf) {
    const size_t K = E.m_area_emitters.size();
    const size_t k = std::min(K - 1, size_t(rng.next_float() * K));
    const float u_phi = rng.next_float();
    const auto& et = E.m_area_emitters[k];
    const Origin o = origin(x.p);
    const std::vector<std::array<VV, 3>>& tris = emitter_triangles(k);
    // Azimuth range: the angular hull of the vertices, split at every vertex's azimuth, or all of
    // it when the emitter is right above or below the origin (or wraps around it). Between two
    // vertex azimuths the theta-range ends follow single edges; phi is the linear map between the
    // two (taped) azimuths, so a crossing keeps its place along its edge. With one uniform phi over
    // the hull, an edge that is nearly radial seen from the origin spans a sliver of phi in which
    // its crossing moves by (theta extent) / (sliver) per unit of azimuth: a heavy tail.
    bool full = false;
    for (const auto& t : tris) {
      double z;
      full |= vertical_hit(o, t, z);
    }
    std::vector<Split> az{{0.0, Var(0.0)}, {2.0 * kPiD, Var(2.0 * kPiD)}};
    if (!full) {
      const double ref = std::atan2(tris[0][0].y.v - o.p0.y, tris[0][0].x.v - o.p0.x);
      std::vector<Split> v_az;
      for (const auto& t : tris)
        for (const VV& v : t) {
          const Var a = atan2(v.y - o.p.y, v.x - o.p.x);
          double off = a.v - ref;
          while (off > kPiD) off -= 2.0 * kPiD;
          while (off <= -kPiD) off += 2.0 * kPiD;
          // .v: the offset from ref (only differences are used); .var: the same angle, unwrapped next to ref
          v_az.push_back({off, a + Var(ref + off - a.v)});
        }
      std::sort(v_az.begin(), v_az.end(), by_value);
      if (v_az.back().v - v_az.front().v < kPiD) {
        az.assign(1, v_az.front());
        for (const Split& s : v_az)
          if (s.v > az.back().v) az.push_back(s);  // shared vertices appear once
        // Vertices at exactly one primal azimuth (an edge exactly radial, an emitter seen exactly
        // edge-on) merge; their azimuths' motion is then dropped, for a measure-zero set of origins.
        if (az.size() < 2) return VV();
      }
    }
    const IntervalChoice ch = choose_interval(az, kAzimuthUniformShare, double(u_phi));
    const Var phi = az[ch.j].var + (az[ch.j + 1].var - az[ch.j].var) * Var(ch.u);
    const Var w_phi = (az[ch.j + 1].var - az[ch.j].var) / Var(ch.p);
    // Theta range: where the slice meets the emitter.
    std::vector<Split> ends;
    crossings(o, phi, tris, ends);
    for (const auto& t : tris) {
      double z;
      if (vertical_hit(o, t, z)) ends.push_back(z > o.p0.z ? Split{0.0, Var(0.0)} : Split{kPiD, Var(kPiD)});
    }
    if (ends.size() < 2) {
      ++cnt.empty_ranges;
      return VV();
    }
    Split lo = ends[0], hi = ends[0];
    for (const Split& s : ends) {
      if (s.v < lo.v) lo = s;
      if (s.v > hi.v) hi = s;
    }
    const Var h = horizon(x, si, phi);
    if (lo.v >= h.v) return VV();  // the emitter is below the tangent plane here
    if (hi.v > h.v) hi = Split{h.v, h};  // nothing is reflected below it (and the integrand is 0 there)
    Var theta, w_theta;
    if (!sample_theta(o, phi, lo.var, hi.var, theta, w_theta, true)) return VV();  // the field hides the emitter here
    const VV w = world_direction(phi, theta);
    const Vec3 w0(float(w.x.v), float(w.y.v), float(w.z.v));
    SurfaceInteraction e;
    ++cnt.rays;
    if (!scene.intersect(spawn_ray(si, w0), e)) return VV();
    if (e.shape != et.shape) {
      note_hit(e);
      return VV();
    }
    if (!(glm::dot(e.ng, w0) < 0.0f)) return VV();  // the back of the emitter
    const Spectrum& rad = std::get<AreaEmitter>(scene.emitters[et.emitter].model).radiance.value;  // constant (checked above)
    return R.bsdf_eval(bsdf, x, wi, w) * R.emitter_value(et.emitter, rad) * (sin(theta) * w_phi * w_theta * Var(double(K)));
  }

  // Whether a shadow ray is blocked. Its first blocker comes with the same ray and is noted when it
  // is no heightfield: its shadow edges get no term (the summary names it).
  bool shadowed(const Ray& r) {
    SurfaceInteraction b;
    if (!scene.intersect(r, b)) return false;
    if (!std::holds_alternative<Heightfield>(scene.shapes[b.shape].geometry)) {
      ++cnt.other_shadow_blocks;
      if (cnt.shadow_blockers.size() <= size_t(b.shape)) cnt.shadow_blockers.resize(scene.shapes.size(), 0);
      cnt.shadow_blockers[b.shape] = 1;
    }
    return true;
  }

  // Point and directional lights by a shadow ray (the shadow edges heightfields cast get the
  // boundary term of delta_edges; other occluders' do not).
  VV delta_light_samples(const DiffVertex& x, const SurfaceInteraction& si, const VV& wi, int bsdf) {
    VV L;
    for (int idx : E.m_delta_emitters) {
      const Emitter& e = scene.emitters[idx];
      ++cnt.delta_light_samples;
      ++cnt.rays;
      if (const auto* pt = std::get_if<PointEmitter>(&e.model)) {
        if (shadowed(spawn_ray_to(si, pt->position))) continue;
        const VV dvec = constant(pt->position) - x.p;
        const Var d2 = dot(dvec, dvec);
        const VV w_dir = dvec / sqrt(d2);
        L = L + R.bsdf_eval(bsdf, x, wi, w_dir) * R.emitter_value(idx, pt->intensity) / d2 * R.point_falloff(*pt, w_dir);
      } else if (const auto* dir = std::get_if<DirectionalEmitter>(&e.model)) {
        if (shadowed(spawn_ray(si, -dir->direction))) continue;
        L = L + R.bsdf_eval(bsdf, x, wi, constant(-dir->direction)) * R.emitter_value(idx, dir->irradiance);
      }
    }
    return L;
  }

  VV escaped(const Vec3& d) const {
    VV L;
    for (int idx : scene.infinite_emitters) {
      const Emitter& e = scene.emitters[idx];
      VV Le = constant(eval_infinite(e, d));
      if (const auto* c = std::get_if<ConstantEmitter>(&e.model)) Le = R.emitter_value(idx, c->radiance);
      L = L + Le;
    }
    return L;
  }

  // The path from a surface vertex on: NEE strategies and uniform continuation.
  VV continue_path(DiffVertex x, SurfaceInteraction si, VV wi, VV beta, int depth) {
    VV L;
    const IntegratorSettings& cfg = scene.integrator;
    for (;; ++depth) {
      if (E.m_max_depth >= 0 && depth + 2 > E.m_max_depth) break;
      const int bsdf = scene.shapes[si.shape].bsdf;
      if (!E.m_area_emitters.empty()) L = L + beta * area_emitter_sample(x, si, wi, bsdf);
      if (!E.m_delta_emitters.empty()) L = L + beta * delta_light_samples(x, si, wi, bsdf);
      // Continuation: uniform azimuth, theta over [0, horizon].
      const Var phi(2.0 * kPiD * double(rng.next_float()));
      Var theta, w_theta;
      if (!sample_theta(origin(x.p), phi, Var(0.0), horizon(x, si, phi), theta, w_theta)) break;
      const VV w = world_direction(phi, theta);
      const Vec3 w0(float(w.x.v), float(w.y.v), float(w.z.v));
      const VV f = R.bsdf_eval(bsdf, x, wi, w);
      if (f.x.v == 0.0 && f.y.v == 0.0 && f.z.v == 0.0) break;
      beta = beta * f * (sin(theta) * Var(2.0 * kPiD) * w_theta);
      const Ray ray = spawn_ray(si, w0);
      SurfaceInteraction next;
      ++cnt.rays;
      if (!scene.intersect(ray, next)) {
        L = L + beta * escaped(w0);
        break;
      }
      note_hit(next);
      x = R.ray_hit(x.p, w, next, ray);  // area emission is counted by emitter sampling only
      wi = -w;
      si = next;
      if (depth + 1 >= cfg.rr_depth) {
        const Spectrum bp(float(beta.x.v), float(beta.y.v), float(beta.z.v));
        const float q = russian_roulette(bp, 1.0f, rng);
        if (q == 0.0f) break;
        beta = beta / Var(double(q));
      }
    }
    return L;
  }

  // The camera's view of world point p0: the hit along the camera ray towards it.
  bool camera_sees(const Vec3& eye, const Vec3& p0, int shape) {
    const Vec3 dv = p0 - eye;
    const float dist = glm::length(dv);
    SurfaceInteraction si;
    ++cnt.rays;
    if (!scene.intersect(Ray{eye, dv / dist, 0.0f, dist * 1.001f}, si)) return false;
    // 1e-3 of the distance: the hit is the same surface point up to the intersector's rounding.
    return si.shape == shape && std::abs(si.t - dist) <= 1e-3f * dist;
  }

  // Whether the delta light `light` reaches surface point si (a shadow ray).
  bool lit_by(int light, const SurfaceInteraction& si) {
    ++cnt.rays;
    if (const auto* pt = std::get_if<PointEmitter>(&scene.emitters[light].model)) return !scene.occluded(spawn_ray_to(si, pt->position));
    return !scene.occluded(spawn_ray(si, -std::get<DirectionalEmitter>(scene.emitters[light].model).direction));
  }

  // The direct light of delta light `light` at the camera's hit at film point f: lit or not, and
  // whether the camera sees `shape` there.
  bool probe(const Vec2& f, int shape, int light, bool& lit) {
    SurfaceInteraction si;
    ++cnt.rays;
    if (!scene.intersect(scene.camera.generate_ray(f), si) || si.shape != shape) return false;
    lit = lit_by(light, si);
    return true;
  }

  // One sample of the shadow edges the heightfields cast under a point or directional light
  // (HeightfieldEstimator::delta_edge_sample). The edges are parameterised by a slice coordinate
  // u, a tape input without a parameter slot (d(film)/du is read from its adjoint): for a point
  // light the azimuth around it (slices through the light), for a directional light the offset
  // across its horizontal direction (parallel slices along it, over the field's footprint).
  bool delta_edges(std::vector<HeightfieldSplat>& splats, std::vector<Var>& vel) {
    const size_t K = E.m_edge_lights.size(), NF = frames.size();
    const int light = E.m_edge_lights[std::min(K - 1, size_t(rng.next_float() * K))];
    const DiffHeightfieldFrame& G = frames[std::min(NF - 1, size_t(rng.next_float() * NF))];
    const PointEmitter* pt = std::get_if<PointEmitter>(&scene.emitters[light].model);
    const DirectionalEmitter* dl = std::get_if<DirectionalEmitter>(&scene.emitters[light].model);
    const double u_rand = double(rng.next_float());
    ++cnt.edge_samples;
    const Heightfield& hf = G.hf;
    // The slice: origin ol (local frame, taped in u) and horizontal direction (dx, dy); 1 / pdf of u.
    Var u, dx, dy;
    VV ol;
    double inv_pdf = double(K) * double(NF), k_light = 0.0;
    VV Dw;  // directional: the world direction of travel
    if (pt) {
      u = Var::input(2.0 * kPiD * u_rand);
      inv_pdf *= 2.0 * kPiD;
      ol = G.to_local_point(constant(pt->position));
      dx = cos(u);
      dy = sin(u);
    } else {
      Dw = constant(dl->direction);
      const VV dloc = G.to_local_vector(Dw);
      const double h = std::sqrt(dloc.x.v * dloc.x.v + dloc.y.v * dloc.y.v);
      // A light straight down casts no shadow edge from a heightfield (a graph has no overhang);
      // 1e-9: below it the slices' direction is rounding.
      if (!(h > 1e-9 * std::abs(dloc.z.v))) return false;
      dx = Var(dloc.x.v / h);
      dy = Var(dloc.y.v / h);
      k_light = dloc.z.v / h;  // rise per horizontal unit along (dx, dy): negative, the light comes from above
      // Offsets across (-dy, dx) that meet the footprint: the corners' extent.
      double lo = 1e300, hi = -1e300;
      for (double cx : {-0.5 * hf.width, 0.5 * hf.width})
        for (double cy : {-0.5 * hf.depth, 0.5 * hf.depth}) {
          const double w = -dy.v * cx + dx.v * cy;
          lo = std::min(lo, w);
          hi = std::max(hi, w);
        }
      u = Var::input(lo + (hi - lo) * u_rand);
      inv_pdf *= hi - lo;
      // Start behind the footprint (its half diagonal back from the centre line), so that the
      // near edge is a footprint edge the slice enters by.
      const double back = 0.5 * std::sqrt(double(hf.width) * hf.width + double(hf.depth) * hf.depth) * 1.01;
      ol = VV(-dy * u - dx * Var(back), dx * u - dy * Var(back), Var(0.5 * (hf.min_height() + hf.max_height())));
    }
    ++cnt.searches;
    const Vec3d o0(ol.x.v, ol.y.v, ol.z.v);
    const glm::dvec2 d0(dx.v, dy.v);
    const std::vector<SlicePeak> peaks = pt ? find_peaks(hf, o0, d0, -1e30, 1e30, E.m_opt.search, &cnt.search)
                                            : find_parallel_peaks(hf, o0, d0, k_light, E.m_opt.search, &cnt.search);
    const CameraView view(scene.camera);
    const Vec3 eye = view.eye_world;
    // Directional light: a virtual light this far behind each peak (world units: the footprint's
    // diagonal), so that both kinds continue their grazing ray alike below.
    const double L_virtual = std::sqrt(double(hf.width) * hf.width + double(hf.depth) * hf.depth) * G.scale.v;
    bool any = false;
    for (const SlicePeak& p : peaks) {
      // The grazing point at fixed horizontal distance: k (slope from a point, or intercept along
      // parallel rays) is stationary in t there (Eq. 12), so its derivative is the partial at fixed
      // t; footprint edges keep to their edge.
      const Var t = p.border ? border_t(hf, ol, dx, dy, p.t) : Var(p.t);
      Var z, zx, zy;
      G.height(in, ol.x + dx * t, ol.y + dy * t, z, zx, zy);
      const VV xb = G.to_world_point(VV(ol.x + dx * t, ol.y + dy * t, z));
      const VV P = pt ? constant(pt->position) : xb - Dw * Var(L_virtual);
      const VV D = pt ? ad::normalize(xb - P) : Dw;
      const Vec3 D0(float(D.x.v), float(D.y.v), float(D.z.v));
      const float tb = float(ad::length(xb - P).v);
      // The ray beyond the grazing point. It runs within a second-order distance of the surface
      // there, and the intersector's near-tangent test reports the grazing point itself as a hit:
      // starting 1e-4 of the distance beyond it lost 13 % of this term on the cone (FD's
      // projection z -6.7). 1 % skips that; a receiver closer behind the peak than 1 % of the
      // light's distance (directional: of the footprint's diagonal) is lost (docs/heightfields.md, Limits).
      const Ray ray{Vec3(float(P.x.v), float(P.y.v), float(P.z.v)), D0, tb * 1.01f, std::numeric_limits<float>::infinity()};
      SurfaceInteraction si;
      ++cnt.rays;
      if (!scene.intersect(ray, si)) continue;
      const DiffVertex y = R.ray_hit(P, D, si, ray);
      const Vec3 y0(float(y.p.x.v), float(y.p.y.v), float(y.p.z.v));
      if (!camera_sees(eye, y0, si.shape)) continue;
      const auto pc = view.proj.to_camera(y.p);
      if (!(pc.z.v > view.proj.near)) continue;
      Var fx, fy;
      view.proj.film(pc, fx, fy);
      // The edge's film tangent ds/du.
      std::vector<double> adj;
      ad::Tape::current().backward(fx.idx, 1.0, adj);
      const double tx = u.idx < int(adj.size()) ? adj[u.idx] : 0.0;
      ad::Tape::current().backward(fy.idx, 1.0, adj);
      const double ty = u.idx < int(adj.size()) ? adj[u.idx] : 0.0;
      const double len = std::sqrt(tx * tx + ty * ty);
      if (!(len > 0.0) || !std::isfinite(len)) continue;
      const glm::dvec2 n(-ty / len, tx / len);
      // Probes 1e-3 pixels either side (as the primary term's): which side the light reaches.
      const double delta = 1e-3;  // 1e-2 and 5e-2 gave the same term (sums within 2.5 %)
      bool lit_minus = false, lit_plus = false;
      if (!probe(Vec2(float(fx.v - delta * n.x), float(fy.v - delta * n.y)), si.shape, light, lit_minus) ||
          !probe(Vec2(float(fx.v + delta * n.x), float(fy.v + delta * n.y)), si.shape, light, lit_plus) || lit_minus == lit_plus)
        continue;
      // The light's direct contribution at y towards the camera (primal).
      const VV we = ad::normalize(constant(eye) - y.p);
      const int bsdf = scene.shapes[si.shape].bsdf;
      VV f;
      if (pt) {
        const VV to_light = P - y.p;
        const Var d2 = dot(to_light, to_light);
        const VV wl = to_light / sqrt(d2);
        f = R.bsdf_eval(bsdf, y, we, wl) * R.emitter_value(light, pt->intensity) / d2 * R.point_falloff(*pt, wl);
      } else {
        f = R.bsdf_eval(bsdf, y, we, -Dw) * R.emitter_value(light, dl->irradiance);
      }
      const double sign = lit_minus ? 1.0 : -1.0;  // f(s - delta n) - f(s + delta n)
      const double w = sign * len * inv_pdf;
      const Spectrum value(float(f.x.v * w), float(f.y.v * w), float(f.z.v * w));
      const Var v = fx * Var(n.x) + fy * Var(n.y);
      bool splatted = false;
      scene.camera.splat(fx.v, fy.v, [&](int pixel, float wt) {
        splats.push_back({pixel, value * wt, int(vel.size())});
        splatted = true;
      });
      if (!splatted) continue;
      vel.push_back(v);
      ++cnt.edge_splats;
      any = true;
    }
    return any;
  }

  // Pixel (px, py) with a box filter: the pixel's cone turned into (phi, theta-range) (App. A.1).
  VV pixel(int px, int py) {
    if (E.m_max_depth == 0) return VV();
    const Camera& cam = scene.camera;
    const Vec3 eye = cam.world_from_camera.point(Vec3(0.0f));
    const Origin o = origin(constant(eye));
    const Mat4d& to_local = hf().world_from_local.inverse_matrix();
    auto local_dir = [&](const Vec2& film) {
      return glm::normalize(glm::dmat3(to_local) * Vec3d(cam.generate_ray(film).d));
    };
    const Vec3d c[4] = {local_dir(Vec2(px, py)), local_dir(Vec2(px + 1, py)), local_dir(Vec2(px + 1, py + 1)), local_dir(Vec2(px, py + 1))};
    const Vec3d centre = local_dir(Vec2(px + 0.5f, py + 0.5f));
    Vec3d n[4];
    for (int k = 0; k < 4; ++k) {
      n[k] = glm::cross(c[k], c[(k + 1) % 4]);
      if (glm::dot(n[k], centre) < 0.0) n[k] = -n[k];
    }
    // Azimuth range of the cone: everything when it holds the vertical, else the corners' hull.
    auto contains = [&](const Vec3d& v) {
      for (const Vec3d& nk : n)
        if (glm::dot(nk, v) < 0.0) return false;
      return true;
    };
    double phi_lo = 0.0, phi_hi = 2.0 * kPiD;
    if (!contains(Vec3d(0, 0, 1)) && !contains(Vec3d(0, 0, -1))) {
      const double ref = std::atan2(centre.y, centre.x);
      double mn = 1e30, mx = -1e30;
      for (const Vec3d& ck : c) {
        double off = std::atan2(ck.y, ck.x) - ref;
        while (off > kPiD) off -= 2.0 * kPiD;
        while (off <= -kPiD) off += 2.0 * kPiD;
        mn = std::min(mn, off);
        mx = std::max(mx, off);
      }
      phi_lo = ref + mn;
      phi_hi = ref + mx;
    }
    const double phi0 = phi_lo + (phi_hi - phi_lo) * double(rng.next_float());
    // Theta range: the half-plane at phi inside all four sides, A sin(theta) + B cos(theta) >= 0.
    double t_lo = 0.0, t_hi = kPiD;
    for (const Vec3d& nk : n) {
      const double A = nk.x * std::cos(phi0) + nk.y * std::sin(phi0), B = nk.z, beta = std::atan2(B, A);
      if (beta >= 0.0) t_hi = std::min(t_hi, kPiD - beta);
      else t_lo = std::max(t_lo, -beta);
    }
    const Var phi(phi0);
    std::vector<std::pair<Var, Var>> dirs;  // (theta, its weight: 1 / pdf, or the Jacobian under Eq. 5)
    Var theta, w_theta;
    const bool every = E.m_opt.camera_every_interval;
    if (!(t_hi > t_lo) || !sample_theta(o, phi, Var(t_lo), Var(t_hi), theta, w_theta, false, every ? &dirs : nullptr)) {
      ++cnt.empty_ranges;
      return VV();
    }
    if (!every) dirs.push_back({theta, w_theta});
    VV L;
    for (const auto& [th, w_th] : dirs) L = L + camera_path(eye, phi, th, w_th * Var(phi_hi - phi_lo));
    return L;
  }

  // The path along the camera direction (phi, theta); weight: 1 / pdf(phi, theta), or the
  // Jacobian of (u_phi, u_theta) -> (phi, theta) when every interval is traced.
  VV camera_path(const Vec3& eye, const Var& phi, const Var& theta, const Var& weight) {
    const Camera& cam = scene.camera;
    const VV w = world_direction(phi, theta);
    const Vec3 w0(float(w.x.v), float(w.y.v), float(w.z.v));
    // Film area per solid angle, K_x K_y / cos^3 (angle to the optical axis).
    const Vec3 fwd = glm::normalize(cam.world_from_camera.vector(Vec3(0, 0, 1)));
    const Var cos_a = dot(w, constant(fwd));
    if (!(cos_a.v > 0.0)) return VV();
    const double Kx = 0.5 * cam.film_width() / cam.tan_half_x, Ky = 0.5 * cam.film_height() / cam.tan_half_y;
    VV beta = VV(Var(1.0), Var(1.0), Var(1.0)) *
              (Var(Kx * Ky) / (cos_a * cos_a * cos_a) * sin(theta) * weight);
    const Ray ray{eye, w0, cam.near_clip / float(cos_a.v), cam.far_clip / float(cos_a.v)};
    SurfaceInteraction si;
    ++cnt.rays;
    const IntegratorSettings& cfg = scene.integrator;
    if (!scene.intersect(ray, si)) return cfg.hide_emitters ? VV() : beta * escaped(w0);
    note_hit(si);
    const DiffVertex x = R.ray_hit(constant(eye), w, si, ray);
    VV L;
    const Shape& shape = scene.shapes[si.shape];
    if (shape.emitter >= 0 && glm::dot(si.ng, w0) < 0.0f && !cfg.hide_emitters)
      L = beta * R.emitter_value(shape.emitter, std::get<AreaEmitter>(scene.emitters[shape.emitter].model).radiance.value);
    return L + continue_path(x, si, -w, beta, 0);
  }
};

ad::V3<ad::Var> HeightfieldEstimator::pixel(int x, int y, Pcg32& rng, PathInputs& in, HeightfieldCounters& counters) const {
  HeightfieldPath path(*this, in, counters, rng);
  return path.pixel(x, y);
}

bool HeightfieldEstimator::delta_edge_sample(Pcg32& rng, PathInputs& in, std::vector<HeightfieldSplat>& splats,
                                             std::vector<ad::Var>& velocity, HeightfieldCounters& counters) const {
  if (!has_delta_edges()) return false;
  HeightfieldPath path(*this, in, counters, rng);
  return path.delta_edges(splats, velocity);
}

std::unique_ptr<HeightfieldEstimator> heightfield_estimator(const Scene& scene, const DiffParams& params, const HeightfieldOptions& options,
                                                            int max_depth, int spp) {
  if (!params.any_geometry()) return nullptr;
  for (const Shape& s : scene.shapes) {
    if (!std::holds_alternative<Heightfield>(s.geometry)) continue;
    if (spp == 0)  // Tong et al. 2023: its boundary terms ride on the interior paths
      throw std::invalid_argument(scene.source + ": heightfield '" + s.id + "' needs spp_interior >= 1 (its estimator has no separate boundary term)");
    if (scene.camera.filter.type != FilmFilter::Type::Box)  // pixel(): each pixel's box footprint (App. A.1)
      throw std::invalid_argument(scene.source + ": heightfield '" + s.id + "': its estimator integrates each pixel's box "
                                  "footprint; use the box reconstruction filter to differentiate it");
    return std::make_unique<HeightfieldEstimator>(scene, params, options, max_depth);
  }
  return nullptr;
}

std::vector<std::string> HeightfieldEstimator::summary(int spp, const HeightfieldCounters& c) const {
  std::vector<std::string> s;
  std::string fields;
  for (int i : m_shapes) {
    const Shape& shape = m_scene.shapes[i];
    const Heightfield& hf = std::get<Heightfield>(shape.geometry);
    fields += (fields.empty() ? "'" : ", '") + shape.id + "' (" + std::to_string(hf.nx) + " x " + std::to_string(hf.ny) + " heights)";
  }
  s.push_back("heightfield estimator (Tong et al. 2023) for " + fields + ": " + std::to_string(spp) +
              " paths per pixel, theta reparameterised at the discontinuities of each azimuth slice; " +
              std::to_string(c.searches) + " peak searches visited " + std::to_string(c.search.nodes) + " mipmap nodes and " +
              std::to_string(c.search.cells) + " cells" +
              (!m_opt.search.use_mipmap       ? " (brute force: no mipmap skipping)"
               : m_opt.search.curvature_test ? " (curvature tests: " + std::to_string(c.search.curvature_hidden) + " nodes hidden, " +
                                                   std::to_string(c.search.curvature_rising) + " rising)"
                                             : " (maximum test only)") +
              (m_opt.theta_subrange_degrees > 0.0f
                   ? ", theta searched in sub-ranges of " + std::to_string(m_opt.theta_subrange_degrees) + " degrees (App. C)"
                   : std::string()));
  s.push_back("primary visibility and indirect boundary terms: not needed (the heightfield estimator reparameterises them)");
  if (c.edge_samples)
    s.push_back("point/directional light shadow edges cast by heightfields: " + std::to_string(c.edge_samples) + " samples, " +
                std::to_string(c.edge_splats) + " reached the film");
  if (c.delta_light_samples) {
    std::string left_out;  // delta lights whose shadow edges get no term
    for (int i : m_delta_emitters)
      if (!has_delta_edges() || std::find(m_edge_lights.begin(), m_edge_lights.end(), i) == m_edge_lights.end())
        left_out += (left_out.empty() ? "'" : ", '") + m_scene.emitters[i].id + "'";
    s.push_back("point/directional lights: " + std::to_string(c.delta_light_samples) + " shadow rays; " +
                (left_out.empty() ? std::string("the shadow edges heightfields cast are differentiated")
                                  : "not differentiated: the shadow edges of " + left_out +
                                        (has_delta_edges() ? " (a directional light from below)" : " (heightfield_delta_edges off)")));
  }
  if (c.other_shadow_blocks) {
    std::string names;
    for (size_t i = 0; i < c.shadow_blockers.size(); ++i)
      if (c.shadow_blockers[i]) names += (names.empty() ? "'" : ", '") + m_scene.shapes[i].id + "'";
    s.push_back("warning: " + std::to_string(c.other_shadow_blocks) + " shadow rays to point/directional lights were blocked by " +
                names + ", not a heightfield: the shadow edges of other occluders are not differentiated, so derivatives may be "
                "biased where those shadows fall on a moving heightfield");
  }
  if (c.other_shape_hits)
    s.push_back("warning: " + std::to_string(c.other_shape_hits) +
                " rays met shapes other than the heightfield and emitters, whose silhouettes are not split: derivatives may be "
                "biased where those shapes occlude");
  if (c.empty_ranges) s.push_back(std::to_string(c.empty_ranges) + " samples had an empty theta-range (value 0, counted)");
  return s;
}

}  // namespace limn
