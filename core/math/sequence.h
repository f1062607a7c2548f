// Stratified points of [0,1)^3 for a boundary term's n samples of one call (DiffOptions::
// boundary_sampler = "stratified"). Sample j of n gets
//     x = (j + xi) / n                       one jittered point per interval of width 1/n,
//     (y, z) = Sobol dimensions 0 and 1 at index j, Owen-scrambled,
// so that (x, y, z) for n = 2^m is a (0, m, 3)-net in base 2 (Sobol's first two dimensions are a
// (0, 2)-sequence; prefixing j / 2^m makes the net, Niederreiter 1992, Lemma 4.22), and the x of
// consecutive samples are consecutive strata. The guides map the three numbers by marginals and
// conditionals (core/guiding/grid.cpp, octree.cpp), each axis monotone in its own number, so a
// region's count of samples follows its probability far more closely than a binomial count and
// the samples inside it are stratified along every axis, the direction axes included.
// Every point is uniform on [0,1)^3 (xi uniform; nested uniform scrambling, Owen 1995), so the
// estimate stays unbiased, and calls with different seeds are independent.
#pragma once
#include <cmath>
#include <cstdint>
#include "core/math/rng.h"
#include "core/math/vec.h"

namespace limn {

// Sobol's first two dimensions at index i, as 32-bit fractions: dimension 0 is the van der
// Corput sequence (bit reversal), dimension 1 has the direction numbers v_0 = 2^31,
// v_k = v_(k-1) xor (v_(k-1) >> 1) (the Pascal matrix mod 2).
inline uint32_t sobol_dim0(uint32_t i) {
  i = (i << 16) | (i >> 16);
  i = ((i & 0x00ff00ffu) << 8) | ((i & 0xff00ff00u) >> 8);
  i = ((i & 0x0f0f0f0fu) << 4) | ((i & 0xf0f0f0f0u) >> 4);
  i = ((i & 0x33333333u) << 2) | ((i & 0xccccccccu) >> 2);
  return ((i & 0x55555555u) << 1) | ((i & 0xaaaaaaaau) >> 1);
}
inline uint32_t sobol_dim1(uint32_t i) {
  uint32_t r = 0, v = 0x80000000u;
  for (; i; i >>= 1, v ^= v >> 1)
    if (i & 1u) r ^= v;
  return r;
}

// Nested uniform (Owen) scrambling of a 32-bit fraction: bit b (from the top) is flipped by a
// hash of the seed, b and the bits above it, so every point is uniform and a net stays a net.
// Only the top 24 bits are scrambled and kept (the rest are zero); point() fills the digits below.
inline uint32_t owen_scramble(uint32_t v, uint64_t seed) {
  uint32_t out = 0;
  for (int b = 0; b < 24; ++b) {
    const int shift = 31 - b;
    const uint32_t prefix = b == 0 ? 0u : v >> (shift + 1);  // the b bits above this one
    const uint64_t h = mix_bits(seed ^ (uint64_t(prefix) << 6 | uint64_t(b)) * 0x9E3779B97F4A7C15ULL);
    out |= ((v >> shift ^ uint32_t(h)) & 1u) << shift;
  }
  return out;
}

class StratifiedSequence3 {
 public:
  StratifiedSequence3(uint64_t n, uint64_t seed) : m_n(n), m_seed_y(mix_bits(seed ^ 0x79)), m_seed_z(mix_bits(seed ^ 0x7a)) {}
  // Point j (< n, < 2^32); xi and the digits below 2^-24 from rng (three doubles).
  Vec3d point(uint64_t j, Pcg32& rng) const {
    const double x = (double(j) + rng.next_double()) / double(m_n);
    const uint32_t i = uint32_t(j);
    // Below the scrambled 24 bits, a uniform offset: the deeper digits of a full nested scramble.
    const double y = (double(owen_scramble(sobol_dim0(i), m_seed_y) >> 8) + rng.next_double()) * 0x1p-24;
    const double z = (double(owen_scramble(sobol_dim1(i), m_seed_z) >> 8) + rng.next_double()) * 0x1p-24;
    return Vec3d(x < 1.0 ? x : std::nextafter(1.0, 0.0), y, z);
  }

 private:
  uint64_t m_n, m_seed_y, m_seed_z;
};

}  // namespace limn
