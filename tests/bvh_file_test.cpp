#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/scene.h"
#include "bvhopt/testing/bvh_file_checksum.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

// Offsets of the header fields (docs/file-format.md).
constexpr size_t kVersionAt = 8, kHeaderSizeAt = 12, kFlagsAt = 16, kRootAt = 20, kNodeCountAt = 24,
                 kRefCountAt = 32, kSlotCountAt = 40, kSceneTrianglesAt = 64, kNameLenAt = 76, kFixedHeader = 80;

class BvhFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("bvhopt_file_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
};

std::vector<unsigned char> file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void spit(const fs::path& p, const std::vector<unsigned char>& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}
// The tests run on little-endian hosts, like the format.
template <class T>
void patch(std::vector<unsigned char>& bytes, size_t at, T v) {
  std::memcpy(bytes.data() + at, &v, sizeof v);
}
template <class T>
T peek(const std::vector<unsigned char>& bytes, size_t at) {
  T v;
  std::memcpy(&v, bytes.data() + at, sizeof v);
  return v;
}
// Recomputes the trailing checksum, as a careful forger would.
void reseal(std::vector<unsigned char>& bytes) {
  patch<uint64_t>(bytes, bytes.size() - 8, bvh_file_checksum(bytes.data(), bytes.size() - 8));
}

