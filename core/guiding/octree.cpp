#include "core/guiding/octree.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <algorithm>
#include <cmath>
#include <deque>
#include <stdexcept>
#include <string>
#include "core/math/rng.h"

namespace limn {

namespace {

void check_options(const OctreeOptions& opt) {
  if (opt.slices < 1 || opt.slices > 1 << 16) throw std::invalid_argument("octree guiding: slices must be in [1, 65536] (got " + std::to_string(opt.slices) + ")");
  if (opt.max_depth < 0 || opt.max_depth > 12) throw std::invalid_argument("octree guiding: max_depth must be in [0, 12] (got " + std::to_string(opt.max_depth) + ")");
  if (opt.leaf_samples < 1) throw std::invalid_argument("octree guiding: leaf_samples must be >= 1 (got " + std::to_string(opt.leaf_samples) + ")");
  if (opt.max_leaves < size_t(opt.slices)) throw std::invalid_argument("octree guiding: max_leaves must be >= slices");
  if (opt.refine_rounds < 0 || opt.refine_rounds > 8) throw std::invalid_argument("octree guiding: refine_rounds must be in [0, 8] (got " + std::to_string(opt.refine_rounds) + ")");
  if (opt.refine_depth < -1 || opt.refine_depth > 12) throw std::invalid_argument("octree guiding: refine_depth must be -1 (max_depth) or in [0, 12] (got " + std::to_string(opt.refine_depth) + ")");
  if (!(opt.refine_factor > 0.0f) || !std::isfinite(opt.refine_factor)) throw std::invalid_argument("octree guiding: refine_factor must be > 0 (got " + std::to_string(opt.refine_factor) + ")");
}

// A leaf's depth below its slab root (the second axis is never split by the slabs).
int depth_of(const Vec3& size) { return int(std::lround(-std::log2(double(size.y)))); }

int refine_limit(const OctreeOptions& opt) { return opt.refine_depth < 0 ? opt.max_depth : opt.refine_depth; }

bool inside_unit_cube(const Vec3& p) { return p.x >= 0.0f && p.x < 1.0f && p.y >= 0.0f && p.y < 1.0f && p.z >= 0.0f && p.z < 1.0f; }

}  // namespace

BoundaryOctree::BoundaryOctree(const std::vector<Vec3>& points, const OctreeOptions& opt, uint64_t seed, int threads,
                               const std::function<float(const Vec3&)>& integrand, const std::vector<float>& values,
                               const std::vector<Vec3>& trained, const std::vector<float>& trained_values)
    : m_opt(opt), m_valued(!values.empty()) {
  check_options(opt);
  if (!values.empty() && values.size() != points.size())
    throw std::invalid_argument("octree guiding: " + std::to_string(values.size()) + " values for " + std::to_string(points.size()) + " points");
  if (trained_values.size() != trained.size())
    throw std::invalid_argument("octree guiding: " + std::to_string(trained_values.size()) + " values for " + std::to_string(trained.size()) + " trained points");
  // Projections where the integrand is zero (a silhouette no path observes) mark no feature:
  // they would only split empty space (section 5.1.2 builds on "samples concentrated at the
  // sparse features"; Mitsuba's prb_projective keeps points of non-zero mass likewise). Trained
  // points (indices from points.size() on) were selected for non-zero values.
  std::vector<Vec3> all = points;
  all.insert(all.end(), trained.begin(), trained.end());
  std::vector<uint32_t> splitting;
  for (size_t i = 0; i < all.size(); ++i)
    if (inside_unit_cube(all[i]) && (i >= points.size() || values.empty() || (std::isfinite(values[i]) && values[i] > 0.0f)))
      splitting.push_back(uint32_t(i));
  const std::vector<std::vector<uint32_t>> leaf_points = partition(all, splitting);

  // Leaf masses from uniform points inside each leaf.
  const double finest_cell = 1.0 / (double(opt.slices) * std::ldexp(1.0, 3 * opt.max_depth));
  std::vector<double> mass(m_leaves.size(), 0.0);
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m_leaves.size(), 64), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t l = r.begin(); l != r.end(); ++l) {
        const Leaf& leaf = m_leaves[l];
        double sum = uniform_sum(leaf, integrand, seed, l);
        int count = opt.leaf_samples;
        double found = 0.0;  // the trained points' values, each over one finest cell
        for (uint32_t i : leaf_points[l]) {
          if (i >= points.size()) {
            found += trained_values[i - points.size()] * finest_cell;
          } else if (i < values.size()) {
            sum += values[i];
            ++count;
          }
        }
        mass[l] = sum / count * double(leaf.size.x) * leaf.size.y * leaf.size.z + found;
      }
    });
  });
  for (int round = 0; round < opt.refine_rounds; ++round) refine(mass, integrand, seed + 1000003ULL * uint64_t(round + 1), threads);
  finish(mass);
}

