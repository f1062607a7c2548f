// Hierarchical guiding (projective-sampling paper, section 5.1.2): the first axis of the boundary
// sample space is pre-split into `slices` equal slabs (heterogeneity across edges, shapes and
// their concatenation); each slab is an octree built bottom-up from projected samples, splitting a
// node 8 ways while it holds more than one sample and is shallower than `max_depth` (given
// `values`, only samples whose one-sample integrand estimate is non-zero count: the others mark no
// feature, and a feature point estimated at zero is still covered by the leaf masses). Every leaf's
// mass is then estimated from `leaf_samples` uniform points inside it, one per octant in each
// round of 8 (no projections needed),
// together with the integrand at the projected points the leaf holds (`values`, optional: a leaf
// narrower than its feature would otherwise often miss it with a few uniform points), and leaves
// are sampled in proportion to it, mixed with a defensive uniform component. Renders sample it
// in a GuideMixture with the projective grid (core/guiding/mixture.h, DiffOptions::octree_grid_mix)
// and with the projections' direction histogram (DiffOptions::direction_mix).
// `trained` points (the training round's, DiffOptions::octree_training) split like the others;
// chosen where the projective grid (with its direction histogram) under-samples the integrand,
// i.e. for large values, each adds its value times the volume of one finest cell (depth
// max_depth) to its leaf's mass: counted
// like the uniform points, times the leaf's volume, they inflated large leaves and starved the
// rest; left out, a leaf around a narrow peak they found kept a zero mass whenever its uniform
// points missed the peak (docs/reports/projective/README.md).
//
// Refinement rounds split the heavy leaves and their coarse face neighbours (OctreeOptions).
//
// Memory is bounded by `max_leaves`: when splitting would exceed it the tree stops growing there
// (the partition breadth first, refinement heaviest leaves first; coarsened(), said in the
// summary), never dropping samples or the boundary term.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>
#include "core/guiding/guide.h"
#include "core/math/distribution.h"

namespace limn {

struct OctreeOptions {
  int slices = 100;          // the paper's 100 trees along the first axis
  int max_depth = 9;         // the paper's maximum depth
  int leaf_samples = 8;      // the paper has 32; at 8 the leaf masses already take most of the set-up
  size_t max_leaves = 1u << 20;
  float defensive = 0.1f;
  // Rounds that split every leaf of more than refine_factor x the mean leaf mass into 8 (up to
  // max_depth) and estimate the new leaves' masses from leaf_samples uniform points each: the
  // partition stops at one point per leaf, which leaves the peaks inside the heavy leaves coarse.
  // Two rounds by default: 1.43x less error at equal time on the paper's scenes
  // (docs/reports/projective/octree_refinement.md); 0 is the paper's octree.
  int refine_rounds = 2;
  float refine_factor = 1.0f;
  // Deepest level refinement splits to; -1: max_depth (the points' partition stops there either
  // way). For experiments (limn_guide_variance --refine-depth): deeper leaves did not pay on the
  // paper's scenes, breadth did (docs/reports/projective/README.md, fourteenth pass).
  int refine_depth = -1;
  // Refinement also splits a heavy leaf's face neighbours that are 2 or more levels coarser than
  // it: a peak that crosses the face into a large leaf is otherwise missed by that leaf's few
  // uniform points, which leaves it at a low density right next to the peak. The indirect term's
  // run-to-run noise at 1024 spp (6 runs, tests/bench/noise_decomposition.py): cube with a hole
  // 0.0140 -> 0.0044 (one sample at 1/28 of the density around it made a 44-sigma pixel),
  // sphere 0.0057 -> 0.0048, torus 0.0140 -> 0.0106, bunny 0.0661 -> 0.0578, for 2-6 % more
  // set-up (docs/reports/projective/README.md, fifteenth pass). false: for comparisons.
  bool refine_neighbours = true;
};

class BoundaryOctree : public BoundaryGuide {
 public:
  // integrand(u) >= 0; called from several threads at once.
  BoundaryOctree(const std::vector<Vec3>& points, const OctreeOptions& options, uint64_t seed, int threads,
                 const std::function<float(const Vec3&)>& integrand, const std::vector<float>& values = {},
                 const std::vector<Vec3>& trained = {}, const std::vector<float>& trained_values = {});

  Vec3 sample(const Vec3d& u, float* pdf) const override;
  float pdf(const Vec3& p) const override;
  float pdf_first(float p0) const override;
  size_t memory_bytes() const override;
  std::string describe() const override;
  size_t region_count() const override { return m_leaves.size(); }
  size_t region_of(const Vec3& p) const override { return size_t(leaf_at(p)); }
  double region_probability(size_t l) const override { return m_select.pmf(l); }
  Box region_box(size_t l) const override { return {m_leaves[l].lo, m_leaves[l].size}; }
  double box_probability(const Box& box) const override;

  size_t leaf_count() const { return m_leaves.size(); }
  size_t empty_leaves() const { return m_empty; }
  bool coarsened() const { return m_coarsened; }

 private:
  struct Node {
    int child = -1;  // first of 8 children, -1 for a leaf
    int leaf = -1;   // index into m_leaves for leaves
    double prob = 0.0;  // of the leaves below
  };
  struct Leaf {
    Vec3 lo, size;
  };
  int leaf_at(const Vec3& p) const;
  // Splits the slabs at points[splitting] (fills m_nodes, m_leaves); the points each leaf holds.
  std::vector<std::vector<uint32_t>> partition(const std::vector<Vec3>& points, const std::vector<uint32_t>& splitting);
  // Leaf probabilities from masses (with the defensive share) and the first coordinate's marginal.
  void finish(const std::vector<double>& mass);
  // Splits leaves of large mass into 8 and estimates the new leaves' masses from uniform points.
  void refine(std::vector<double>& mass, const std::function<float(const Vec3&)>& integrand, uint64_t seed, int threads);
  // Sum of the integrand at leaf_samples uniform points in the leaf (the stream: seed and index).
  double uniform_sum(const Leaf& leaf, const std::function<float(const Vec3&)>& integrand, uint64_t seed, size_t index) const;

  OctreeOptions m_opt;
  std::vector<Node> m_nodes;       // the first `slices` nodes are the slab roots
  std::vector<Leaf> m_leaves;
  std::vector<float> m_prob;       // mixture probability of each leaf
  Distribution1D m_select;
  Distribution1D m_slabs;          // the slabs' probabilities
  std::vector<float> m_first;      // density of the first coordinate on a fine regular grid
  size_t m_empty = 0;
  size_t m_splitting = 0;  // points that took part in the partition
  bool m_valued = false;   // built with values (only non-zero ones split)
  bool m_coarsened = false;
  int m_deepest = 0;
  size_t m_refined = 0;  // leaves made by refine()
  size_t m_neighbours_split = 0;  // coarse neighbours of heavy leaves split (refine_neighbours)
  size_t m_depth_limited = 0;  // leaves heavy enough to split in the last round but at refine_depth
};

}  // namespace limn
