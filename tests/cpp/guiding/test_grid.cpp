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
