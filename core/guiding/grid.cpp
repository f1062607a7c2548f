#include "core/guiding/grid.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include "core/math/rng.h"

namespace limn {

namespace {
std::string cells_text(const std::array<int, 3>& r) { return std::to_string(r[0]) + "x" + std::to_string(r[1]) + "x" + std::to_string(r[2]); }
}  // namespace

BoundaryGrid::BoundaryGrid(std::array<int, 3> res, int spc, uint64_t seed, int threads,
                           const std::function<float(const Vec3&)>& integrand, float defensive)
    : m_res(res) {
  check_resolution(res);
  if (spc < 1) throw std::invalid_argument("grid guiding: guiding_spp must be >= 1 (got " + std::to_string(spc) + ")");
  const size_t n = size_t(res[0]) * res[1] * res[2];
  std::vector<float> mass(n, 0.0f);
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t c = r.begin(); c != r.end(); ++c) {
        Pcg32 rng = pixel_rng(mix_bits(seed ^ 0x67726964ULL), c);
        const int i0 = int(c / (size_t(res[1]) * res[2])), i1 = int((c / res[2]) % res[1]), i2 = int(c % res[2]);
        double sum = 0;
        for (int s = 0; s < spc; ++s) {
          const Vec3 p((i0 + rng.next_float()) / res[0], (i1 + rng.next_float()) / res[1], (i2 + rng.next_float()) / res[2]);
          const float f = integrand(p);
          if (std::isfinite(f) && f > 0.0f) sum += f;
        }
        mass[c] = float(sum / spc);
      }
    });
  });
  finish(mass, defensive);
}

BoundaryGrid::BoundaryGrid(std::array<int, 3> res, const std::vector<Vec3>& points, const std::vector<float>& values, float defensive)
    : m_res(res), m_projective(true) {
  check_resolution(res);
  std::vector<float> mass(size_t(res[0]) * res[1] * res[2], 0.0f);
  for (size_t i = 0; i < points.size() && i < values.size(); ++i)
    if (std::isfinite(values[i]) && values[i] > 0.0f) mass[cell_of(points[i])] += values[i];
  finish(mass, defensive);
}

void BoundaryGrid::check_resolution(const std::array<int, 3>& res) {
  for (int r : res)
    if (r < 1 || r > kMaxResolution)
      throw std::invalid_argument("grid guiding: resolution must be in [1, " + std::to_string(kMaxResolution) + "] (got " + std::to_string(r) + ")");
  if (size_t(res[0]) * res[1] * res[2] > kMaxCells)
    throw std::invalid_argument("grid guiding: " + cells_text(res) + " cells exceed the limit of " + std::to_string(kMaxCells) +
                                " (lower grid_resolution)");
}

void BoundaryGrid::finish(const std::vector<float>& mass, float defensive) {
  const size_t n = mass.size();
  double total = 0;
  for (float m : mass) {
    total += m;
    m_empty += m == 0.0f;
  }
  // Mixture: (1 - defensive) * mass / total + defensive / n; all-uniform when nothing was found.
  m_mass.resize(n);
  for (size_t c = 0; c < n; ++c)
    m_mass[c] = total > 0.0 ? float((1.0 - defensive) * mass[c] / total + defensive / double(n)) : float(1.0 / double(n));
  m_cells = Distribution1D(m_mass);
  m_first.assign(m_res[0], 0.0f);
  for (size_t c = 0; c < n; ++c) m_first[c / (size_t(m_res[1]) * m_res[2])] += m_cells.pmf(c);
}

std::string BoundaryGrid::describe() const {
  // One cell along the first axis: a histogram of the directions alone (DiffOptions::direction_mix).
  const bool directions_only = m_res[0] == 1 && m_res[1] * m_res[2] > 1;
  const std::string cells = directions_only ? "over the directions only, " + std::to_string(m_res[1]) + "x" + std::to_string(m_res[2])
                                          : cells_text(m_res);
  return std::string(m_projective ? "projective grid " : "grid ") + cells + " (" + std::to_string(m_empty) + " of " +
         std::to_string(m_mass.size()) + " cells empty)";
}

