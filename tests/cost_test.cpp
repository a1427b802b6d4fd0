#include <gtest/gtest.h>

#include "bvhopt/cost.h"
#include "bvhopt/median_builder.h"
#include "test_support.h"

namespace bvhopt {
namespace {

// Two unit cubes side by side: root box 2x1x1 has area 2(2+1+2) = 10, each leaf area 6.
TEST(Cost, HandComputedTwoLeaves) {
  PrimitiveRefs refs = make_references({Box({0, 0, 0}, {1, 1, 1}), Box({1, 0, 0}, {2, 1, 1})});
  Bvh bvh = build_object_median(refs);
  ASSERT_EQ(bvh.nodes.size(), 3u);
  EXPECT_FLOAT_EQ(bvh[bvh.root].area, 10.0f);
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

}  // namespace
}  // namespace bvhopt
