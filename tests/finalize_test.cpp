#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <cstring>
#include <numeric>

#include "bvhopt/build.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "bvhopt/scene.h"
#include "test_support.h"

namespace bvhopt {
namespace {

Box box(float x0, float y0, float z0, float x1, float y1, float z1) { return Box({x0, y0, z0}, {x1, y1, z1}); }

TEST(SeparatingAxis, LargestGapWins) {
  // Gaps: x 2, y -1 (overlap), z 0.5.
  Box a = box(0, 0, 0, 1, 1, 1);
  Box b = box(3, 0, 1.5f, 4, 1, 2);
  EXPECT_EQ(separating_axis(a, b), 0);
  EXPECT_EQ(separating_axis(b, a), 0);
  // A wider gap on z than on x.
  Box c = box(1.5f, 0, 5, 2, 1, 6);
  EXPECT_EQ(separating_axis(a, c), 2);
  EXPECT_EQ(separating_axis(c, a), 2);
  // Gap only on y, however small.
  Box d = box(-5, 1.001f, -5, 5, 2, 5);
  EXPECT_EQ(separating_axis(a, d), 1);
}

TEST(SeparatingAxis, LeastRelativeOverlapWhenNoGap) {
  // x: [0,10] and [5,15] overlap 5 of 15; y: [0,1] and [0.9,1.9] overlap 0.1 of 1.9;
  // z: identical, full overlap.
  Box a = box(0, 0, 0, 10, 1, 1);
  Box b = box(5, 0.9f, 0, 15, 1.9f, 1);
  EXPECT_EQ(separating_axis(a, b), 1);
  EXPECT_EQ(separating_axis(b, a), 1);
  // Relative, not absolute: an overlap of 2 on a 100-long union beats 0.5 on a 1-long one.
  Box c = box(0, 0, 0, 51, 1, 1);
  Box d = box(49, 0.5f, 0, 100, 1, 1);
  EXPECT_EQ(separating_axis(c, d), 0);
}

TEST(SeparatingAxis, TouchingCountsAsZeroOverlap) {
  Box a = box(0, 0, 0, 1, 1, 1);
  Box b = box(0, 1, 0, 1, 2, 1);  // touching on y, identical on x and z
  EXPECT_EQ(separating_axis(a, b), 1);
}

TEST(SeparatingAxis, FlatBoxesInOnePlane) {
  // Both flat in z = 0: z is full overlap, not zero overlap; x overlaps half, y a tenth.
  Box a = box(0, 0, 0, 2, 10, 0);
  Box b = box(1, 9, 0, 3, 19, 0);
  EXPECT_EQ(separating_axis(a, b), 1);
  // Identical boxes: all axes overlap fully, the lowest axis wins.
  EXPECT_EQ(separating_axis(a, a), 0);
}

PrimitiveRefs scene(uint32_t n, uint64_t seed) { return make_references(testing::random_mesh(n, seed)); }

// Walks the tree and the flat array together and checks every correspondence.
// Returns the number of flat nodes in the subtree at flat index `i`.
uint32_t check_subtree(const Bvh& bvh, const PrimitiveRefs& refs, const FlatBvh& flat, uint32_t n, uint32_t i,
                       bool ordered) {
  EXPECT_LT(i, flat.nodes.size());
  if (i >= flat.nodes.size()) return 0;
  const BvhNode& nd = bvh[n];
  const FlatNode& f = flat.nodes[i];
  EXPECT_EQ(f.box, nd.box) << "node " << n;
  if (nd.is_leaf()) {
    EXPECT_TRUE(f.is_leaf());
    EXPECT_EQ(f.count, nd.ref_count());
    for (uint32_t k = 0; k < nd.ref_count(); ++k)
      EXPECT_EQ(flat.triangle_ids[f.index + k], refs.triangle_ids[bvh.ref_indices[nd.first_ref() + k]]);
    return 1;
  }
  EXPECT_FALSE(f.is_leaf());
  const Box& lb = bvh[nd.left()].box;
  const Box& rb = bvh[nd.right()].box;
  uint32_t first = nd.left(), second = nd.right();
  if (ordered) {
    EXPECT_EQ(f.axis, separating_axis(lb, rb));
    // The child placed first (the next node) is the one lower on the recorded axis: by
    // centre, then by min; a full tie keeps the tree's order.
    const int ax = f.axis;
    const double cl = double(lb.min[ax]) + lb.max[ax], cr = double(rb.min[ax]) + rb.max[ax];
    if (cr < cl || (cr == cl && rb.min[ax] < lb.min[ax])) std::swap(first, second);
    const Box& a = bvh[first].box;
    const Box& b = bvh[second].box;
    EXPECT_LE(a.min[f.axis] + a.max[f.axis], b.min[f.axis] + b.max[f.axis]) << "node " << n;
  } else {
    EXPECT_LT(f.axis, 3);
  }
  // Left child = the next node; the right child's index follows the whole left subtree.
  uint32_t left_size = check_subtree(bvh, refs, flat, first, i + 1, ordered);
  EXPECT_EQ(f.index, i + 1 + left_size) << "node " << n;
  uint32_t right_size = check_subtree(bvh, refs, flat, second, f.index, ordered);
  return 1 + left_size + right_size;
}

TEST(Finalize, MatchesTheTreeForEveryBuilder) {
  for (BuilderKind kind : all_builders())
    for (uint32_t leaf : {1u, 3u})
      for (bool ordered : {false, true}) {
        PrimitiveRefs refs = scene(700, 31 + leaf);
        BuildOptions o;
        o.kind = kind;
        o.leaf.max_leaf_size = leaf;
        Bvh bvh = build_bvh(refs, o);
        FlatBvh flat = finalize(bvh, refs, FinalizeOptions{ordered});
        ASSERT_EQ(flat.nodes.size(), bvh.depth_first_order().size());
        EXPECT_EQ(check_subtree(bvh, refs, flat, bvh.root, 0, ordered), flat.nodes.size());
        // Every reference kept, once.
        std::vector<uint32_t> ids = flat.triangle_ids;
        std::sort(ids.begin(), ids.end());
        std::vector<uint32_t> expected(refs.size());
        std::iota(expected.begin(), expected.end(), 0u);
        EXPECT_EQ(ids, expected) << builder_name(kind);
      }
}

TEST(Finalize, WithoutReorderingKeepsTheTreeOrderAndRecordsTheCentreAxis) {
  // Two children apart along y by centre, more than along x.
  PrimitiveRefs refs = make_references({box(0, 5, 0, 1, 6, 1), box(0.5f, 0, 0, 3, 1, 1)});
  Bvh bvh = build_object_median(refs);
  FlatBvh flat = finalize(bvh, refs, FinalizeOptions{false});
  ASSERT_EQ(flat.nodes.size(), 3u);
  EXPECT_EQ(flat.nodes[0].axis, 1);
  EXPECT_EQ(flat.nodes[1].box, bvh[bvh[bvh.root].left()].box);
  EXPECT_EQ(flat.nodes[0].index, 2u);
}

TEST(Finalize, OrdersChildrenLowFirstOnTheSeparatingAxis) {
  // A hand-made root whose left child is the high one on z.
  PrimitiveRefs refs = make_references({box(0, 0, 10, 1, 1, 11), box(0, 0, 0, 1, 1, 1)});
  Bvh bvh;
  bvh.nodes.resize(3);
  bvh.ref_indices = {0, 1};
  bvh.root = 0;
  bvh[1].make_leaf(0, 1);
  bvh[1].parent = 0;
  bvh[1].set_box(refs.boxes[0]);
  bvh[2].make_leaf(1, 1);
  bvh[2].parent = 0;
  bvh[2].set_box(refs.boxes[1]);
  bvh[0].make_inner(1, 2);
  bvh[0].set_box(merge(refs.boxes[0], refs.boxes[1]));
  FlatBvh flat = finalize(bvh, refs);
  ASSERT_EQ(flat.nodes.size(), 3u);
  EXPECT_EQ(flat.nodes[0].axis, 2);
  EXPECT_EQ(flat.nodes[1].box, refs.boxes[1]);  // the low one first
  EXPECT_EQ(flat.triangle_ids, (std::vector<uint32_t>{1, 0}));
  EXPECT_EQ(flat.nodes[0].index, 2u);
}

TEST(Finalize, EmptyAndSingleLeafTrees) {
  EXPECT_TRUE(finalize(Bvh{}, PrimitiveRefs{}).nodes.empty());
  PrimitiveRefs one = make_references({box(0, 0, 0, 1, 1, 1)});
  FlatBvh flat = finalize(build_bvh(one), one);
  ASSERT_EQ(flat.nodes.size(), 1u);
  EXPECT_TRUE(flat.nodes[0].is_leaf());
  EXPECT_EQ(flat.nodes[0].count, 1);
  EXPECT_EQ(flat.triangle_ids, (std::vector<uint32_t>{0}));
}

TEST(Finalize, RejectsLeavesOverTheLimit) {
  std::vector<Box> boxes(65536, box(0, 0, 0, 1, 1, 1));
  PrimitiveRefs refs = make_references(boxes);
  MedianConfig big;
  big.leaf.max_leaf_size = 70000;
  Bvh bvh = build_object_median(refs, big);
  ASSERT_TRUE(bvh[bvh.root].is_leaf());
  EXPECT_THROW(
      {
        try {
          finalize(bvh, refs);
        } catch (const Error& e) {
          EXPECT_NE(std::string(e.what()).find("more than 65535"), std::string::npos) << e.what();
          throw;
        }
      },
      Error);
  // 65535 is still fine.
  boxes.pop_back();
  PrimitiveRefs fits = make_references(boxes);
  Bvh ok = build_object_median(fits, big);
  EXPECT_EQ(finalize(ok, fits).nodes[0].count, 65535);
}

TEST(Finalize, ReferenceOutOfRangeThrows) {
  PrimitiveRefs refs = scene(100, 4);
  Bvh bvh = build_object_median(refs);
  bvh.ref_indices[57] = 5000;
  try {
    finalize(bvh, refs);
    ADD_FAILURE() << "accepted a reference id out of range";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("leaf slot 57 holds reference 5000, out of range (100 references)"),
              std::string::npos)
        << e.what();
  }
}

TEST(Finalize, BuiltInSceneEveryBuilderBothOrders) {
  Mesh mesh = make_builtin_scene({.seed = 2, .target_triangles = 20000});
  PrimitiveRefs refs = make_references(mesh);
  for (BuilderKind kind : all_builders()) {
    BuildOptions o;
    o.kind = kind;
    Bvh bvh = build_bvh(refs, o);
    for (bool ordered : {false, true}) {
      FlatBvh flat = finalize(bvh, refs, FinalizeOptions{ordered});
      EXPECT_EQ(check_subtree(bvh, refs, flat, bvh.root, 0, ordered), flat.nodes.size()) << builder_name(kind);
      EXPECT_EQ(flat.triangle_ids.size(), refs.size());
    }
  }
}

TEST(Finalize, SameResultOnOneAndTwoThreads) {
  PrimitiveRefs refs = scene(50000, 8);
  Bvh bvh = build_object_median(refs);
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return finalize(bvh, refs);
  };
  FlatBvh one = run(1), two = run(2);
  ASSERT_EQ(one.nodes.size(), two.nodes.size());
  EXPECT_EQ(std::memcmp(one.nodes.data(), two.nodes.data(), one.nodes.size() * sizeof(FlatNode)), 0);
  EXPECT_EQ(one.triangle_ids, two.triangle_ids);
}