double BoundaryOctree::uniform_sum(const Leaf& leaf, const std::function<float(const Vec3&)>& integrand, uint64_t seed, size_t index) const {
  Pcg32 rng = pixel_rng(mix_bits(seed ^ 0x6f63747265650aULL), index);
  double sum = 0.0;
  // In rounds of 8 (leaf_samples a multiple of 8): one point per octant, and along each axis one
  // per eighth of the leaf (a Latin hypercube within the octants: the halves' four eighths shuffled).
  // Variance of the derivative image per sample with the default guide, 4 guide seeds, against
  // independent points: sphere 354 -> 244, torus 1150 -> 1023, cube with a hole 503 -> 354, bunny
  // 3757 -> 2765 (octants alone: 274, 1101, 407, 3940; docs/reports/projective/README.md).
  const bool stratified = m_opt.leaf_samples % 8 == 0;
  int eighth[3][8];  // [axis][octant]: which eighth of the leaf along the axis
  for (int s = 0; s < m_opt.leaf_samples; ++s) {
    const int octant = s % 8;
    if (stratified && octant == 0) {
      for (int a = 0; a < 3; ++a)
        for (int half = 0; half < 2; ++half) {
          int order[4] = {0, 1, 2, 3};
          for (int i = 3; i > 0; --i) std::swap(order[i], order[std::min(i, int(rng.next_float() * float(i + 1)))]);
          int k = 0;
          for (int o = 0; o < 8; ++o)
            if (((o >> a) & 1) == half) eighth[a][o] = 4 * half + order[k++];
        }
    }
    Vec3 v(rng.next_float(), rng.next_float(), rng.next_float());
    if (stratified) v = (v + Vec3(float(eighth[0][octant]), float(eighth[1][octant]), float(eighth[2][octant]))) / 8.0f;
    const Vec3 p = leaf.lo + leaf.size * v;
    const float f = integrand(glm::min(p, Vec3(1.0f - 1e-7f)));
    if (std::isfinite(f) && f > 0.0f) sum += f;
  }
  return sum;
}