// Runs the reader and returns its message ("" if it did not throw).
std::string bvh_read_error(const fs::path& p) {
  try {
    read_bvh_file(p);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

struct Sample {
  PrimitiveRefs refs;
  Bvh bvh;
  BvhFileInfo info;
};

Sample sample(uint32_t triangles, uint64_t seed, BuilderKind kind = BuilderKind::object_median, uint32_t leaf = 1) {
  Sample s;
  s.refs = make_references(testing::random_mesh(triangles, seed, true));
  BuildOptions o;
  o.kind = kind;
  o.leaf.max_leaf_size = leaf;
  s.bvh = build_bvh(s.refs, o);
  s.info.cost = CostModel{3.5, 1.25};
  s.info.scene_name = "random(" + std::to_string(seed) + ") \xc3\xa9t\xc3\xa9";  // UTF-8 passes through
  s.info.scene_triangles = triangles;
  s.info.method = std::string(builder_name(kind)) + "+test";
  return s;
}

TEST_F(BvhFileTest, RoundTripForEveryBuilder) {
  for (BuilderKind kind : all_builders())
    for (uint32_t leaf : {1u, 4u})
      for (uint64_t seed : {1u, 2u}) {
        Sample s = sample(300 + 211 * static_cast<uint32_t>(seed), seed, kind, leaf);
        fs::path p = dir_ / "tree.bvh";
        write_bvh_file(p, s.bvh, s.refs, s.info);
        BvhFile f = read_bvh_file(p);
        Bvh want = s.bvh;
        want.renumber_depth_first();  // the file stores the depth-first numbering
        EXPECT_TRUE(testing::same_nodes(f.bvh, want));
        ASSERT_EQ(f.refs.size(), s.refs.size());
        for (size_t r = 0; r < s.refs.size(); ++r) {
          ASSERT_EQ(std::memcmp(&f.refs.boxes[r], &s.refs.boxes[r], sizeof(Box)), 0);
          ASSERT_EQ(f.refs.triangle_ids[r], s.refs.triangle_ids[r]);
          ASSERT_EQ(f.refs.centroids[r], s.refs.centroids[r]);
        }
        EXPECT_EQ(f.info.cost.traversal, 3.5);
        EXPECT_EQ(f.info.cost.intersection, 1.25);
        EXPECT_EQ(f.info.scene_name, s.info.scene_name);
        EXPECT_EQ(f.info.scene_triangles, s.info.scene_triangles);
        EXPECT_EQ(f.info.method, s.info.method);
        // Writing what was read gives the same bytes.
        fs::path q = dir_ / "again.bvh";
        write_bvh_file(q, f.bvh, f.refs, f.info);
        EXPECT_EQ(file_bytes(p), file_bytes(q));
      }
}

TEST_F(BvhFileTest, RoundTripOfATreeWithUnreachableNodesAndScatteredSlots) {
  Sample s = sample(200, 9);
  // Reverse the slot order and fix the leaves up: not the depth-first layout any more.
  const uint32_t n = static_cast<uint32_t>(s.bvh.ref_indices.size());
  std::vector<uint32_t> rev(n);
  for (uint32_t i = 0; i < s.bvh.nodes.size(); ++i)
    if (s.bvh[i].is_leaf()) {
      uint32_t slot = s.bvh[i].first_ref();
      rev[n - 1 - slot] = s.bvh.ref_indices[slot];
      s.bvh[i].make_leaf(n - 1 - slot, 1);
    }
  s.bvh.ref_indices = rev;
  s.bvh.nodes.push_back(BvhNode{});  // unreachable garbage
  fs::path p = dir_ / "t.bvh";
  write_bvh_file(p, s.bvh, s.refs, s.info);
  BvhFile f = read_bvh_file(p);
  Bvh want = s.bvh;
  want.renumber_depth_first();
  EXPECT_TRUE(testing::same_nodes(f.bvh, want));
  EXPECT_EQ(testing::tree_signature(f.bvh, f.refs), testing::tree_signature(s.bvh, s.refs));
}

TEST_F(BvhFileTest, RoundTripOnTheBuiltInScene) {
  Mesh mesh = make_builtin_scene({.seed = 4, .target_triangles = 30000});
  PrimitiveRefs refs = make_references(mesh);
  for (BuilderKind kind : all_builders()) {
    BuildOptions o;
    o.kind = kind;
    Bvh bvh = build_bvh(refs, o);
    BvhFileInfo info;
    info.scene_name = "builtin:atrium?triangles=30000&seed=4";
    info.scene_triangles = mesh.triangle_count();
    info.method = std::string(builder_name(kind));
    fs::path p = dir_ / "builtin.bvh";
    write_bvh_file(p, bvh, refs, info);
    BvhFile f = read_bvh_file(p);
    bvh.renumber_depth_first();
    EXPECT_TRUE(testing::same_nodes(f.bvh, bvh));
    EXPECT_EQ(testing::tree_signature(f.bvh, f.refs), testing::tree_signature(bvh, refs));
    EXPECT_EQ(f.info.scene_triangles, mesh.triangle_count());
  }
}

TEST_F(BvhFileTest, EmptyTreeRoundTrip) {
  fs::path p = dir_ / "empty.bvh";
  write_bvh_file(p, Bvh{}, PrimitiveRefs{}, BvhFileInfo{});
  BvhFile f = read_bvh_file(p);
  EXPECT_TRUE(f.bvh.empty());
  EXPECT_TRUE(f.bvh.nodes.empty());
  EXPECT_TRUE(f.refs.empty());
}

class Rejections : public BvhFileTest {
 protected:
  void SetUp() override {
    BvhFileTest::SetUp();
    s_ = sample(40, 5, BuilderKind::spatial_median, 2);
    good_ = dir_ / "good.bvh";
    bad_ = dir_ / "bad.bvh";
    write_bvh_file(good_, s_.bvh, s_.refs, s_.info);
    bytes_ = file_bytes(good_);
    ASSERT_EQ(bvh_read_error(good_), "");
  }
  // Writes the damaged bytes and returns the reader's message, which must name the file.
  std::string damaged(const std::vector<unsigned char>& b) {
    spit(bad_, b);
    std::string e = bvh_read_error(bad_);
    EXPECT_NE(e, "") << "accepted a damaged file";
    EXPECT_NE(e.find(bad_.string()), std::string::npos) << e;
    return e;
  }
  size_t header_size() const { return peek<uint32_t>(bytes_, kHeaderSizeAt); }

  Sample s_;
  fs::path good_, bad_;
  std::vector<unsigned char> bytes_;
};

TEST_F(Rejections, MissingFileAndDirectory) {
  std::string e = bvh_read_error(dir_ / "nope.bvh");
  EXPECT_NE(e.find("nope.bvh: cannot open"), std::string::npos) << e;
  EXPECT_NE(bvh_read_error(dir_), "");
}

TEST_F(Rejections, WrongMagic) {
  auto b = bytes_;
  b[1] = 'X';
  EXPECT_NE(damaged(b).find("not a bvhopt BVH file"), std::string::npos);
  // A text-mode conversion of CR LF to LF.
  b = bytes_;
  b.erase(b.begin() + 4);
  EXPECT_NE(damaged(b).find("not a bvhopt BVH file"), std::string::npos);
  // Something else altogether.
  std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  EXPECT_NE(damaged(std::vector<unsigned char>(obj.begin(), obj.end())).find("not a bvhopt BVH file"),
            std::string::npos);
}

TEST_F(Rejections, NewerVersion) {
  auto b = bytes_;
  patch<uint32_t>(b, kVersionAt, 3);
  EXPECT_NE(damaged(b).find("written by a newer bvhopt: version 3, this reads up to 2"), std::string::npos);
  reseal(b);
  EXPECT_NE(damaged(b).find("version 3, this reads up to 2"), std::string::npos);
  patch<uint32_t>(b, kVersionAt, 0);
  EXPECT_NE(damaged(b).find("version 0"), std::string::npos);
}

TEST_F(Rejections, TruncatedAtManyOffsets) {
  const size_t hs = header_size();
  const size_t nodes_end = hs + 32 * peek<uint64_t>(bytes_, kNodeCountAt);
  std::vector<size_t> cuts = {1, 5, 8, 12, 30, kFixedHeader - 1, kFixedHeader, kFixedHeader + 3, hs - 1, hs,
                              hs + 17, nodes_end, nodes_end + 2, bytes_.size() - 9, bytes_.size() - 8,
                              bytes_.size() - 1};
  for (size_t cut : cuts) {
    std::vector<unsigned char> b(bytes_.begin(), bytes_.begin() + static_cast<long>(cut));
    std::string e = damaged(b);
    EXPECT_NE(e.find("truncated: expected "), std::string::npos) << "cut at " << cut << ": " << e;
    EXPECT_NE(e.find("file has " + std::to_string(cut)), std::string::npos) << "cut at " << cut << ": " << e;
  }
  EXPECT_NE(damaged({}).find("empty file"), std::string::npos);
}

TEST_F(Rejections, TrailingData) {
  auto b = bytes_;
  b.push_back(0);
  EXPECT_NE(damaged(b).find("trailing data"), std::string::npos);
}

// Any single flipped byte is caught; past the fields that are checked before the
// checksum (magic, version, sizes, counts), it is caught as a checksum mismatch.
TEST_F(Rejections, EveryFlippedByteIsCaught) {
  // Patched in place rather than rewritten: ext4 flushes a file truncated over old data,
  // which made thousands of rewrites take seconds.
  spit(bad_, bytes_);
  std::fstream io(bad_, std::ios::binary | std::ios::in | std::ios::out);
  auto put = [&](size_t at, unsigned char v) {
    io.seekp(static_cast<std::streamoff>(at));
    io.put(static_cast<char>(v));
    io.flush();
  };
  for (size_t at = 0; at < bytes_.size(); ++at) {
    for (unsigned char mask : {0x01, 0x80}) {
      put(at, bytes_[at] ^ mask);
      std::string e = bvh_read_error(bad_);
      ASSERT_NE(e, "") << "accepted a flip of byte " << at;
      EXPECT_NE(e.find(bad_.string()), std::string::npos) << e;
      const size_t name_end = kFixedHeader + s_.info.scene_name.size();
      const bool checked_early = at < kVersionAt + 8 || (at >= kNodeCountAt && at < kNodeCountAt + 24) ||
                                 (at >= kNameLenAt && at < kNameLenAt + 4) || (at >= name_end && at < name_end + 4);
      if (!checked_early) {
        EXPECT_NE(e.find("corrupt: checksum mismatch"), std::string::npos) << "byte " << at << ": " << e;
      }
    }
    put(at, bytes_[at]);
  }
  EXPECT_EQ(bvh_read_error(bad_), "");
}

// A later minor addition at the end of the header (covered by header_size) is skipped.
TEST_F(Rejections, UnknownHeaderBytesAreSkipped) {
  const size_t hs = header_size();
  auto b = bytes_;
  b.insert(b.begin() + static_cast<long>(hs), {1, 2, 3, 4, 5});
  patch<uint32_t>(b, kHeaderSizeAt, static_cast<uint32_t>(hs + 5));
  reseal(b);
  spit(bad_, b);
  BvhFile f = read_bvh_file(bad_);
  EXPECT_EQ(f.bvh.nodes.size(), s_.bvh.nodes.size());
  EXPECT_EQ(f.info.method, s_.info.method);
}

TEST_F(Rejections, BogusCountsWithARecomputedChecksum) {
  // Huge: beyond what 32-bit indices can address.
  auto b = bytes_;
  patch<uint64_t>(b, kNodeCountAt, uint64_t(1) << 40);
  reseal(b);
  EXPECT_NE(damaged(b).find("counts out of range"), std::string::npos);
  // Large but addressable: must be refused from the file size, before any allocation.
  b = bytes_;
  patch<uint64_t>(b, kRefCountAt, 0xfffffff0ull);
  reseal(b);
  std::string e = damaged(b);
  EXPECT_NE(e.find("truncated: expected"), std::string::npos) << e;
  EXPECT_NE(e.find("4294967280 references"), std::string::npos) << e;
  // One node fewer and four more slots: the same size, the wrong layout.
  b = bytes_;
  patch<uint64_t>(b, kNodeCountAt, peek<uint64_t>(b, kNodeCountAt) - 1);
  patch<uint64_t>(b, kSlotCountAt, peek<uint64_t>(b, kSlotCountAt) + 8);
  reseal(b);
  EXPECT_NE(damaged(b), "");
  // A scene name longer than the file.
  b = bytes_;
  patch<uint32_t>(b, kNameLenAt, 0x7fffffff);
  reseal(b);
  EXPECT_NE(damaged(b).find("truncated"), std::string::npos);
  // A header size smaller than the header.
  b = bytes_;
  patch<uint32_t>(b, kHeaderSizeAt, 20);
  reseal(b);
  EXPECT_NE(damaged(b).find("header size 20"), std::string::npos);
}

TEST_F(Rejections, BadFieldsWithARecomputedChecksum) {
  const size_t hs = header_size();
  auto b = bytes_;
  patch<uint32_t>(b, kFlagsAt, 4);
  reseal(b);
  EXPECT_NE(damaged(b).find("unsupported flags"), std::string::npos);

  b = bytes_;
  patch<uint32_t>(b, kRootAt, 5);
  reseal(b);
  EXPECT_NE(damaged(b).find("root 5"), std::string::npos);

  // Node 0 is the root, an inner node: its right child index points past the end.
  b = bytes_;
  ASSERT_EQ(peek<uint32_t>(b, hs + 28) & 0x80000000u, 0u);
  patch<uint32_t>(b, hs + 28, 100000);
  reseal(b);
  EXPECT_NE(damaged(b).find("node 0: right child 100000 out of range"), std::string::npos);

  // A child that points backwards would make a cycle.
  b = bytes_;
  ASSERT_EQ(peek<uint32_t>(b, hs + 32 + 28) & 0x80000000u, 0u) << "node 1 should be an inner node";
  patch<uint32_t>(b, hs + 32 + 24, 0);  // node 1's left child
  reseal(b);
  EXPECT_NE(damaged(b).find("node 1: left child 0 does not follow its parent"), std::string::npos);

  // A leaf whose slot range runs off the end.
  const uint64_t nodes = peek<uint64_t>(b, kNodeCountAt);
  b = bytes_;
  size_t leaf_at = 0;
  for (uint64_t i = 0; i < nodes && !leaf_at; ++i)
    if (peek<uint32_t>(b, hs + 32 * i + 28) & 0x80000000u) leaf_at = hs + 32 * i;
  ASSERT_NE(leaf_at, 0u);
  patch<uint32_t>(b, leaf_at + 24, 1u << 30);
  reseal(b);
  EXPECT_NE(damaged(b).find("out of range"), std::string::npos);

  // A reference id out of range in the slot section.
  const size_t slots_at = hs + 32 * nodes;
  b = bytes_;
  patch<uint32_t>(b, slots_at + 4, 77777);
  reseal(b);
  EXPECT_NE(damaged(b).find("holds reference 77777, out of range"), std::string::npos);

  // Two slots holding the same reference: caught by validation, reported with node names.
  b = bytes_;
  patch<uint32_t>(b, slots_at + 4, peek<uint32_t>(b, slots_at));
  reseal(b);
  std::string e = damaged(b);
  EXPECT_NE(e.find("invalid tree: "), std::string::npos) << e;
  EXPECT_NE(e.find("is also in leaf node"), std::string::npos) << e;

  // A shrunk box: the stored tree is not a valid BVH.
  b = bytes_;
  patch<float>(b, hs + 12, peek<float>(b, hs + 12) - 1.0f);  // root max.x
  reseal(b);
  EXPECT_NE(damaged(b).find("node 0: box is not the union"), std::string::npos);

  // A triangle id beyond the scene's triangle count.
  const size_t refs_at = slots_at + 4 * peek<uint64_t>(b, kSlotCountAt);
  b = bytes_;
  patch<uint32_t>(b, refs_at + 24, 40);
  reseal(b);
  EXPECT_NE(damaged(b).find("triangle id 40 out of range (the scene has 40 triangles)"), std::string::npos);
  (void)kSceneTrianglesAt;
}

// Content a valid checksum can cover but no writer produces: cost constants that are not
// finite non-negative numbers, an inverted reference box, a node no path from the root reaches.
TEST_F(Rejections, CorruptContentBehindAValidChecksum) {
  const size_t hs = header_size();
  constexpr size_t kTraversalAt = 48, kIntersectionAt = 56;
  for (double bad : {std::nan(""), double(INFINITY), -2.0}) {
    for (size_t at : {kTraversalAt, kIntersectionAt}) {
      auto b = bytes_;
      patch<double>(b, at, bad);
      reseal(b);
      std::string e = damaged(b);
      EXPECT_NE(e.find("cost constant"), std::string::npos) << e;
    }
  }

  // Reference 0's box with min and max x swapped (the reference has an extent in x).
  const uint64_t nodes = peek<uint64_t>(bytes_, kNodeCountAt);
  const size_t refs_at = hs + 32 * nodes + 4 * peek<uint64_t>(bytes_, kSlotCountAt);
  auto b = bytes_;
  size_t ref_at = refs_at;
  while (peek<float>(b, ref_at) == peek<float>(b, ref_at + 12)) ref_at += 28;
  const float lo = peek<float>(b, ref_at), hi = peek<float>(b, ref_at + 12);
  patch<float>(b, ref_at, hi);
  patch<float>(b, ref_at + 12, lo);
  reseal(b);
  std::string e = damaged(b);
  EXPECT_NE(e.find("inverted"), std::string::npos) << e;

  // One more node record after the last, a leaf over slot 0: nothing points to it.
  b = bytes_;
  std::vector<unsigned char> extra(32, 0);
  std::memcpy(extra.data(), b.data() + hs, 24);  // the root's box
  uint32_t leaf[2] = {0, 1u | 0x80000000u};
  std::memcpy(extra.data() + 24, leaf, 8);
  b.insert(b.begin() + std::ptrdiff_t(hs + 32 * nodes), extra.begin(), extra.end());
  patch<uint64_t>(b, kNodeCountAt, nodes + 1);
  reseal(b);
  e = damaged(b);
  EXPECT_NE(e.find("node " + std::to_string(nodes) + ": unreachable"), std::string::npos) << e;
}

// A forger who recomputes the checksum: random words anywhere in the file replaced by
// interesting or random values. The reader must accept or throw Error, never crash or
// allocate wildly (the sanitizer build checks the memory side).
TEST_F(Rejections, RandomResealedDamageNeverCrashes) {
  spit(bad_, bytes_);
  std::fstream io(bad_, std::ios::binary | std::ios::in | std::ios::out);
  std::mt19937_64 rng(2024);
  int rejected = 0;
  const int trials = 1500;
  for (int trial = 0; trial < trials; ++trial) {
    auto b = bytes_;
    const int words = 1 + static_cast<int>(rng() % 3);
    for (int w = 0; w < words; ++w) {
      size_t at = (rng() % ((b.size() - 8) / 4)) * 4;
      const uint32_t values[] = {0u, 1u, 0x80000000u, 0x80000001u, 0xffffffffu, 0x7fffffffu,
                                 static_cast<uint32_t>(rng() % 64), static_cast<uint32_t>(rng())};
      patch<uint32_t>(b, at, values[rng() % 8]);
    }
    reseal(b);
    io.seekp(0);
    io.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
    io.flush();
    try {
      BvhFile f = read_bvh_file(bad_);
      // Whatever was accepted is a valid tree.
      EXPECT_TRUE(validate(f.bvh, f.refs).ok());
    } catch (const Error& e) {
      ++rejected;
      EXPECT_NE(std::string(e.what()).find(bad_.string()), std::string::npos) << e.what();
    }
  }
  // Most damage must be caught (some, like a changed cost constant, is harmless).
  EXPECT_GT(rejected, trials / 2);
}

TEST_F(BvhFileTest, FailedWriteIntoMissingDirectoryLeavesNothing) {
  Sample s = sample(30, 1);
  fs::path missing = dir_ / "no" / "such" / "dir";
  fs::path p = missing / "t.bvh";
  EXPECT_THROW(write_bvh_file(p, s.bvh, s.refs, s.info), Error);
  EXPECT_FALSE(fs::exists(missing));
  EXPECT_TRUE(fs::is_empty(dir_));
}

TEST_F(BvhFileTest, FailedWriteLeavesTheOldFileIntact) {
  Sample old = sample(30, 1);
  fs::path p = dir_ / "t.bvh";
  write_bvh_file(p, old.bvh, old.refs, old.info);
  const auto before = file_bytes(p);

  // A tree the reader would refuse is refused before anything is written. (A write that
  // fails half way is tested on write_atomically itself, in atomic_file_test.)
  Sample next = sample(60, 2);
  Bvh broken = next.bvh;
  broken.nodes[broken.root].box = Box({0, 0, 0}, {1e-3f, 1e-3f, 1e-3f});
  try {
    write_bvh_file(p, broken, next.refs, next.info);
    ADD_FAILURE() << "an invalid tree was written";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
  }
  EXPECT_EQ(file_bytes(p), before);

  // The target is a directory: the rename fails after a complete write; the temporary
  // must be gone afterwards.
  fs::path d = dir_ / "adir";
  fs::create_directory(d);
  fs::create_directory(d / "keep");
  EXPECT_THROW(write_bvh_file(d, next.bvh, next.refs, next.info), Error);
  EXPECT_TRUE(fs::is_directory(d / "keep"));
  for (const auto& entry : fs::directory_iterator(dir_))
    EXPECT_EQ(entry.path().filename().string().find(".tmp-"), std::string::npos) << entry.path();

  // Afterwards a normal write replaces the file.
  write_bvh_file(p, next.bvh, next.refs, next.info);
  EXPECT_NE(file_bytes(p), before);
  EXPECT_EQ(read_bvh_file(p).refs.size(), 60u);
}

TEST_F(BvhFileTest, RefusesToWriteAnInvalidTree) {
  Sample s = sample(30, 3);
  s.bvh.ref_indices[0] = s.bvh.ref_indices[1];
  fs::path p = dir_ / "t.bvh";
  try {
    write_bvh_file(p, s.bvh, s.refs, s.info);
    ADD_FAILURE() << "wrote an invalid tree";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("invalid tree"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_empty(dir_));
}

TEST(BvhFileChecksum, SensitiveToEveryByteAndLength) {
  std::vector<unsigned char> data(257);
  for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<unsigned char>(i * 37);
  const uint64_t base = bvh_file_checksum(data.data(), data.size());
  for (size_t i = 0; i < data.size(); ++i) {
    data[i] ^= 0x10;
    EXPECT_NE(bvh_file_checksum(data.data(), data.size()), base) << i;
    data[i] ^= 0x10;
  }
  // Zero padding of the last word must not make lengths collide.
  std::vector<unsigned char> zeros(16, 0);
  EXPECT_NE(bvh_file_checksum(zeros.data(), 15), bvh_file_checksum(zeros.data(), 16));
  EXPECT_NE(bvh_file_checksum(zeros.data(), 0), bvh_file_checksum(zeros.data(), 1));
}

}  // namespace
}  // namespace bvhopt
