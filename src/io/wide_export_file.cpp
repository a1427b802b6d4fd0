// Wide BVH export files (docs/wide-export-format.md): a header, then one or two sections at
// 64-byte boundaries, the data exactly as laid out in memory (little-endian hosts only).
#include "bvhopt/wide_export_file.h"

#include <bit>
#include <cerrno>
#include <cstddef>
#include <cstring>
#include <fstream>
#include <string>

#include "bvhopt/atomic_file.h"
#include "bvhopt/error.h"
#include "io/fnv1a.h"

namespace bvhopt {
namespace {

static_assert(std::endian::native == std::endian::little, "wide export files are little-endian; add byte swapping");

constexpr char kMagic[8] = {'B', 'V', 'H', 'O', 'W', 'I', 'D', 'E'};
constexpr size_t kChecksumOffset = offsetof(WideExportHeader, checksum);

struct Section {
  const void* data = nullptr;
  uint64_t bytes = 0;
};

uint64_t align64(uint64_t n) { return (n + 63) / 64 * 64; }

WideExportHeader make_header(WideExportFormat format, const Box& bounds, const Section& s0, const Section& s1) {
  WideExportHeader h{};
  std::memcpy(h.magic, kMagic, 8);
  h.version = kWideExportVersion;
  h.byte_order = kWideExportByteOrder;
  h.format = uint32_t(format);
  h.section0_offset = sizeof(WideExportHeader);
  h.section0_bytes = s0.bytes;
  if (s1.bytes != 0) {
    h.section1_offset = align64(h.section0_offset + s0.bytes);
    h.section1_bytes = s1.bytes;
  }
  for (int a = 0; a < 3; ++a) {
    h.bounds_min[a] = bounds.min[a];
    h.bounds_max[a] = bounds.max[a];
  }
  return h;
}

void write_file(const std::filesystem::path& path, WideExportHeader h, const Section& s0, const Section& s1) {
  static const char zeros[64] = {};
  uint64_t c = detail::fnv1a(detail::kFnvBasis, &h, kChecksumOffset);
  c = detail::fnv1a(c, s0.data, s0.bytes);
  h.checksum = detail::fnv1a(c, s1.data, s1.bytes);
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path.string() + ": cannot create " + tmp.string() + ": " + std::strerror(errno));
    out.write(reinterpret_cast<const char*>(&h), sizeof h);
    out.write(static_cast<const char*>(s0.data), std::streamsize(s0.bytes));
    if (s1.bytes != 0) {
      out.write(zeros, std::streamsize(h.section1_offset - h.section0_offset - s0.bytes));
      out.write(static_cast<const char*>(s1.data), std::streamsize(s1.bytes));
    }
    out.close();
    if (!out) throw Error(path.string() + ": write failed (disk full or no permission?)");
  });
}

}  // namespace

void write_wide_export_file(const std::filesystem::path& path, const WideBvh& bvh, const Box& bounds) {
  const Section arena{bvh.data(), bvh.stats().bytes};
  WideExportHeader h = make_header(WideExportFormat::flat, bounds, arena, {});
  h.width = bvh.width();
  h.triangles = uint32_t(bvh.triangle_test() == TriangleTest::watertight ? ExportTriangles::vertices
                                                                           : ExportTriangles::vertex_and_edges);
  h.root = bvh.root();
  h.scene_triangles = bvh.triangle_count();
  h.nodes = bvh.stats().nodes;
  h.leaf_items = bvh.stats().blocks;
  h.stack_entries = bvh.stack_entries();
  write_file(path, h, arena, {});
}

void write_cwbvh_export_file(const std::filesystem::path& path, const CompressedWideBvh& bvh, const Box& bounds,
                             uint64_t scene_triangles) {
  const Section nodes{bvh.nodes.data(), bvh.nodes.size() * sizeof(CwbvhNode)};
  const Section triangles{bvh.triangles.data(), bvh.triangles.size() * sizeof(CwbvhTriangle)};
  WideExportHeader h = make_header(WideExportFormat::cwbvh, bounds, nodes, triangles);
  h.width = 8;
  h.triangles = uint32_t(ExportTriangles::vertices);
  h.root = 0;
  h.scene_triangles = scene_triangles;
  h.nodes = bvh.nodes.size();
  h.leaf_items = bvh.triangles.size();
  h.stack_entries = bvh.stack_entries;
  write_file(path, h, nodes, triangles);
}

}  // namespace bvhopt