size_t BoundaryGrid::cell_of(const Vec3& p) const {
  const int i0 = std::clamp(int(p.x * m_res[0]), 0, m_res[0] - 1);
  const int i1 = std::clamp(int(p.y * m_res[1]), 0, m_res[1] - 1);
  const int i2 = std::clamp(int(p.z * m_res[2]), 0, m_res[2] - 1);
  return (size_t(i0) * m_res[1] + i1) * m_res[2] + i2;
}

Vec3 BoundaryGrid::sample(const Vec3d& u, float* pdf) const {
  // Marginal then conditionals (a Knothe-Rosenblatt map, as pbrt's 2D distributions): u.x picks
  // the slab along axis 0, u.y the row along axis 1 within it, u.z the cell within the row, and
  // each number's remainder places the point along its axis. Each axis is monotone in its number,
  // so stratified points (core/math/sequence.h) stay stratified along every axis. Picking the cell
  // from the row-major order with u.x alone made the baseline grid's error 1.3-3x larger with
  // stratified points (docs/reports/projective/README.md, tenth pass).
  const size_t row = size_t(m_res[2]), slab = size_t(m_res[1]) * row;
  const double below_one = std::nextafter(1.0, 0.0);
  // Of `count` consecutive bins starting at cell `begin`, `stride` cells each: the one holding
  // the fraction v of their mass (skipping empty ones), and where v fell inside it.
  auto pick = [&](double v, size_t begin, size_t stride, int count, int* k) {
    const double lo = m_cells.cdf(begin), t = lo + v * (m_cells.cdf(begin + stride * size_t(count)) - lo);
    int a = 0, b = count - 1;
    while (a < b) {
      const int mid = (a + b) / 2;
      if (m_cells.cdf(begin + stride * size_t(mid + 1)) > t) b = mid;
      else a = mid + 1;
    }
    while (a > 0 && !(m_cells.cdf(begin + stride * size_t(a + 1)) > m_cells.cdf(begin + stride * size_t(a)))) --a;
    *k = a;
    const double c0 = m_cells.cdf(begin + stride * size_t(a)), c1 = m_cells.cdf(begin + stride * size_t(a + 1));
    return c1 > c0 ? std::clamp((t - c0) / (c1 - c0), 0.0, below_one) : 0.5;
  };
  int i0, i1, i2;
  const double f0 = pick(u.x, 0, slab, m_res[0], &i0);
  const double f1 = pick(u.y, size_t(i0) * slab, row, m_res[1], &i1);
  const double f2 = pick(u.z, size_t(i0) * slab + size_t(i1) * row, 1, m_res[2], &i2);
  // Kept below the cell's far face (i + f rounds up to i + 1 for f close to 1).
  auto inside = [](int i, double f, int res) { return std::min(float((i + f) / res), std::nextafter(float(i + 1) / res, 0.0f)); };
  const Vec3 p(inside(i0, f0, m_res[0]), inside(i1, f1, m_res[1]), inside(i2, f2, m_res[2]));
  *pdf = m_cells.pmf((size_t(i0) * m_res[1] + i1) * m_res[2] + i2) * float(m_mass.size());
  return p;
}

Box BoundaryGrid::region_box(size_t c) const {
  const int i0 = int(c / (size_t(m_res[1]) * m_res[2])), i1 = int((c / m_res[2]) % m_res[1]), i2 = int(c % m_res[2]);
  const Vec3 size(1.0f / m_res[0], 1.0f / m_res[1], 1.0f / m_res[2]);
  return {Vec3(float(i0), float(i1), float(i2)) * size, size};
}

double BoundaryGrid::box_probability(const Box& box) const {
  // Only the cells the box overlaps (one cell more on each side against rounding).
  std::array<int, 3> lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::clamp(int(std::floor(box.lo[a] * m_res[a])) - 1, 0, m_res[a] - 1);
    hi[a] = std::clamp(int(std::ceil((box.lo[a] + box.size[a]) * m_res[a])), 0, m_res[a] - 1);
  }
  double total = 0.0;
  for (int i0 = lo[0]; i0 <= hi[0]; ++i0)
    for (int i1 = lo[1]; i1 <= hi[1]; ++i1)
      for (int i2 = lo[2]; i2 <= hi[2]; ++i2) {
        const size_t c = (size_t(i0) * m_res[1] + i1) * m_res[2] + i2;
        total += m_cells.pmf(c) * overlap_fraction(region_box(c), box);
      }
  return total;
}

