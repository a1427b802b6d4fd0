#include <gtest/gtest.h>

#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/stats.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace bvhopt {
namespace {

// Four unit cubes in a row along x: the object median gives ((0,1),(2,3)).
//   root [0,4]x[0,1]x[0,1]: area 2(4 + 1 + 4) = 18
//   two inner [0,2], [2,4]: area 2(2 + 1 + 2) = 10 each
//   four leaves, unit cubes: area 6 each
PrimitiveRefs four_in_a_row() {
  std::vector<Box> boxes;
  for (int i = 0; i < 4; ++i) boxes.push_back(Box({float(i), 0, 0}, {float(i + 1), 1, 1}));
  return make_references(boxes);
}

TEST(Stats, FourUnitBoxesInARow) {
  PrimitiveRefs refs = four_in_a_row();
  Bvh bvh = build_object_median(refs);
  ASSERT_EQ(testing::tree_signature(bvh, refs), "(([0],[1]),([2],[3]))");
  TreeStats s = compute_stats(bvh, CostModel{3, 2});
  EXPECT_EQ(s.nodes, 7u);
  EXPECT_EQ(s.inner_nodes, 3u);
  EXPECT_EQ(s.leaves, 4u);
  EXPECT_EQ(s.references, 4u);
  EXPECT_EQ(s.max_depth, 2u);
  EXPECT_DOUBLE_EQ(s.mean_leaf_depth, 2.0);
  EXPECT_EQ(s.min_refs_per_leaf, 1u);
  EXPECT_EQ(s.max_refs_per_leaf, 1u);
  EXPECT_DOUBLE_EQ(s.mean_refs_per_leaf, 1.0);
  EXPECT_DOUBLE_EQ(s.root_area, 18.0);
  EXPECT_DOUBLE_EQ(s.inner_area_sum, 38.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_sum, 24.0);
  ASSERT_EQ(s.inner_area_by_depth.size(), 3u);
  ASSERT_EQ(s.leaf_area_by_depth.size(), 3u);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[0], 18.0);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[1], 20.0);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[2], 0.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_by_depth[0], 0.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_by_depth[1], 0.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_by_depth[2], 24.0);
  // (3 * 38 + 2 * 24) / 18 = 162 / 18 = 9.
  EXPECT_NEAR(s.cost, 9.0, 1e-12);
  // Each half collapses (2 * 10 * 2 = 40 < 3 * 10 + 12 + 12 = 54); the root does not
  // (3 * 18 + 80 = 134 < 2 * 18 * 4 = 144): 134 / 18.
  EXPECT_NEAR(s.ocost, 134.0 / 18.0, 1e-12);
}

// A hand-made chain (0,(1,(2,3))) over the same cubes: unbalanced depths.
TEST(Stats, HandMadeChain) {
  PrimitiveRefs refs = four_in_a_row();
  Bvh bvh;
  bvh.nodes.resize(7);
  bvh.ref_indices = {0, 1, 2, 3};
  bvh.root = 0;
  auto leaf = [&](uint32_t n, uint32_t parent, uint32_t slot) {
    bvh[n].make_leaf(slot, 1);
    bvh[n].parent = parent;
    bvh[n].set_box(refs.boxes[slot]);
  };
  auto inner = [&](uint32_t n, uint32_t parent, uint32_t l, uint32_t r) {
    bvh[n].make_inner(l, r);
    bvh[n].parent = parent;
    bvh[n].set_box(merge(bvh[l].box, bvh[r].box));
  };
  leaf(1, 0, 0);
  leaf(3, 2, 1);
  leaf(5, 4, 2);
  leaf(6, 4, 3);
  inner(4, 2, 5, 6);  // [2,4]: area 10
  inner(2, 0, 3, 4);  // [1,4]: area 2(3 + 1 + 3) = 14
  inner(0, kInvalidNode, 1, 2);  // [0,4]: area 18
  ASSERT_TRUE(validate(bvh, refs).ok()) << validate(bvh, refs).summary();

  TreeStats s = compute_stats(bvh, CostModel{3, 2});
  EXPECT_EQ(s.nodes, 7u);
  EXPECT_EQ(s.max_depth, 3u);
  EXPECT_DOUBLE_EQ(s.mean_leaf_depth, (1 + 2 + 3 + 3) / 4.0);
  EXPECT_DOUBLE_EQ(s.inner_area_sum, 42.0);
  ASSERT_EQ(s.inner_area_by_depth.size(), 4u);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[0], 18.0);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[1], 14.0);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[2], 10.0);
  EXPECT_DOUBLE_EQ(s.inner_area_by_depth[3], 0.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_by_depth[1], 6.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_by_depth[2], 6.0);
  EXPECT_DOUBLE_EQ(s.leaf_area_by_depth[3], 12.0);
  EXPECT_NEAR(s.cost, (3 * 42.0 + 2 * 24.0) / 18.0, 1e-12);
}

