// The geometry fingerprint: see include/bvhopt/geometry_fingerprint.h.
#include "bvhopt/geometry_fingerprint.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "bvhopt/random_stream.h"

namespace bvhopt {
namespace {

// 32-bit words per block of the fingerprint: blocks hash in parallel, their hashes are
// combined in block order, so the result does not depend on the thread count.
constexpr size_t kFingerprintBlock = size_t(1) << 16;

// Multiply-xorshift over the words of one block, seeded by its place in the sequence.
uint64_t hash_words(const unsigned char* words, size_t n, uint64_t seed) {
  uint64_t h = mix64(seed);
  for (size_t i = 0; i < n; ++i) {
    uint32_t w;
    std::memcpy(&w, words + 4 * i, 4);  // floats by bit pattern, without aliasing them
    h = (h ^ w) * kGoldenGamma;
    h ^= h >> 29;
  }
  return mix64(h ^ n);
}

// The hashes of `words` in blocks, appended to `out`; `tag` tells the arrays apart.
void hash_blocks(const void* data, size_t n, uint64_t tag, std::vector<uint64_t>& out) {
  const auto* words = static_cast<const unsigned char*>(data);
  const size_t blocks = (n + kFingerprintBlock - 1) / kFingerprintBlock;
  const size_t base = out.size();
  out.resize(base + blocks);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, blocks), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t b = r.begin(); b != r.end(); ++b) {
      const size_t begin = b * kFingerprintBlock;
      out[base + b] = hash_words(words + 4 * begin, std::min(kFingerprintBlock, n - begin), tag * kGoldenGamma + b);
    }
  });
}

}  // namespace

uint64_t geometry_fingerprint(const Mesh& mesh) {
  static_assert(sizeof(float) == sizeof(uint32_t));
  std::vector<uint64_t> blocks = {mesh.positions.size(), mesh.indices.size()};
  // Floats by bit pattern: -0 and 0 differ, as they may in a traversal's comparisons.
  hash_blocks(mesh.positions.data(), mesh.positions.size(), 1, blocks);
  hash_blocks(mesh.indices.data(), mesh.indices.size(), 2, blocks);
  uint64_t h = 0;
  for (uint64_t b : blocks) h = mix64(h ^ b) + kGoldenGamma;
  return h == 0 ? 1 : h;
}

}  // namespace bvhopt