float BoundaryGrid::pdf(const Vec3& p) const { return m_cells.pmf(cell_of(p)) * float(m_mass.size()); }

float BoundaryGrid::pdf_first(float p0) const {
  const int i0 = std::clamp(int(p0 * m_res[0]), 0, m_res[0] - 1);
  return m_first[i0] * float(m_res[0]);
}

GridPyramid::GridPyramid(std::array<int, 3> res, int coarser, int finer, const std::vector<Vec3>& points, const std::vector<float>& values,
                         float defensive) {
  for (int octaves : {coarser, finer})
    if (octaves < 0 || octaves > 8) throw std::invalid_argument("grid guiding: octaves must be in [0, 8] (got " + std::to_string(octaves) + ")");
  for (int k = -coarser; k <= finer; ++k) {
    std::array<int, 3> level;
    size_t cells = 1;
    for (int a = 0; a < 3; ++a) {
      level[a] = k < 0 ? std::max(1, res[a] >> -k) : res[a] << k;
      cells *= size_t(level[a]);
    }
    const bool too_fine = k > 0 && (cells > kMaxLevelCells || *std::max_element(level.begin(), level.end()) > BoundaryGrid::kMaxResolution);
    if (too_fine) {
      ++m_left_out;
      continue;
    }
    m_levels.emplace_back(level, points, values, defensive);
  }
}

Vec3 GridPyramid::sample(const Vec3d& u, float* pdf) const {
  // The first number picks the level and is reused, rescaled (and kept below 1), inside it.
  const double L = double(m_levels.size()), scaled = u.x * L;
  const size_t l = std::min(size_t(scaled), m_levels.size() - 1);
  float unused;
  const Vec3 p = m_levels[l].sample(Vec3d(std::min(scaled - double(l), std::nextafter(1.0, 0.0)), u.y, u.z), &unused);
  *pdf = this->pdf(p);
  return p;
}

float GridPyramid::pdf(const Vec3& p) const {
  double sum = 0.0;
  for (const BoundaryGrid& g : m_levels) sum += g.pdf(p);
  return float(sum / double(m_levels.size()));
}

float GridPyramid::pdf_first(float p0) const {
  double sum = 0.0;
  for (const BoundaryGrid& g : m_levels) sum += g.pdf_first(p0);
  return float(sum / double(m_levels.size()));
}

double GridPyramid::box_probability(const Box& box) const {
  double sum = 0.0;
  for (const BoundaryGrid& g : m_levels) sum += g.box_probability(box);
  return sum / double(m_levels.size());
}

size_t GridPyramid::memory_bytes() const {
  size_t bytes = 0;
  for (const BoundaryGrid& g : m_levels) bytes += g.memory_bytes();
  return bytes;
}

std::string GridPyramid::describe() const {
  if (m_levels.size() == 1 && m_left_out == 0) return m_levels[0].describe();
  const auto first = m_levels.front().resolution(), last = m_levels.back().resolution();
  const bool directions_only = last[0] == 1;  // the direction histogram's coarser levels (DiffOptions::direction_octaves)
  auto text = [&](const std::array<int, 3>& r) { return directions_only ? std::to_string(r[1]) + "x" + std::to_string(r[2]) : cells_text(r); };
  std::string s = std::string("projective grid ") + (directions_only ? "over the directions only, " : "") + "pyramid of " +
                  std::to_string(m_levels.size()) + " levels, " + text(first) + " to " + text(last) + " cells, equal shares (" +
                  std::to_string(m_levels.back().empty_cells()) + " of " + std::to_string(m_levels.back().cell_count()) + " finest cells empty)";
  if (m_left_out > 0)
    s += ", " + std::to_string(m_left_out) + " finer level(s) left out (over " + std::to_string(kMaxLevelCells) + " cells)";
  return s;
}

}  // namespace limn
