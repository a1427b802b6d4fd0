#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

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

// Walks the tree from the root without its stored boxes: each node's box is rebuilt from
// the reference boxes below it, and the cost summed from Eq. 1 by recursion. Shares nothing
// with sah_cost (which collapse_leaves reports), nor with the node array's size.
struct FromScratch {
  double cost = 0.0;  // normalized
  size_t nodes = 0, leaves = 0;
};
FromScratch from_scratch(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& m) {
  FromScratch out;
  double sum = 0.0;
  auto rec = [&](auto&& self, uint32_t n) -> Box {
    const BvhNode& nd = bvh[n];
    ++out.nodes;
    Box b;
    if (nd.is_leaf()) {
      ++out.leaves;
      for (uint32_t k = 0; k < nd.ref_count(); ++k) b.extend(refs.boxes[bvh.ref_indices[nd.first_ref() + k]]);
      const double x = double(b.max.x) - b.min.x, y = double(b.max.y) - b.min.y, z = double(b.max.z) - b.min.z;
      sum += m.intersection * 2.0 * (x * y + y * z + z * x) * nd.ref_count();
      return b;
    }
    b = merge(self(self, nd.left()), self(self, nd.right()));
    const double x = double(b.max.x) - b.min.x, y = double(b.max.y) - b.min.y, z = double(b.max.z) - b.min.z;
    sum += m.traversal * 2.0 * (x * y + y * z + z * x);
    return b;
  };
  const Box root = rec(rec, bvh.root);
  const double x = double(root.max.x) - root.min.x, y = double(root.max.y) - root.min.y,
               z = double(root.max.z) - root.min.z;
  out.cost = sum / (2.0 * (x * y + y * z + z * x));
  return out;
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
      ic.limits.max_passes = 20;
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
      const FromScratch scratch = from_scratch(t, refs, CostModel{});
      EXPECT_NEAR(scratch.cost, r.cost_after, 1e-9 * ocost) << "seed " << seed << " max leaf " << max_leaf;
      EXPECT_EQ(scratch.nodes, r.nodes_after);
      EXPECT_EQ(scratch.leaves, r.leaves_after);
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

// The tree with every node of `cut` (a bit set over node ids) that has no cut ancestor made
// a leaf of all the references below it, collapsed by hand; false when a new leaf would
// hold more than max_leaf references (0 = no limit).
bool collapse_by_hand(Bvh& bvh, uint64_t cut, uint32_t max_leaf) {
  std::vector<uint32_t> refs;
  bool fits = true;
  auto gather = [&](auto&& self, uint32_t n, std::vector<uint32_t>& out) -> void {
    const BvhNode& nd = bvh[n];
    if (nd.is_leaf()) {
      for (uint32_t k = 0; k < nd.ref_count(); ++k) out.push_back(bvh.ref_indices[nd.first_ref() + k]);
      return;
    }
    self(self, nd.left(), out);
    self(self, nd.right(), out);
  };
  auto walk = [&](auto&& self, uint32_t n) -> void {
    BvhNode& nd = bvh[n];
    if (nd.is_leaf() || (cut >> n & 1)) {
      const uint32_t first = static_cast<uint32_t>(refs.size());
      gather(gather, n, refs);
      const uint32_t count = static_cast<uint32_t>(refs.size()) - first;
      if (!nd.is_leaf() && max_leaf != 0 && count > max_leaf) fits = false;
      nd.make_leaf(first, count);
      return;
    }
    self(self, nd.left());
    self(self, nd.right());
  };
  walk(walk, bvh.root);
  bvh.ref_indices = std::move(refs);
  return fits;
}

// ocost, and the cost after collapse_leaves, against the cheapest of every possible collapse
// of small trees (all subsets of inner nodes, each tree collapsed by hand and costed from
// scratch): the two share one recurrence, so a fault in it would show in both at once.
TEST(Compaction, OcostIsTheCheapestOfEveryCollapseChoice) {
  int cases = 0, collapsed = 0;
  for (uint32_t seed = 0; seed < 60; ++seed) {
    const uint32_t count = 1 + seed % 8;
    const PrimitiveRefs refs = testing::random_refs(count, 100 + seed);
    const Bvh bvh = seed % 2 == 0 ? build_spatial_median(refs) : build_sweep_sah(refs);
    ASSERT_LE(bvh.nodes.size(), 63u);
    for (const CostModel model : {CostModel{}, CostModel{1.0, 1.0}, CostModel{0.5, 4.0}, CostModel{10.0, 1.0}}) {
      for (uint32_t max_leaf : {0u, 2u, 3u}) {
        std::vector<uint32_t> inner;
        for (uint32_t n : bvh.post_order())
          if (!bvh[n].is_leaf()) inner.push_back(n);
        double cheapest = sah_cost(bvh, model);
        for (uint64_t subset = 1; subset < (uint64_t(1) << inner.size()); ++subset) {
          uint64_t cut = 0;
          for (size_t i = 0; i < inner.size(); ++i)
            if (subset >> i & 1) cut |= uint64_t(1) << inner[i];
          Bvh t = bvh;
          if (collapse_by_hand(t, cut, max_leaf)) cheapest = std::min(cheapest, sah_cost(t, model));
        }
        const double ocost = optimal_collapse_cost(bvh, model, max_leaf);
        EXPECT_NEAR(ocost, cheapest, 1e-12 * cheapest) << "seed " << seed << " max leaf " << max_leaf;
        Bvh t = bvh;
        CollapseConfig cfg;
        cfg.cost = model;
        cfg.max_leaf_size = max_leaf;
        const CollapseResult r = collapse_leaves(t, cfg);
        EXPECT_EQ(r.cost_after, ocost) << "seed " << seed << " max leaf " << max_leaf;
        EXPECT_EQ(sah_cost(t, model), ocost);
        ++cases;
        collapsed += r.leaves_after < r.leaves_before;
      }
    }
  }
  EXPECT_EQ(cases, 720);
  EXPECT_GT(collapsed, 100);  // the cheapest choice is often a real collapse
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
