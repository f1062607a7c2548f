#include "core/guiding/grid.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <stdexcept>
#include <string>
#include "core/math/rng.h"

namespace limn {

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
                                          : std::to_string(m_res[0]) + "x" + std::to_string(m_res[1]) + "x" + std::to_string(m_res[2]);
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
  size_t c;
  const double f = m_cells.sample_remapped(u.x, &c);
  const int i0 = int(c / (size_t(m_res[1]) * m_res[2])), i1 = int((c / m_res[2]) % m_res[1]), i2 = int(c % m_res[2]);
  // Inside the cell: the remapped first number for axis 0, the other two for axes 1 and 2, kept
  // below the cell's far face (i + f rounds up to i + 1 for f close to 1).
  auto inside = [](int i, double f, int res) { return std::min(float((i + f) / res), std::nextafter(float(i + 1) / res, 0.0f)); };
  const Vec3 p(inside(i0, f, m_res[0]), inside(i1, u.y, m_res[1]), inside(i2, u.z, m_res[2]));
  *pdf = m_cells.pmf(c) * float(m_mass.size());
  return p;
}

Box BoundaryGrid::region_box(size_t c) const {
  const int i0 = int(c / (size_t(m_res[1]) * m_res[2])), i1 = int((c / m_res[2]) % m_res[1]), i2 = int(c % m_res[2]);
  const Vec3 size(1.0f / m_res[0], 1.0f / m_res[1], 1.0f / m_res[2]);
  return {Vec3(float(i0), float(i1), float(i2)) * size, size};
}

double BoundaryGrid::box_probability(const Box& box) const {
  double total = 0.0;
  for (size_t c = 0; c < m_mass.size(); ++c) total += m_cells.pmf(c) * overlap_fraction(region_box(c), box);
  return total;
}

float BoundaryGrid::pdf(const Vec3& p) const { return m_cells.pmf(cell_of(p)) * float(m_mass.size()); }

float BoundaryGrid::pdf_first(float p0) const {
  const int i0 = std::clamp(int(p0 * m_res[0]), 0, m_res[0] - 1);
  return m_first[i0] * float(m_res[0]);
}

}  // namespace limn
