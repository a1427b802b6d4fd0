// The fingerprint that ties a stored tree to the geometry it was built over.
#pragma once

#include <cstdint>

#include "bvhopt/mesh.h"

namespace bvhopt {

// A 64-bit hash of the geometry exactly as it will be traced: the bit patterns of every
// position (after any rotation) and every index, and their counts. A tree file stores it
// (docs/file-format.md, "Version 2: the geometry fingerprint") so that a tree is never traced against
// another scene of the same triangle count, the scene rotated otherwise, or the built-in
// scene with another seed. Never 0 (0 means "unknown" in a file). Deterministic; computed
// in parallel blocks whose hashes are combined in order.
uint64_t geometry_fingerprint(const Mesh& mesh);

}  // namespace bvhopt
