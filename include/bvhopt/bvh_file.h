// The versioned binary BVH file (docs/file-format.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/references.h"

namespace bvhopt {

inline constexpr uint32_t kBvhFileVersion = 1;

// What a file holds besides the tree: enough to trace it against its scene, to optimize
// it further without the scene, and to refuse the wrong scene.
struct BvhFileInfo {
  CostModel cost;                    // the constants the tree was built or optimized with
  std::string scene_name;            // the scene spec or file name it was built from
  uint64_t scene_triangles = 0;      // triangle count of that scene
  std::string method;                // e.g. "sweep", "sweep+anneal"
};

struct BvhFile {
  BvhFileInfo info;
  Bvh bvh;              // as stored: depth-first, every node reachable (the reader refuses others)
  PrimitiveRefs refs;   // boxes and triangle ids of the references (centroids recomputed)
};

// Writes to a temporary file beside `path` and renames it into place; on any failure the
// temporary is removed and Error is thrown, leaving an existing `path` untouched.
void write_bvh_file(const std::filesystem::path& path, const Bvh& bvh, const PrimitiveRefs& refs,
                    const BvhFileInfo& info);

// Throws Error naming the file and the problem: missing, wrong magic, newer version,
// truncated, checksum mismatch, counts or indices out of range, invalid tree.
BvhFile read_bvh_file(const std::filesystem::path& path);

// bvh_file_checksum (for tools that patch a file) is in bvhopt/testing/bvh_file_checksum.h.

}  // namespace bvhopt