void BoundaryOctree::refine(std::vector<double>& mass, const std::function<float(const Vec3&)>& integrand, uint64_t seed, int threads) {
  double total = 0.0;
  for (double m : mass) total += m;
  if (!(total > 0.0)) return;
  const double threshold = m_opt.refine_factor * total / double(m_leaves.size());
  const int deepest = refine_limit(m_opt);
  std::vector<int> leaf_node(m_leaves.size(), -1);
  for (size_t k = 0; k < m_nodes.size(); ++k)
    if (m_nodes[k].child < 0) leaf_node[size_t(m_nodes[k].leaf)] = int(k);
  // The leaves to split: heavy and above refine_depth, and their coarse face neighbours; beyond
  // the leaf budget the heaviest ones (the budget coarsens where the mass is least), split in
  // index order either way.
  std::vector<size_t> heavy, limited;
  for (size_t l = 0; l < m_leaves.size(); ++l) {
    if (!(mass[l] > threshold)) continue;
    if (depth_of(m_leaves[l].size) >= deepest) limited.push_back(l);
    else heavy.push_back(l);
  }
  m_depth_limited = limited.size();
  std::vector<char> neighbour;
  if (m_opt.refine_neighbours) {
    // Face neighbours of heavy leaves that are at least 2 levels coarser: the point just across a
    // face's centre lies in such a neighbour whenever one touches the face (the tree is aligned).
    // Half the finest cell's width along the axis reaches across and stays inside the neighbour.
    const double finest = std::ldexp(1.0, -m_opt.max_depth);
    const Vec3 step(float(0.5 * finest / m_opt.slices), float(0.5 * finest), float(0.5 * finest));
    std::vector<char> chosen(m_leaves.size(), 0);  // 1: heavy, 2: a coarse neighbour
    for (size_t l : heavy) chosen[l] = 1;
    std::vector<size_t> over = heavy;
    over.insert(over.end(), limited.begin(), limited.end());
    for (size_t o : over) {
      const Leaf& h = m_leaves[o];
      const int depth = depth_of(h.size);
      const Vec3 centre = h.lo + 0.5f * h.size;
      for (int a = 0; a < 3; ++a)
        for (int side = 0; side < 2; ++side) {
          Vec3 q = centre;
          q[a] = side ? h.lo[a] + h.size[a] + step[a] : h.lo[a] - step[a];
          if (!inside_unit_cube(q)) continue;
          const size_t n = size_t(leaf_at(q));
          if (chosen[n] || depth_of(m_leaves[n].size) > depth - 2) continue;
          chosen[n] = 2;
          heavy.push_back(n);
        }
    }
    std::sort(heavy.begin(), heavy.end());
    neighbour = std::move(chosen);
  }
  const size_t room = (m_opt.max_leaves - m_leaves.size()) / 7;
  if (heavy.size() > room) {
    m_coarsened = true;
    auto heavier = [&](size_t a, size_t b) { return mass[a] > mass[b] || (mass[a] == mass[b] && a < b); };
    std::nth_element(heavy.begin(), heavy.begin() + std::ptrdiff_t(room), heavy.end(), heavier);
    heavy.resize(room);
    std::sort(heavy.begin(), heavy.end());
  }
  for (size_t l : heavy) m_neighbours_split += !neighbour.empty() && neighbour[l] == 2;
  std::vector<size_t> fresh;     // leaves whose mass is to be estimated
  std::vector<double> inherited;  // an eighth of each fresh leaf's parent's mass
  for (size_t l : heavy) {
    const int depth = depth_of(m_leaves[l].size);
    const Leaf parent = m_leaves[l];
    const double parent_mass = mass[l];
    const int node = leaf_node[l], first = int(m_nodes.size());
    m_nodes[size_t(node)].child = first;
    m_nodes[size_t(node)].leaf = -1;
    m_nodes.resize(m_nodes.size() + 8);
    const Vec3 half = 0.5f * parent.size, mid = parent.lo + half;
    for (int c = 0; c < 8; ++c) {
      const Leaf child{Vec3(c & 1 ? mid.x : parent.lo.x, c & 2 ? mid.y : parent.lo.y, c & 4 ? mid.z : parent.lo.z), half};
      const size_t index = c == 0 ? l : m_leaves.size();
      if (c == 0) m_leaves[l] = child;
      else m_leaves.push_back(child);
      m_nodes[size_t(first + c)].leaf = int(index);
      fresh.push_back(index);
      inherited.push_back(parent_mass / 8.0);
    }
    m_deepest = std::max(m_deepest, depth + 1);
  }
  mass.resize(m_leaves.size(), 0.0);
  m_refined += fresh.size();
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    // Half the parent's mass spread evenly: a child whose uniform points all missed the parent's
    // peak keeps half the parent's density, so no part of a heavy leaf becomes a heavy tail.
    tbb::parallel_for(size_t(0), fresh.size(), [&](size_t i) {
      const Leaf& leaf = m_leaves[fresh[i]];
      const double own = uniform_sum(leaf, integrand, seed, fresh[i]) / m_opt.leaf_samples * double(leaf.size.x) * leaf.size.y * leaf.size.z;
      mass[fresh[i]] = 0.5 * own + 0.5 * inherited[i];
    });
  });
}

