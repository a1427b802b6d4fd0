// The binary ray file (docs/ray-file-format.md), part of bvhopt::io.
#pragma once

#include <cstdint>
#include <filesystem>

#include "bvhopt/ray_sets.h"

namespace bvhopt {

// write_ray_file writes a temporary file beside
// `path` and renames it into place; on failure the temporary is removed and Error thrown.
void write_ray_file(const std::filesystem::path& path, const RaySet& set);
// Throws Error naming the file and the problem: missing, too short, wrong magic, newer
// version, unknown kind or query, truncated or trailing bytes, checksum mismatch, or a
// ray that cannot be traced (non-finite numbers, zero direction, tmin > tmax).
RaySet read_ray_file(const std::filesystem::path& path);

inline constexpr uint32_t kRayFileVersion = 1;

}  // namespace bvhopt
