// The versioned binary BVH file (docs/file-format.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"

namespace bvhopt {

// Version 2 adds the geometry fingerprint; version-1 files are still read.
inline constexpr uint32_t kBvhFileVersion = 2;

// What a file holds besides the tree: enough to trace it against its scene, to optimize
// it further without the scene, and to refuse the wrong scene.
struct BvhFileInfo {
  CostModel cost;                    // the constants the tree was built or optimized with
  std::string scene_name;            // the scene spec or file name it was built from
  uint64_t scene_triangles = 0;      // triangle count of that scene
  std::string method;                // e.g. "sweep", "sweep+anneal"
  // geometry_fingerprint() of the scene as built (after --rotate); 0 when unknown (a
  // version-1 file, or a writer that did not set it).
  uint64_t geometry_fingerprint = 0;
};

// What a file says about its scene, for a tree about to be built over `mesh`.
BvhFileInfo scene_info(const Mesh& mesh, const CostModel& cost, const std::string& method);

// Throws Error naming `file`, both scene names and what differs unless the tree of `info`
// was built over `mesh`: the same triangle count and, when the file has one, the same
// geometry fingerprint (another scene of the same size, another --rotate or another
// built-in seed all differ there). A file without a fingerprint (version 1) must also
// name the same scene. Every place where a stored tree meets a scene calls this.
void check_tree_matches_scene(const std::string& file, const BvhFileInfo& info, const Mesh& mesh);

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

// True when the file starts with the BVH file's magic bytes (so a tree passed where a scene
// is expected gets a clear error, not assimp's Biovision motion-capture reader).
bool has_bvh_file_magic(const std::filesystem::path& path);

// bvh_file_checksum (for tools that patch a file) is in bvhopt/testing/bvh_file_checksum.h.

}  // namespace bvhopt
