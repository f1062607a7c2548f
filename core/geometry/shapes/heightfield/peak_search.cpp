#include "core/geometry/shapes/heightfield/peak_search.h"

#include <array>

namespace limn {
namespace {

struct Node {
  int level, i, j;
  double t0, t1;
};

// The search for both kinds of slice: from the point o (parallel == false: k is the slope
// (z - o_z) / t of the line from o, the running line o_z + k_run t turns about o) or along rays
// of fixed slope k_light (parallel: k is the intercept g = z - k_light t, the running line
// k_run + k_light t moves up). Everything else (records, skips, bisection) is shared.
std::vector<SlicePeak> search(const Heightfield& hf, const Vec3d& o, const glm::dvec2& d, double k_start, double k_stop,
                              const PeakSearchOptions& opt, PeakSearchStats* stats, bool* blocked, bool parallel, double k_light) {
  std::vector<SlicePeak> peaks;
  if (blocked) *blocked = false;
  PeakSearchStats local_stats;
  PeakSearchStats& st = stats ? *stats : local_stats;
  // The part of the slice over the footprint.
  double t_in = 0.0, t_out = 1e30;
  const int top = int(hf.mip.size()) - 1;
  if (!hf.node_span(top, 0, 0, o.x, o.y, d.x, d.y, t_in, t_out)) return peaks;
  // Slope samples along the slice with the sign of dk/dt = (z'(t) - k) / t: a maximum lies between
  // consecutive samples where it turns from rising to falling, also right after a skipped node
  // (everything inside that node is under the running maximum, so no record is lost there).
  struct Sample {
    double t, k, dk;
  };
  CellPatch cell;  // the cell being sampled; refinements may reach into the previous one
  auto sample_at = [&](double t) {
    const double x = o.x + t * d.x, y = o.y + t * d.y;
    const double c = hf.grid_c(x), r = hf.grid_r(y);
    const bool in_cell = cell.i >= 0 && c >= cell.i - 1e-9 && c <= cell.i + 1 + 1e-9 && r >= cell.j - 1e-9 && r <= cell.j + 1 + 1e-9;
    const HeightSample h = in_cell ? cell.eval(hf, x, y) : hf.eval(x, y);
    const double k = parallel ? h.z - k_light * t : (h.z - o.z) / t;
    // dk/dt: (z' - k) / t from a point (t > 0, so its sign), z' - k_light for parallel rays.
    return Sample{t, k, (h.dx * d.x + h.dy * d.y) - (parallel ? k_light : k)};
  };
  double k_run = k_start;
  // The running line's height at t and its slope.
  auto line = [&](double t) { return parallel ? k_run + k_light * t : o.z + k_run * t; };
  auto line_slope = [&]() { return parallel ? k_light : k_run; };
  if (t_in > 0.0) {  // the origin is outside the footprint: the near edge hides what passes under it
    const double k = sample_at(t_in).k;
    if (k > k_run && k < k_stop) peaks.push_back({t_in, k, true});
    k_run = std::max(k_run, k);
  }
  Sample prev{0, -1e300, 0};
  bool have_prev = false, last_is_record = false;
  double last_t = -1.0;
  auto add_sample = [&](const Sample& s) {
    if (have_prev && prev.dk > 0.0 && s.dk <= 0.0) {
      double lo = prev.t, hi = s.t;  // bisection on the sign of dk/dt
      for (int it = 0; it < 36; ++it) {  // 2^-36 of a sub-step; k errs by its square (k is stationary)
        const double mid = 0.5 * (lo + hi);
        (sample_at(mid).dk > 0.0 ? lo : hi) = mid;
      }
      const Sample m = sample_at(0.5 * (lo + hi));
      if (m.k > k_run && m.k < k_stop) peaks.push_back({m.t, m.k, false});
      k_run = std::max(k_run, m.k);
    }
    last_is_record = s.k > k_run;
    last_t = s.t;
    k_run = std::max(k_run, s.k);
    prev = s;
    have_prev = true;
  };

  const double z_max = hf.max_height();
  // Slack for the skip test: bounds are floats, heights are evaluated in double.
  const double eps = 1e-6 * std::max(1.0, std::max(std::abs(double(hf.max_height())), std::abs(double(hf.min_height()))));
  const int n_sub = std::max(1, opt.samples_per_cell);
  // Curvature tests (peak_search.h): C bounds the second derivative along d over the node
  // (|d| = 1, so dx^2 + dy^2 + 2 |dx dy| weighs the three bounds); both use z and z' at t0.
  const double adx2 = d.x * d.x, ady2 = d.y * d.y, adxy = 2.0 * std::abs(d.x * d.y);
  enum class Shape { unknown, hidden, rising };
  auto classify = [&](const Node& n, const Heightfield::Level& L, size_t k) {
    if (!(n.t0 > 0.0)) return Shape::unknown;  // the origin's own node: k is not defined at t0
    const double C = L.node[k].zxx * adx2 + L.node[k].zyy * ady2 + L.node[k].zxy * adxy;
    const HeightSample h = hf.eval(o.x + n.t0 * d.x, o.y + n.t0 * d.y);
    const double dt = n.t1 - n.t0, slope = h.dx * d.x + h.dy * d.y, rise = h.z - o.z;
    // eps as for the maximum test, plus the rounding of the bounds' own terms.
    const double slack = eps + 1e-9 * (std::abs(rise) + std::abs(slope) * (n.t0 + dt) + C * dt * (n.t0 + dt));
    // Hidden: the parabola z0 + z0' s + C s^2 / 2 minus the line is convex, so under it at both ends
    // means under it everywhere.
    if (h.z <= line(n.t0) - slack && h.z + slope * dt + 0.5 * C * dt * dt <= line(n.t1) - slack) {
      ++st.curvature_hidden;
      return Shape::hidden;
    }
    // Rising: t dk/dt = z'(t) - k(t) >= (t0 (z0' - k0) - C t0 s - 1.5 C s^2) / t at t = t0 + s (from
    // z' >= z0' - C s and the parabola), decreasing in s: positive at s = dt means k rises through
    // the whole node, so it holds no maximum and only its far end matters.
    // Parallel rays: dk/dt = z' - k_light >= z0' - C s - k_light, positive at s = dt.
    if (parallel ? slope - k_light > C * dt + 1e-9 * (std::abs(slope) + std::abs(k_light) + C * dt)
                 : n.t0 * slope - rise > C * dt * (n.t0 + 1.5 * dt) + slack) {
      ++st.curvature_rising;
      return Shape::rising;
    }
    return Shape::unknown;
  };
  std::vector<Node> stack;
  stack.reserve(64);
  stack.push_back({top, 0, 0, t_in, t_out});
  while (!stack.empty() && k_run < k_stop) {
    const Node n = stack.back();
    stack.pop_back();
    ++st.nodes;
    // Lowest point of the line o_z + k_run t over the node's span.
    const double line_min = line(line_slope() >= 0.0 ? n.t0 : n.t1);
    if (line_slope() >= 0.0 && line(n.t0) > z_max + eps) break;  // the line is above everything that follows
    const Heightfield::Level& L = hf.mip[n.level];
    const size_t k = size_t(n.j) * L.w + n.i;
    const Shape shape = !opt.use_mipmap                ? Shape::unknown
                        : L.node[k].hi <= line_min - eps    ? Shape::hidden
                        : opt.curvature_test           ? classify(n, L, k)
                                                       : Shape::unknown;
    if (shape == Shape::hidden) {
      have_prev = false;
      last_is_record = false;
      continue;
    }
    if (shape == Shape::rising) {  // no maximum inside: continue the run from the node's far end
      add_sample(sample_at(n.t1));
      continue;
    }
    if (n.level > 0) {
      std::array<Node, 4> kids;
      int count = 0;
      for (int b = 0; b < 2; ++b)
        for (int a = 0; a < 2; ++a) {
          double c0 = n.t0, c1 = n.t1;
          const int ci = 2 * n.i + a, cj = 2 * n.j + b;
          if (hf.node_span(n.level - 1, ci, cj, o.x, o.y, d.x, d.y, c0, c1) && c1 > c0) kids[count++] = {n.level - 1, ci, cj, c0, c1};
        }
      for (int a = 1; a < count; ++a)  // farthest first, so the nearest child is popped next
        for (int b = a; b > 0 && kids[b - 1].t0 < kids[b].t0; --b) std::swap(kids[b - 1], kids[b]);
      for (int c = 0; c < count; ++c) stack.push_back(kids[c]);
      continue;
    }
    ++st.cells;
    cell.load(hf, n.i, n.j);
    // Sub-steps of this cell; the cell's first point is the previous cell's last unless the run
    // was broken, and t = 0 itself (the origin) is never a sample.
    const bool continues = have_prev && std::abs(prev.t - n.t0) <= 1e-12 * std::max(1.0, n.t0);
    for (int s = continues ? 1 : 0; s <= n_sub; ++s) {
      const double t = n.t0 + (n.t1 - n.t0) * s / n_sub;
      if (t <= 1e-9 * (hf.width + hf.depth)) continue;
      add_sample(sample_at(t));
    }
  }
  if (blocked) *blocked = k_run >= k_stop;
  // The far edge is a silhouette when the slope still rises there.
  if (k_run < k_stop && last_is_record && std::abs(last_t - t_out) <= 1e-9 * std::max(1.0, t_out))
    peaks.push_back({t_out, prev.k, true});
  return peaks;
}

}  // namespace

std::vector<SlicePeak> find_peaks(const Heightfield& hf, const Vec3d& o, const glm::dvec2& d, double k_start, double k_stop,
                                  const PeakSearchOptions& opt, PeakSearchStats* stats, bool* blocked) {
  return search(hf, o, d, k_start, k_stop, opt, stats, blocked, false, 0.0);
}

std::vector<SlicePeak> find_parallel_peaks(const Heightfield& hf, const Vec3d& o, const glm::dvec2& d, double k_light,
                                           const PeakSearchOptions& opt, PeakSearchStats* stats) {
  return search(hf, o, d, -1e300, 1e300, opt, stats, nullptr, true, k_light);
}

}  // namespace limn