std::vector<std::vector<uint32_t>> BoundaryOctree::partition(const std::vector<Vec3>& points, const std::vector<uint32_t>& splitting) {
  // Bottom-up partition, breadth first so that a leaf budget coarsens evenly.
  struct Pending {
    int node, depth;
    Vec3 lo, size;
    std::vector<uint32_t> idx;
  };
  const int S = m_opt.slices;
  m_nodes.resize(size_t(S));
  std::deque<Pending> queue;
  std::vector<std::vector<uint32_t>> by_slice(static_cast<size_t>(S));
  for (uint32_t i : splitting) by_slice[size_t(std::min(int(points[i].x * S), S - 1))].push_back(i);
  m_splitting = splitting.size();
  for (int s = 0; s < S; ++s) queue.push_back({s, 0, Vec3(float(s) / S, 0.0f, 0.0f), Vec3(1.0f / S, 1.0f, 1.0f), std::move(by_slice[size_t(s)])});
  size_t leaves = size_t(S);
  m_deepest = 0;
  std::vector<std::pair<int, Leaf>> leaf_nodes;
  std::vector<std::vector<uint32_t>> leaf_points;  // the points each leaf holds
  while (!queue.empty()) {
    Pending n = std::move(queue.front());
    queue.pop_front();
    const bool split = n.idx.size() > 1 && n.depth < m_opt.max_depth;
    if (split && leaves + 7 > m_opt.max_leaves) m_coarsened = true;
    if (!split || leaves + 7 > m_opt.max_leaves) {
      leaf_nodes.push_back({n.node, Leaf{n.lo, n.size}});
      leaf_points.push_back(std::move(n.idx));
      m_deepest = std::max(m_deepest, n.depth);
      continue;
    }
    leaves += 7;
    const int first = int(m_nodes.size());
    m_nodes[size_t(n.node)].child = first;
    m_nodes.resize(m_nodes.size() + 8);
    const Vec3 half = 0.5f * n.size, mid = n.lo + half;
    std::vector<uint32_t> parts[8];
    for (uint32_t i : n.idx) {
      const Vec3& p = points[i];
      parts[(p.x >= mid.x ? 1 : 0) | (p.y >= mid.y ? 2 : 0) | (p.z >= mid.z ? 4 : 0)].push_back(i);
    }
    for (int c = 0; c < 8; ++c) {
      const Vec3 lo(c & 1 ? mid.x : n.lo.x, c & 2 ? mid.y : n.lo.y, c & 4 ? mid.z : n.lo.z);
      queue.push_back({first + c, n.depth + 1, lo, half, std::move(parts[c])});
    }
  }
  m_leaves.reserve(leaf_nodes.size());
  for (auto& [node, leaf] : leaf_nodes) {
    m_nodes[size_t(node)].leaf = int(m_leaves.size());
    m_leaves.push_back(leaf);
  }
  return leaf_points;
}

