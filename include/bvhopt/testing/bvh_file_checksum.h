// The BVH file's checksum, for tools and tests that patch a file and need to re-seal it.
#pragma once

#include <cstdint>

namespace bvhopt {

// The file's 64-bit checksum (docs/file-format.md) over `size` bytes.
uint64_t bvh_file_checksum(const void* data, uint64_t size);

}  // namespace bvhopt