TEST(Finalize, CorruptTreeThrowsInsteadOfLooping) {
  PrimitiveRefs refs = scene(100, 3);
  Bvh bvh = build_object_median(refs);
  uint32_t deepest = 0;
  for (uint32_t n : bvh.depth_first_order())
    if (!bvh[n].is_leaf()) deepest = n;
  bvh[deepest].set_child(1, bvh.root);
  EXPECT_THROW(finalize(bvh, refs), Error);
}

}  // namespace
}  // namespace bvhopt

namespace bvhopt {
namespace {

// A leaf's count is 16 bits in the flat node: the test-only flattening must refuse a larger
// leaf as finalize does, not cast it and drop triangles.
TEST(FlattenForTracing, LeafAboveSixteenBitsIsAnError) {
  const uint32_t n = 70000;
  const PrimitiveRefs refs = make_references(testing::random_mesh(n, 3, true));
  Bvh bvh;
  bvh.nodes.resize(1);
  bvh.nodes[0].make_leaf(0, n);
  bvh.root = 0;
  bvh.ref_indices.resize(n);
  std::iota(bvh.ref_indices.begin(), bvh.ref_indices.end(), 0u);
  EXPECT_THROW(flatten_for_tracing(bvh, refs), Error);
}

}  // namespace
}  // namespace bvhopt