void BoundaryOctree::finish(const std::vector<double>& mass) {
  double total = 0.0;
  for (double m : mass) {
    total += m;
    m_empty += m == 0.0;
  }
  m_prob.resize(m_leaves.size());
  for (size_t l = 0; l < m_leaves.size(); ++l) {
    const double volume = double(m_leaves[l].size.x) * m_leaves[l].size.y * m_leaves[l].size.z;
    m_prob[l] = float(total > 0.0 ? (1.0 - m_opt.defensive) * mass[l] / total + m_opt.defensive * volume : volume);
  }
  m_select = Distribution1D(m_prob);
  // Subtree probabilities for sample()'s descent (children come after their parent).
  for (size_t k = m_nodes.size(); k-- > 0;) {
    Node& node = m_nodes[k];
    if (node.child < 0) {
      node.prob = m_select.pmf(size_t(node.leaf));
    } else {
      node.prob = 0.0;
      for (int c = 0; c < 8; ++c) node.prob += m_nodes[size_t(node.child + c)].prob;
    }
  }
  std::vector<float> slab_prob(size_t(m_opt.slices));
  for (int s = 0; s < m_opt.slices; ++s) slab_prob[size_t(s)] = float(m_nodes[size_t(s)].prob);
  m_slabs = Distribution1D(slab_prob);

  // Marginal density of the first coordinate on the finest slab subdivision (a difference array:
  // every leaf adds prob / width over the bins it spans).
  const size_t bins = size_t(m_opt.slices) << m_deepest;
  std::vector<double> diff(bins + 1, 0.0);
  for (size_t l = 0; l < m_leaves.size(); ++l) {
    const size_t b0 = size_t(std::llround(double(m_leaves[l].lo.x) * bins));
    const size_t b1 = std::min(bins, b0 + std::max<size_t>(1, size_t(std::llround(double(m_leaves[l].size.x) * bins))));
    const double density = m_select.pmf(l) / double(m_leaves[l].size.x);
    diff[b0] += density;
    diff[b1] -= density;
  }
  m_first.resize(bins);
  double run = 0.0;
  for (size_t b = 0; b < bins; ++b) m_first[b] = float(run += diff[b]);
}

int BoundaryOctree::leaf_at(const Vec3& p) const {
  const int S = m_opt.slices;
  int node = std::clamp(int(p.x * S), 0, S - 1);
  Vec3 lo(float(node) / S, 0.0f, 0.0f), size(1.0f / S, 1.0f, 1.0f);
  while (m_nodes[size_t(node)].child >= 0) {
    size *= 0.5f;
    const Vec3 mid = lo + size;
    const int c = (p.x >= mid.x ? 1 : 0) | (p.y >= mid.y ? 2 : 0) | (p.z >= mid.z ? 4 : 0);
    lo = Vec3(c & 1 ? mid.x : lo.x, c & 2 ? mid.y : lo.y, c & 4 ? mid.z : lo.z);
    node = m_nodes[size_t(node)].child + c;
  }
  return m_nodes[size_t(node)].leaf;
}

