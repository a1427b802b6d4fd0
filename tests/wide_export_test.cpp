// The compressed 8-wide BVH (CWBVH) and the export files: quantized boxes contain the real
// ones on every node, the structure references every triangle through valid meta bytes, and
// the files carry the documented header, checksum and sections.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <bit>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <unistd.h>

#include "bvhopt/build.h"
#include "bvhopt/compressed_wide_bvh.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/references.h"
#include "bvhopt/wide_export_file.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

struct Case {
  std::string name;
  Mesh mesh;
  FlatBvh flat;
};

FlatBvh build_flat(const PrimitiveRefs& refs, uint32_t leaf) {
  BuildOptions o;
  o.leaf.max_leaf_size = leaf;
  // The median builder makes a leaf of every node that fits: leaves larger than CWBVH's 3.
  if (leaf > 4) o.kind = BuilderKind::object_median;
  return finalize(build_bvh(refs, o), refs);
}

std::vector<Case> cases() {
  std::vector<Case> out;
  for (uint64_t seed : {1u, 2u}) {
    Mesh mesh = testing::random_mesh(1500, seed, /*with_degenerate=*/true);
    const PrimitiveRefs refs = make_references(mesh);
    for (uint32_t leaf : {1u, 4u, 16u})
      out.push_back({"seed " + std::to_string(seed) + " leaf " + std::to_string(leaf), mesh, build_flat(refs, leaf)});
    EdgeVolumeConfig evh;
    evh.t = 16;
    const PrimitiveRefs split = subdivide_edge_volume(mesh, evh).refs;
    EXPECT_GT(split.size(), refs.size());
    out.push_back({"seed " + std::to_string(seed) + " evh leaf 8", mesh, build_flat(split, 8)});
  }
  return out;
}

Box triangle_box(const Mesh& mesh, uint32_t id) { return mesh.triangle(id).bounds(); }

// The box of every triangle under a child, from the exported structure alone.
Box subtree_box(const CompressedWideBvh& c, const Mesh& mesh, uint32_t node) {
  Box b;
  const CwbvhNode& n = c.nodes[node];
  uint32_t inner = 0;
  for (uint32_t s = 0; s < 8; ++s) {
    if (n.meta[s] == 0) continue;
    if (n.inner_mask & (1u << s)) {
      b.extend(subtree_box(c, mesh, n.child_base + inner++));
    } else {
      for (uint32_t i = 0; i < uint32_t(std::popcount(uint32_t(n.meta[s] >> 5))); ++i)
        b.extend(triangle_box(mesh, c.triangles[n.triangle_base + (n.meta[s] & 31u) + i].id));
    }
  }
  return b;
}

TEST(Cwbvh, QuantizedBoxesContainTheRealChildBoxesOnEveryNode) {
  for (const Case& k : cases()) {
    const CompressedWideBvh c = build_compressed_wide_bvh(k.flat, k.mesh);
    ASSERT_EQ(c.exact_child_boxes.size(), 8 * c.nodes.size()) << k.name;
    size_t checked = 0, tight = 0;
    for (size_t i = 0; i < c.nodes.size(); ++i) {
      const CwbvhNode& n = c.nodes[i];
      for (uint32_t s = 0; s < 8; ++s) {
        const Box exact = c.exact_child_boxes[8 * i + s];
        const Box q = cwbvh_child_box(n, s);
        if (n.meta[s] == 0) {
          EXPECT_TRUE(exact.is_empty() && q.is_empty()) << k.name << " node " << i << " slot " << s;
          continue;
        }
        ++checked;
        for (int a = 0; a < 3; ++a) {
          ASSERT_LE(q.min[a], exact.min[a]) << k.name << " node " << i << " slot " << s << " axis " << a;
          ASSERT_GE(q.max[a], exact.max[a]) << k.name << " node " << i << " slot " << s << " axis " << a;
          // Rounded outward by less than two steps of the node's scale (a quantizer that gave
          // every child the whole node box would also be conservative, and useless).
          const float step = std::bit_cast<float>(uint32_t(n.exponent[a]) << 23);
          EXPECT_LE(exact.min[a] - q.min[a], 2.0f * step) << k.name;
          EXPECT_LE(q.max[a] - exact.max[a], 2.0f * step) << k.name;
        }
        tight += q == exact ? 0 : 1;
      }
    }
    EXPECT_GT(checked, c.nodes.size()) << k.name;
    EXPECT_GT(tight, 0u) << k.name;
  }
}