TEST(Stats, LeavesWithSeveralReferences) {
  PrimitiveRefs refs = make_references(testing::random_mesh(1000, 5));
  BuildOptions o;
  o.kind = BuilderKind::object_median;
  o.leaf.max_leaf_size = 3;
  Bvh bvh = build_bvh(refs, o);
  TreeStats s = compute_stats(bvh);
  // 1000 split in halves down to at most 3: counts 2 and 3 only, 1000 in all.
  EXPECT_EQ(s.references, 1000u);
  EXPECT_GE(s.min_refs_per_leaf, 2u);
  EXPECT_EQ(s.max_refs_per_leaf, 3u);
  EXPECT_DOUBLE_EQ(s.mean_refs_per_leaf, 1000.0 / s.leaves);
}

// On random trees from every builder, the statistics agree with a brute-force recount.
TEST(Stats, AgreesWithARecountOnRandomTrees) {
  for (BuilderKind kind : all_builders())
    for (uint64_t seed = 1; seed <= 4; ++seed) {
      PrimitiveRefs refs = make_references(testing::random_mesh(300 * static_cast<uint32_t>(seed), seed));
      BuildOptions o;
      o.kind = kind;
      o.leaf.max_leaf_size = static_cast<uint32_t>(seed);
      Bvh bvh = build_bvh(refs, o);
      TreeStats s = compute_stats(bvh);

      size_t leaves = 0, inner = 0, refs_in_leaves = 0;
      double inner_sum = 0, leaf_sum = 0, weighted_leaf = 0;
      std::vector<uint32_t> depth(bvh.nodes.size(), 0);
      uint32_t max_depth = 0;
      for (uint32_t n : bvh.depth_first_order()) {
        if (n != bvh.root) depth[n] = depth[bvh[n].parent] + 1;
        max_depth = std::max(max_depth, depth[n]);
        if (bvh[n].is_leaf()) {
          ++leaves;
          refs_in_leaves += bvh[n].ref_count();
          leaf_sum += bvh[n].box.area();
          weighted_leaf += double(bvh[n].box.area()) * bvh[n].ref_count();
        } else {
          ++inner;
          inner_sum += bvh[n].box.area();
        }
      }
      EXPECT_EQ(s.leaves, leaves);
      EXPECT_EQ(s.inner_nodes, inner);
      EXPECT_EQ(s.nodes, leaves + inner);
      EXPECT_EQ(s.nodes, 2 * leaves - 1);
      EXPECT_EQ(s.references, refs.size());
      EXPECT_EQ(s.references, refs_in_leaves);
      EXPECT_EQ(s.max_depth, max_depth);
      EXPECT_NEAR(s.inner_area_sum, inner_sum, 1e-9 * inner_sum);
      EXPECT_NEAR(s.leaf_area_sum, leaf_sum, 1e-9 * leaf_sum);
      double by_depth_inner = 0, by_depth_leaf = 0;
      for (double a : s.inner_area_by_depth) by_depth_inner += a;
      for (double a : s.leaf_area_by_depth) by_depth_leaf += a;
      EXPECT_NEAR(by_depth_inner, inner_sum, 1e-9 * inner_sum);
      EXPECT_NEAR(by_depth_leaf, leaf_sum, 1e-9 * leaf_sum);
      EXPECT_EQ(s.inner_area_by_depth.size(), max_depth + 1u);
      EXPECT_DOUBLE_EQ(s.root_area, bvh[bvh.root].box.area());
      EXPECT_NEAR(s.cost, (3.0 * inner_sum + 2.0 * weighted_leaf) / s.root_area, 1e-9 * s.cost);
      EXPECT_LE(s.ocost, s.cost + 1e-12);
    }
}

TEST(Stats, EmptyTree) {
  TreeStats s = compute_stats(Bvh{});
  EXPECT_EQ(s.nodes, 0u);
  EXPECT_EQ(s.leaves, 0u);
  EXPECT_EQ(s.cost, 0.0);
  EXPECT_TRUE(s.inner_area_by_depth.empty());
}

}  // namespace
}  // namespace bvhopt