Vec3 BoundaryOctree::sample(const Vec3d& u, float* pdf) const {
  // A descent, marginal then conditionals at every level (the Knothe-Rosenblatt map of the
  // piecewise-constant density, as BoundaryGrid::sample): u.x picks the slab, then at each node
  // u.x the half along axis 0, u.y the half along axis 1 given it and u.z the half along axis 2,
  // each number rescaled to what is left of it. Every axis stays monotone in its own number, so
  // stratified points (core/math/sequence.h) stay stratified along each axis inside the tree.
  const double below_one = std::nextafter(1.0, 0.0);
  // Chooses the upper half when v falls beyond the lower half's share and rescales v.
  auto choose = [below_one](double& v, double lower, double both) {
    const double share = both > 0.0 ? lower / both : 0.5;
    const bool upper = !(v < share);
    v = upper ? (share < 1.0 ? (v - share) / (1.0 - share) : 0.5) : (share > 0.0 ? v / share : 0.5);
    v = std::clamp(v, 0.0, below_one);
    return upper ? 1 : 0;
  };
  size_t slab;
  Vec3d v(m_slabs.sample_remapped(u.x, &slab), u.y, u.z);
  int node = int(slab);
  Vec3d lo(double(slab) / m_opt.slices, 0.0, 0.0), size(1.0 / m_opt.slices, 1.0, 1.0);
  while (m_nodes[size_t(node)].child >= 0) {
    const int first = m_nodes[size_t(node)].child;
    auto prob = [&](int c) { return m_nodes[size_t(first + c)].prob; };
    // Child c = bx | by << 1 | bz << 2 (partition()).
    const int bx = choose(v.x, prob(0) + prob(2) + prob(4) + prob(6), m_nodes[size_t(node)].prob);
    const int by = choose(v.y, prob(bx) + prob(bx | 4), prob(bx) + prob(bx | 2) + prob(bx | 4) + prob(bx | 6));
    const int bz = choose(v.z, prob(bx | by << 1), prob(bx | by << 1) + prob(bx | by << 1 | 4));
    const int c = bx | by << 1 | bz << 2;
    size *= 0.5;
    lo += Vec3d(bx, by, bz) * size;
    node = first + c;
  }
  // Kept inside the leaf the descent chose: lo + size v rounds onto the leaf's far face for v close
  // to 1, and there the next leaf's density would stand for it. Next to a leaf of no mass that is
  // the defensive density, 10^4 - 10^5 times too low where the integrand peaks at the face (one of
  // 16 sphere renders at 1024 spp had a relative RMSE of 1.93 from a single such sample).
  const int l = m_nodes[size_t(node)].leaf;
  const Leaf& leaf = m_leaves[size_t(l)];
  Vec3 p(lo + size * v);
  for (int a = 0; a < 3; ++a) p[a] = std::clamp(p[a], leaf.lo[a], std::min(std::nextafter(leaf.lo[a] + leaf.size[a], leaf.lo[a]), 1.0f - 1e-7f));
  if (leaf_at(p) != l) p = leaf.lo + 0.5f * leaf.size;  // a face rounded differently from the descent's
  *pdf = m_select.pmf(size_t(l)) / (leaf.size.x * leaf.size.y * leaf.size.z);
  return p;
}

float BoundaryOctree::pdf(const Vec3& p) const {
  const int l = leaf_at(p);
  const Leaf& leaf = m_leaves[size_t(l)];
  return m_select.pmf(size_t(l)) / (leaf.size.x * leaf.size.y * leaf.size.z);
}

double BoundaryOctree::box_probability(const Box& box) const {
  double total = 0.0;
  for (size_t l = 0; l < m_leaves.size(); ++l) total += m_select.pmf(l) * overlap_fraction(region_box(l), box);
  return total;
}

float BoundaryOctree::pdf_first(float p0) const {
  const size_t b = std::min(m_first.size() - 1, size_t(std::max(p0, 0.0f) * m_first.size()));
  return m_first[b];
}

size_t BoundaryOctree::memory_bytes() const {
  return m_nodes.size() * sizeof(Node) + m_leaves.size() * (sizeof(Leaf) + sizeof(float) + sizeof(float) + sizeof(double)) +
         m_first.size() * sizeof(float);
}

std::string BoundaryOctree::describe() const {
  return "octree " + std::to_string(m_opt.slices) + " slices split at " + std::to_string(m_splitting) +
         (m_valued ? " points of non-zero value, " : " points, ") + std::to_string(m_leaves.size()) + " leaves (" +
         std::to_string(m_empty) + " empty), depth <= " + std::to_string(m_deepest) + ", " +
         std::to_string(m_opt.leaf_samples) + " uniform samples per leaf" +
         (m_refined > 0 ? ", " + std::to_string(m_refined) + " leaves from " + std::to_string(m_opt.refine_rounds) + " refinement rounds (" +
                                 std::to_string(m_depth_limited) + " heavy leaves at depth " + std::to_string(refine_limit(m_opt)) + " in the last" +
                                 (m_opt.refine_neighbours ? ", " + std::to_string(m_neighbours_split) + " coarse neighbours of heavy leaves split" : "") + ")" : "") +
         (m_coarsened ? ", COARSENED at the leaf budget (max_leaves " + std::to_string(m_opt.max_leaves) + ")" : "");
}

}  // namespace limn
