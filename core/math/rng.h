// PCG32 random number generator (O'Neill 2014). One stream per pixel, so the image for a given
// seed does not depend on how pixels are distributed over threads.
#pragma once
#include <cstdint>
#include "core/math/vec.h"

namespace limn {

class Pcg32 {
 public:
  Pcg32(uint64_t seed = 0x853c49e6748fea9bULL, uint64_t stream = 0xda3e39cb94b95bdbULL) { seed_stream(seed, stream); }

  void seed_stream(uint64_t seed, uint64_t stream) {
    m_state = 0;
    m_inc = (stream << 1u) | 1u;
    next_u32();
    m_state += seed;
    next_u32();
  }
  uint32_t next_u32() {
    const uint64_t old = m_state;
    m_state = old * 6364136223846793005ULL + m_inc;
    const uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
    const uint32_t rot = static_cast<uint32_t>(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
  }
  // Uniform in [0, 1): 24 random mantissa bits, so 1 - 2^-24 is the largest value.
  float next_float() { return static_cast<float>(next_u32() >> 8) * 0x1p-24f; }
  // Uniform in [0, 1) with 53 random bits (two draws), for numbers that are remapped many times.
  double next_double() {
    const uint64_t hi = next_u32() >> 5, lo = next_u32() >> 6;
    return double((hi << 26) | lo) * 0x1p-53;
  }
  Vec2 next_2d() {
    const float a = next_float();
    return Vec2(a, next_float());
  }

 private:
  uint64_t m_state = 0, m_inc = 1;
};

// SplitMix64 finaliser: decorrelates (seed, pixel) pairs before they become PCG states.
inline uint64_t mix_bits(uint64_t v) {
  v ^= v >> 31;
  v *= 0x7fb5d329728ea185ULL;
  v ^= v >> 27;
  v *= 0x81dadef4bc2dd44dULL;
  v ^= v >> 33;
  return v;
}

inline Pcg32 pixel_rng(uint64_t seed, uint64_t pixel_index) {
  return Pcg32(mix_bits(seed * 0x9E3779B97F4A7C15ULL + pixel_index), mix_bits(pixel_index + 0x51ED270B27D5B1F3ULL));
}

}  // namespace limn
