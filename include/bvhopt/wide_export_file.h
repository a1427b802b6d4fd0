// Wide BVH export files for renderers (`bvhopt export`, docs/wide-export-format.md): the
// 4- or 8-wide layout the wide tracer reads (format flat), or the compressed 8-wide nodes of
// GPU tracers (format cwbvh), behind one 128-byte little-endian header.
#pragma once

#include <cstdint>
#include <filesystem>

#include "bvhopt/compressed_wide_bvh.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {

inline constexpr uint32_t kWideExportVersion = 1;
inline constexpr uint32_t kWideExportByteOrder = 0x01020304u;

enum class WideExportFormat : uint32_t { flat = 1, cwbvh = 2 };
// What a triangle's rows hold: v0, v1 - v0, v2 - v0 (Moller-Trumbore), or v0, v1, v2.
enum class ExportTriangles : uint32_t { vertex_and_edges = 0, vertices = 1 };

struct WideExportHeader {
  char magic[8];           // "BVHOWIDE"
  uint32_t version;        // kWideExportVersion
  uint32_t byte_order;     // kWideExportByteOrder as written (bytes 04 03 02 01: little-endian)
  uint32_t format;         // WideExportFormat
  uint32_t width;          // 4 or 8 (cwbvh: 8)
  uint32_t triangles;      // ExportTriangles
  uint32_t root;           // flat: the root's child word; cwbvh: 0, the first node
  uint64_t scene_triangles;
  uint64_t nodes;
  uint64_t leaf_items;     // flat: 4-triangle blocks; cwbvh: triangle entries
  uint64_t section0_offset, section0_bytes;  // flat: the arena; cwbvh: the nodes
  uint64_t section1_offset, section1_bytes;  // flat: 0, 0; cwbvh: the triangles
  uint32_t stack_entries;  // enough for a traversal pushing all entered children but one per node
  uint32_t reserved;
  float bounds_min[3], bounds_max[3];  // the root's box
  uint64_t checksum;       // FNV-1a 64 over bytes 0..119, then section 0, then section 1
};
static_assert(sizeof(WideExportHeader) == 128);

// Write through write_atomically (bvhopt/atomic_file.h): a failed write leaves no file.
// `bounds` is the root's box; `scene_triangles` the mesh's triangle count.
void write_wide_export_file(const std::filesystem::path& path, const WideBvh& bvh, const Box& bounds);
void write_cwbvh_export_file(const std::filesystem::path& path, const CompressedWideBvh& bvh, const Box& bounds,
                             uint64_t scene_triangles);

}  // namespace bvhopt
