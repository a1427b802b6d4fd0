#include <gtest/gtest.h>

#include "bvhopt/cost.h"
#include "bvhopt/build.h"
#include "bvhopt/median_builder.h"
#include "test_support.h"

namespace bvhopt {
namespace {

// Two unit cubes side by side: root box 2x1x1 has area 2(2+1+2) = 10, each leaf area 6.
TEST(Cost, HandComputedTwoLeaves) {
  PrimitiveRefs refs = make_references({Box({0, 0, 0}, {1, 1, 1}), Box({1, 0, 0}, {2, 1, 1})});
  Bvh bvh = build_object_median(refs);
  ASSERT_EQ(bvh.nodes.size(), 3u);
  EXPECT_FLOAT_EQ(bvh[bvh.root].area(), 10.0f);
  // (3 * 10 + 2 * 6 + 2 * 6) / 10 = 5.4
  EXPECT_NEAR(sah_cost(bvh, CostModel{3, 2}), 5.4, 1e-9);
  EXPECT_NEAR(sah_cost(bvh, CostModel{1, 1}), (10.0 + 12.0) / 10.0, 1e-9);
  // Collapsing both into one leaf: 2 * 10 * 2 / 10 = 4 < 5.4.
  EXPECT_NEAR(optimal_collapse_cost(bvh, CostModel{3, 2}), 4.0, 1e-9);
  // With a leaf size limit of 1 nothing may collapse.
  EXPECT_NEAR(optimal_collapse_cost(bvh, CostModel{3, 2}, 1), 5.4, 1e-9);
}

TEST(Cost, OptimalTreeOracleOnTwoBoxesIsTheOnlyTree) {
  PrimitiveRefs refs = make_references({Box({0, 0, 0}, {1, 1, 1}), Box({1, 0, 0}, {2, 1, 1})});
  EXPECT_NEAR(testing::optimal_tree_cost(refs, 3, 2), 54.0, 1e-9);
}

// The cost recomputed by a plain recursion over the tree, straight from Eq. 1.
double recursive_cost(const Bvh& bvh, uint32_t n, const CostModel& m) {
  const BvhNode& nd = bvh[n];
  if (nd.is_leaf()) return m.intersection * double(nd.box.area()) * nd.ref_count();
  return m.traversal * double(nd.box.area()) + recursive_cost(bvh, nd.left(), m) + recursive_cost(bvh, nd.right(), m);
}

TEST(Cost, AgreesWithARecursionFromScratchOnEveryBuilder) {
  const CostModel m{3, 2};
  for (BuilderKind kind : all_builders())
    for (uint32_t leaf : {1u, 4u}) {
      PrimitiveRefs refs = make_references(testing::random_mesh(500, 11 + leaf));
      BuildOptions o;
      o.kind = kind;
      o.leaf.max_leaf_size = leaf;
      Bvh bvh = build_bvh(refs, o);
      const double root_area = bvh[bvh.root].box.area();
      const double expected = recursive_cost(bvh, bvh.root, m) / root_area;
      EXPECT_NEAR(sah_cost(bvh, m), expected, 1e-9 * expected) << builder_name(kind);
      std::vector<double> sub = subtree_costs(bvh, m);
      EXPECT_NEAR(sub[bvh.root], expected * root_area, 1e-9 * expected * root_area);
      // Collapsing can only help, and with a leaf limit of 1 a tree of single-reference
      // leaves cannot collapse at all.
      EXPECT_LE(optimal_collapse_cost(bvh, m), sah_cost(bvh, m) + 1e-12);
      if (leaf == 1) {
        EXPECT_NEAR(optimal_collapse_cost(bvh, m, 1), sah_cost(bvh, m), 1e-12 * expected);
      }
    }
}

TEST(Cost, NoBuilderBeatsTheOracle) {
  const CostModel m{3, 2};
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    PrimitiveRefs refs = testing::random_refs(2 + static_cast<uint32_t>(seed % 9), seed);
    const double optimum = testing::optimal_tree_cost(refs, m.traversal, m.intersection);
    for (BuilderKind kind : all_builders()) {
      BuildOptions o;
      o.kind = kind;
      Bvh bvh = build_bvh(refs, o);
      EXPECT_GE(sah_cost(bvh, m) * bvh[bvh.root].area(), optimum * (1 - 1e-6)) << builder_name(kind) << " " << seed;
    }
  }
}

}  // namespace
}  // namespace bvhopt
