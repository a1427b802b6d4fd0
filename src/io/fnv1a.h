// Internal: the 64-bit FNV-1a checksum of the ray and wide export files.
#pragma once

#include <cstddef>
#include <cstdint>

namespace bvhopt::detail {

inline constexpr uint64_t kFnvBasis = 0xCBF29CE484222325ull;

inline uint64_t fnv1a(uint64_t h, const void* data, size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001B3ull;
  }
  return h;
}

}  // namespace bvhopt::detail
