// splitmix64 (Steele, Lea and Flood 2014): a tiny generator whose sequence is the same on
// every platform and compiler (the standard library's distributions are not), cheap enough
// to give every parallel task its own stream, so that results never depend on the thread
// count.
#pragma once

#include <cstdint>

namespace bvhopt {

inline constexpr uint64_t kGoldenGamma = 0x9e3779b97f4a7c15ull;

// splitmix64's output function: a bijective mix of all 64 bits.
constexpr uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

struct RandomStream {
  uint64_t state = 0;

  constexpr uint64_t next() { return mix64(state += kGoldenGamma); }
  // Uniform in [0, n) (the high 32 bits scaled, without division).
  constexpr uint32_t below(uint32_t n) { return static_cast<uint32_t>((next() >> 32) * n >> 32); }
  // Uniform in [0, 1) with 24 bits.
  constexpr float uniform_float() { return static_cast<float>(next() >> 40) * 0x1p-24f; }
  // Uniform in (0, 1): the centre of one of 2^53 equal cells, so never 0 and never 1 (safe
  // under a logarithm).
  constexpr double open_uniform() { return (static_cast<double>(next() >> 11) + 0.5) * 0x1.0p-53; }
};

}  // namespace bvhopt
