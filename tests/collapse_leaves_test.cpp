#include <gtest/gtest.h>

#include <cmath>

#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace bvhopt {
namespace {

TEST(Compaction, TwoTouchingCubesBecomeOneLeaf) {
  PrimitiveRefs refs = make_references({Box({0, 0, 0}, {1, 1, 1}), Box({1, 0, 0}, {2, 1, 1})});
  Bvh bvh = build_object_median(refs);
  CollapseResult r = collapse_leaves(bvh);
  EXPECT_NEAR(r.cost_before, 5.4, 1e-9);
  EXPECT_NEAR(r.cost_after, 4.0, 1e-9);  // 2 * 10 * 2 / 10
  ASSERT_EQ(bvh.nodes.size(), 1u);
  EXPECT_EQ(bvh[bvh.root].ref_count(), 2u);
  EXPECT_TRUE(validate(bvh, refs).ok());
}

TEST(Compaction, LeafSizeOneChangesNothing) {
  PrimitiveRefs refs = testing::random_refs(300, 1);
  Bvh bvh = build_sweep_sah(refs);
  std::string before = testing::tree_signature(bvh, refs);
  CollapseConfig cfg;
  cfg.max_leaf_size = 1;
  CollapseResult r = collapse_leaves(bvh, cfg);
  EXPECT_EQ(r.cost_before, r.cost_after);
  EXPECT_EQ(testing::tree_signature(bvh, refs), before);
}

// On many random trees (from several builders, optimized or not, with several leaf limits):
// the result is valid, never costs more, equals the `ocost` of the tree before, and keeps
// every leaf within the limit.
TEST(Compaction, EqualsOcostAndNeverRaisesTheCost) {
  int collapsed = 0;
  for (uint32_t seed = 0; seed < 120; ++seed) {
    const uint32_t count = 1 + (seed * 37) % 700;
    PrimitiveRefs refs = seed % 4 == 0 ? make_references(testing::random_mesh(count, seed, true))
                                       : testing::random_refs(count, seed);
    Bvh bvh = seed % 3 == 0 ? build_spatial_median(refs) : build_sweep_sah(refs);
    if (seed % 2 == 0) {
      InsertionConfig ic;
      ic.max_passes = 20;
      optimize_insertion(bvh, ic);
    }
    for (uint32_t max_leaf : {0u, 2u, 4u, 8u}) {
      Bvh t = bvh;
      const double ocost = optimal_collapse_cost(t, CostModel{}, max_leaf);
      const double before = sah_cost(t);
      CollapseConfig cfg;
      cfg.max_leaf_size = max_leaf;
      CollapseResult r = collapse_leaves(t, cfg);
      ValidationReport v = validate(t, refs);
      ASSERT_TRUE(v.ok()) << v.summary();
      EXPECT_EQ(r.cost_before, before);
      EXPECT_LE(r.cost_after, before * (1 + 1e-12));
      EXPECT_NEAR(r.cost_after, ocost, 1e-12 * ocost) << "seed " << seed << " max leaf " << max_leaf;
      EXPECT_NEAR(sah_cost(t), r.cost_after, 1e-12 * ocost);
      EXPECT_EQ(t.nodes.size(), r.nodes_after);
      EXPECT_EQ(r.nodes_after, 2 * r.leaves_after - 1);
      for (const BvhNode& n : t.nodes) {
        if (n.is_leaf() && max_leaf != 0) {
          EXPECT_LE(n.ref_count(), std::max(max_leaf, 1u));
        }
      }
      // Compacting twice changes nothing: the first pass already took every collapse.
      Bvh again = t;
      CollapseResult r2 = collapse_leaves(again, cfg);
      EXPECT_EQ(r2.leaves_after, r.leaves_after);
      collapsed += r.leaves_after < r.leaves_before;
    }
  }
  EXPECT_GT(collapsed, 100);
}

TEST(Compaction, LeavesAreContiguousInDepthFirstOrder) {
  PrimitiveRefs refs = testing::random_refs(500, 5);
  Bvh bvh = build_spatial_median(refs);
  collapse_leaves(bvh);
  uint32_t next = 0;
  for (uint32_t n : bvh.depth_first_order()) {
    if (!bvh[n].is_leaf()) continue;
    EXPECT_EQ(bvh[n].first_ref(), next);
    next += bvh[n].ref_count();
  }
  EXPECT_EQ(next, refs.size());
}

}  // namespace
}  // namespace bvhopt