TEST(Cwbvh, QuantizedBoxesContainTheTrianglesBelowThem) {
  for (const Case& k : cases()) {
    if (k.name.find("evh") != std::string::npos) continue;  // clipped boxes bound pieces only
    const CompressedWideBvh c = build_compressed_wide_bvh(k.flat, k.mesh);
    for (size_t i = 0; i < c.nodes.size(); ++i) {
      const CwbvhNode& n = c.nodes[i];
      uint32_t inner = 0;
      for (uint32_t s = 0; s < 8; ++s) {
        if (n.meta[s] == 0) continue;
        Box below;
        if (n.inner_mask & (1u << s)) {
          below = subtree_box(c, k.mesh, n.child_base + inner++);
        } else {
          for (uint32_t t = 0; t < uint32_t(std::popcount(uint32_t(n.meta[s] >> 5))); ++t)
            below.extend(triangle_box(k.mesh, c.triangles[n.triangle_base + (n.meta[s] & 31u) + t].id));
        }
        ASSERT_TRUE(cwbvh_child_box(n, s).contains(below)) << k.name << " node " << i << " slot " << s;
      }
    }
  }
}

TEST(Cwbvh, MetaBytesFormATreeOverEveryTriangle) {
  for (const Case& k : cases()) {
    const CompressedWideBvh c = build_compressed_wide_bvh(k.flat, k.mesh);
    std::vector<int> node_refs(c.nodes.size(), 0), triangle_refs(c.triangles.size(), 0);
    std::vector<uint8_t> seen(k.mesh.triangle_count(), 0);
    for (size_t i = 0; i < c.nodes.size(); ++i) {
      const CwbvhNode& n = c.nodes[i];
      uint32_t inner = 0;
      bool empty_seen = false;
      for (uint32_t s = 0; s < 8; ++s) {
        const uint32_t m = n.meta[s];
        if (m == 0) {
          empty_seen = true;
          EXPECT_EQ(n.inner_mask & (1u << s), 0u);
          continue;
        }
        EXPECT_FALSE(empty_seen) << "slots fill from 0";
        if (n.inner_mask & (1u << s)) {
          EXPECT_EQ(m, 0x20u | (24u + s)) << k.name;
          const uint32_t child = n.child_base + inner++;
          ASSERT_LT(child, c.nodes.size());
          EXPECT_GT(child, i) << "children after their parent";
          ++node_refs[child];
        } else {
          const uint32_t unary = m >> 5, count = uint32_t(std::popcount(unary));
          ASSERT_TRUE(unary == 1 || unary == 3 || unary == 7) << k.name << " meta " << m;
          ASSERT_LE((m & 31u) + count, 24u);
          for (uint32_t t = 0; t < count; ++t) {
            const size_t at = n.triangle_base + (m & 31u) + t;
            ASSERT_LT(at, c.triangles.size());
            ++triangle_refs[at];
            const CwbvhTriangle& tri = c.triangles[at];
            ASSERT_LT(tri.id, k.mesh.triangle_count());
            seen[tri.id] = 1;
            const Triangle want = k.mesh.triangle(tri.id);
            EXPECT_EQ(Vec3(tri.v0[0], tri.v0[1], tri.v0[2]), want.v0);
            EXPECT_EQ(Vec3(tri.v2[0], tri.v2[1], tri.v2[2]), want.v2);
          }
        }
      }
    }
    EXPECT_EQ(node_refs[0], 0);
    for (size_t i = 1; i < node_refs.size(); ++i) ASSERT_EQ(node_refs[i], 1) << k.name << " node " << i;
    for (size_t i = 0; i < triangle_refs.size(); ++i) ASSERT_EQ(triangle_refs[i], 1) << k.name << " triangle " << i;
    for (size_t t = 0; t < seen.size(); ++t) ASSERT_TRUE(seen[t]) << k.name << " triangle " << t << " missing";
    EXPECT_GT(c.stack_entries, 1u);
  }
}

// The layout is written in parallel from offsets computed beforehand: every byte (gaps
// included, since export files hold the arena as it is) must not depend on the threads.
TEST(WideLayout, SameBytesOnAnyThreadCount) {
  for (const Case& k : cases()) {
    for (uint32_t width : {4u, 8u}) {
      WideLayoutOptions o;
      o.collapse.width = width;
      std::unique_ptr<WideBvh> one, many;
      {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
        one = std::make_unique<WideBvh>(k.flat, k.mesh, o);
      }
      tbb::task_arena(8).execute([&] { many = std::make_unique<WideBvh>(k.flat, k.mesh, o); });
      ASSERT_EQ(one->stats().bytes, many->stats().bytes) << k.name;
      EXPECT_EQ(one->stats().bytes % 64, 0u);
      EXPECT_EQ(std::memcmp(one->data(), many->data(), one->stats().bytes), 0) << k.name << " width " << width;
      EXPECT_EQ(one->root(), 0u);
      EXPECT_EQ(one->stack_entries(), many->stack_entries());
    }
  }
}


uint64_t fnv1a(uint64_t h, const char* p, size_t n) {
  for (size_t i = 0; i < n; ++i) h = (h ^ uint8_t(p[i])) * 0x100000001B3ull;
  return h;
}

class ExportFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("bvhopt_export_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

WideExportHeader header_of(const std::string& bytes) {
  WideExportHeader h{};
  EXPECT_GE(bytes.size(), sizeof h);
  std::memcpy(&h, bytes.data(), sizeof h);
  EXPECT_EQ(std::string(h.magic, 8), "BVHOWIDE");
  EXPECT_EQ(h.version, 1u);
  EXPECT_EQ(std::string(bytes.data() + 12, 4), std::string("\x04\x03\x02\x01", 4));
  EXPECT_EQ(h.section0_offset % 64, 0u);
  EXPECT_EQ(h.section1_offset % 64, 0u);
  uint64_t sum = fnv1a(0xCBF29CE484222325ull, bytes.data(), 120);
  sum = fnv1a(sum, bytes.data() + h.section0_offset, h.section0_bytes);
  sum = fnv1a(sum, bytes.data() + h.section1_offset, h.section1_bytes);
  EXPECT_EQ(sum, h.checksum);
  return h;
}

TEST_F(ExportFile, FlatFileHoldsTheArenaBehindItsHeader) {
  const Case k = cases()[1];
  for (uint32_t width : {4u, 8u}) {
    WideLayoutOptions o;
    o.collapse.width = width;
    const WideBvh wide(k.flat, k.mesh, o);
    const fs::path out = dir_ / "flat.wbvh";
    write_wide_export_file(out, wide, k.flat.nodes[0].box);
    const std::string bytes = testing::read_text(out);
    const WideExportHeader h = header_of(bytes);
    EXPECT_EQ(h.format, 1u);
    EXPECT_EQ(h.width, width);
    EXPECT_EQ(h.triangles, 0u);
    EXPECT_EQ(h.root, wide.root());
    EXPECT_EQ(h.scene_triangles, k.mesh.triangle_count());
    EXPECT_EQ(h.nodes, wide.stats().nodes);
    EXPECT_EQ(h.leaf_items, wide.stats().blocks);
    EXPECT_EQ(h.stack_entries, wide.stack_entries());
    EXPECT_EQ(h.section0_offset, 128u);
    EXPECT_EQ(h.section1_bytes, 0u);
    ASSERT_EQ(bytes.size(), 128 + wide.stats().bytes);
    EXPECT_EQ(std::memcmp(bytes.data() + 128, wide.data(), wide.stats().bytes), 0);
    EXPECT_EQ(h.bounds_min[0], k.flat.nodes[0].box.min.x);
    EXPECT_EQ(h.bounds_max[2], k.flat.nodes[0].box.max.z);
  }
}

TEST_F(ExportFile, CwbvhFileHoldsNodesAndTriangles) {
  const Case k = cases()[3];
  const CompressedWideBvh c = build_compressed_wide_bvh(k.flat, k.mesh);
  const fs::path out = dir_ / "c.wbvh";
  write_cwbvh_export_file(out, c, k.flat.nodes[0].box, k.mesh.triangle_count());
  const std::string bytes = testing::read_text(out);
  const WideExportHeader h = header_of(bytes);
  EXPECT_EQ(h.format, 2u);
  EXPECT_EQ(h.width, 8u);
  EXPECT_EQ(h.triangles, 1u);
  EXPECT_EQ(h.nodes, c.nodes.size());
  EXPECT_EQ(h.leaf_items, c.triangles.size());
  EXPECT_EQ(h.section0_bytes, 80 * c.nodes.size());
  EXPECT_EQ(h.section1_bytes, 48 * c.triangles.size());
  EXPECT_GE(h.section1_offset, h.section0_offset + h.section0_bytes);
  ASSERT_EQ(bytes.size(), h.section1_offset + h.section1_bytes);
  EXPECT_EQ(std::memcmp(bytes.data() + h.section0_offset, c.nodes.data(), h.section0_bytes), 0);
  EXPECT_EQ(std::memcmp(bytes.data() + h.section1_offset, c.triangles.data(), h.section1_bytes), 0);
}

TEST_F(ExportFile, FailedWriteLeavesNothing) {
  const Case k = cases()[0];
  const CompressedWideBvh c = build_compressed_wide_bvh(k.flat, k.mesh);
  const fs::path out = dir_ / "missing-folder" / "c.wbvh";
  EXPECT_THROW(write_cwbvh_export_file(out, c, k.flat.nodes[0].box, k.mesh.triangle_count()), Error);
  EXPECT_FALSE(fs::exists(out.parent_path()));
  // A folder in the way is refused and kept.
  fs::create_directories(dir_ / "taken");
  EXPECT_THROW(write_cwbvh_export_file(dir_ / "taken", c, k.flat.nodes[0].box, 1), Error);
  EXPECT_TRUE(fs::is_directory(dir_ / "taken"));
}

}  // namespace
}  // namespace bvhopt
