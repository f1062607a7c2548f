// Grid guiding: the density integrates to 1, samples follow it, and the defensive mixture keeps
// every cell reachable.
#include <doctest/doctest.h>

#include "core/guiding/grid.h"
#include "core/math/rng.h"

using namespace limn;

TEST_CASE("grid guiding: pdf integrates to 1, sampling matches it, no zero-probability cell") {
  // A peaked integrand: a thin slab and a corner.
  auto f = [](const Vec3& u) { return (std::abs(u.x - 0.3f) < 0.02f ? 50.0f : 0.0f) + (u.y > 0.9f && u.z > 0.9f ? 5.0f : 0.0f); };
  const BoundaryGrid grid({32, 8, 8}, 8, 3, 0, f);
  Pcg32 rng(4);
  const int n = 200000;
  double integral = 0;
  for (int i = 0; i < n; ++i) integral += grid.pdf(Vec3(rng.next_float(), rng.next_float(), rng.next_float()));
  CHECK(integral / n == doctest::Approx(1.0).epsilon(0.02));
  double first = 0;
  for (int i = 0; i < n; ++i) first += grid.pdf_first(rng.next_float());
  CHECK(first / n == doctest::Approx(1.0).epsilon(0.02));
  // Samples: the returned pdf is the density at the sample, and the slab gets most of them.
  int in_slab = 0;
  for (int i = 0; i < 20000; ++i) {
    float pdf;
    const Vec3 p = grid.sample(Vec3d(rng.next_double(), rng.next_float(), rng.next_float()), &pdf);
    CHECK(pdf == doctest::Approx(grid.pdf(p)).epsilon(1e-4));
    CHECK(pdf > 0.0f);
    in_slab += std::abs(p.x - 0.3f) < 0.04f;
  }
  CHECK(in_slab > 10000);
  // Defensive mixture: an empty cell still has 10% / cells of the probability.
  CHECK(grid.pdf(Vec3(0.9f, 0.1f, 0.1f)) == doctest::Approx(0.1f).epsilon(1e-3));
  CHECK(grid.empty_cells() > 0);
  CHECK_THROWS_AS(BoundaryGrid({0, 1, 1}, 1, 0, 0, f), std::invalid_argument);
}

// The sampling map is the Knothe-Rosenblatt map (grid.cpp): u.x alone sets the slab along axis 0,
// u.y then the row with the conditional probabilities given the slab, u.z the cell given the row,
// each axis monotone in its number. So stratified points stay stratified along every axis; with
// the cell picked from the row-major order by u.x alone (before the tenth pass of
// docs/reports/projective/README.md), sweeping u.y moved the point inside one cell only.
TEST_CASE("grid guiding: samples follow the marginal along axis 0 and the conditionals along axes 1 and 2") {
  Pcg32 rng(11);
  std::vector<Vec3> points;
  std::vector<float> values;
  for (int i = 0; i < 4000; ++i) {
    const Vec3 p(rng.next_float(), rng.next_float(), rng.next_float());
    points.push_back(p);
    values.push_back(1.0f + 20.0f * p.x * p.z + (p.y > 0.7f ? 10.0f : 0.0f));
  }
  const std::array<int, 3> res{8, 4, 8};
  const BoundaryGrid grid(res, points, values);
  auto probability = [&](int i0, int i1, int i2) {  // of a cell; -1 sums over an axis
    double sum = 0.0;
    for (int a = 0; a < res[0]; ++a)
      for (int b = 0; b < res[1]; ++b)
        for (int c = 0; c < res[2]; ++c)
          if ((i0 < 0 || a == i0) && (i1 < 0 || b == i1) && (i2 < 0 || c == i2))
            sum += grid.region_probability((size_t(a) * res[1] + b) * res[2] + c);
    return sum;
  };
  const int steps = 4096;
  float pdf;
  for (double ux : {0.13, 0.61}) {
    for (double uy : {0.27, 0.88}) {
      // Sweeping u.z: axes 0 and 1 stay, axis 2 is non-decreasing and visits each cell of the row
      // for its conditional probability.
      const Vec3 first = grid.sample(Vec3d(ux, uy, 0.5 / steps), &pdf);
      const int i0 = int(first.x * res[0]), i1 = int(first.y * res[1]);
      std::vector<int> visits(res[2], 0);
      float last = -1.0f;
      for (int k = 0; k < steps; ++k) {
        const Vec3 p = grid.sample(Vec3d(ux, uy, (k + 0.5) / steps), &pdf);
        CHECK(int(p.x * res[0]) == i0);
        CHECK(int(p.y * res[1]) == i1);
        CHECK(p.z >= last);
        last = p.z;
        ++visits[int(p.z * res[2])];
      }
      for (int i2 = 0; i2 < res[2]; ++i2)
        CHECK(visits[i2] / double(steps) == doctest::Approx(probability(i0, i1, i2) / probability(i0, i1, -1)).epsilon(0.01));
    }
    // Sweeping u.y: axis 0 stays, axis 1 is non-decreasing and visits each row of the slab for its
    // conditional probability.
    const int i0 = int(grid.sample(Vec3d(ux, 0.5 / steps, 0.5), &pdf).x * res[0]);
    std::vector<int> visits(res[1], 0);
    float last = -1.0f;
    for (int k = 0; k < steps; ++k) {
      const Vec3 p = grid.sample(Vec3d(ux, (k + 0.5) / steps, 0.5), &pdf);
      CHECK(int(p.x * res[0]) == i0);
      CHECK(p.y >= last);
      last = p.y;
      ++visits[int(p.y * res[1])];
    }
    for (int i1 = 0; i1 < res[1]; ++i1)
      CHECK(visits[i1] / double(steps) == doctest::Approx(probability(i0, i1, -1) / probability(i0, -1, -1)).epsilon(0.01));
  }
  // Sweeping u.x: axis 0 is non-decreasing and follows the marginal.
  std::vector<int> visits(res[0], 0);
  float last = -1.0f;
  for (int k = 0; k < steps; ++k) {
    const Vec3 p = grid.sample(Vec3d((k + 0.5) / steps, 0.5, 0.5), &pdf);
    CHECK(p.x >= last);
    last = p.x;
    ++visits[int(p.x * res[0])];
  }
  for (int i0 = 0; i0 < res[0]; ++i0)
    CHECK(visits[i0] / double(steps) == doctest::Approx(probability(i0, -1, -1)).epsilon(0.01));
}
