// The wide collapse: the DP is optimal against an exhaustive enumeration of every collapse of
// small trees, greedy widening never beats it, and the collapsed structure is a valid tree.
#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/references.h"
#include "bvhopt/wide_bvh.h"
#include "test_support.h"

namespace bvhopt {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Every way to represent a subtree, enumerated: a cut of the subtree is {n} or a cut of the
// left child joined with a cut of the right child. A wide node at n has as children any cut
// of n's children of at most `width` subtrees, each represented in its own cheapest way (the
// representations of different subtrees are independent, so the minimum of the sum is the sum
// of the minima). Exponential; for trees of up to 12 leaves.
class Exhaustive {
 public:
  Exhaustive(const FlatBvh& bvh, const CollapseOptions& o) : bvh_(bvh), o_(o), best_(bvh.nodes.size(), -1.0) {}

  double root_cost() {
    const FlatNode& root = bvh_.nodes[0];
    if (root.is_leaf()) return (o_.cost.node * root.box.area() + leaf_cost(0)) / root.box.area();
    return inner_cost(0) / root.box.area();
  }

 private:
  std::vector<uint32_t> triangles(uint32_t n) const {
    const FlatNode& f = bvh_.nodes[n];
    if (f.is_leaf()) return {bvh_.triangle_ids.begin() + f.index, bvh_.triangle_ids.begin() + f.index + f.count};
    std::vector<uint32_t> a = triangles(n + 1), b = triangles(f.index);
    a.insert(a.end(), b.begin(), b.end());
    return a;
  }
  double leaf_cost(uint32_t n) const {
    std::vector<uint32_t> t = triangles(n);
    std::sort(t.begin(), t.end());
    t.erase(std::unique(t.begin(), t.end()), t.end());
    if (!bvh_.nodes[n].is_leaf() && t.size() > o_.max_leaf_triangles) return kInf;
    return o_.cost.block * bvh_.nodes[n].box.area() * double((t.size() + 3) / 4);
  }
  // Costs of every cut of the subtree of n, as (subtrees, summed best cost).
  std::vector<std::pair<uint32_t, double>> cuts(uint32_t n) {
    std::vector<std::pair<uint32_t, double>> out{{1u, best(n)}};
    if (bvh_.nodes[n].is_leaf()) return out;
    for (const auto& a : cuts(n + 1))
      for (const auto& b : cuts(bvh_.nodes[n].index))
        if (a.first + b.first <= o_.width) out.push_back({a.first + b.first, a.second + b.second});
    return out;
  }
  double inner_cost(uint32_t n) {
    double best_cut = kInf;
    for (const auto& a : cuts(n + 1))
      for (const auto& b : cuts(bvh_.nodes[n].index))
        if (a.first + b.first <= o_.width) best_cut = std::min(best_cut, a.second + b.second);
    return o_.cost.node * bvh_.nodes[n].box.area() + best_cut;
  }
  double best(uint32_t n) {
    if (best_[n] < 0.0) best_[n] = std::min(leaf_cost(n), bvh_.nodes[n].is_leaf() ? kInf : inner_cost(n));
    return best_[n];
  }

  const FlatBvh& bvh_;
  CollapseOptions o_;
  std::vector<double> best_;
};

FlatBvh small_tree(uint32_t triangles, uint64_t seed, BuilderKind kind, uint32_t leaf) {
  const Mesh mesh = testing::random_mesh(triangles, seed);
  const PrimitiveRefs refs = make_references(mesh);
  BuildOptions b;
  b.kind = kind;
  b.leaf.max_leaf_size = leaf;
  return finalize(build_bvh(refs, b), refs);
}

// Structure: depth-first, 2..width children (the root may have 1), every triangle of the
// binary tree in exactly the leaves covering it once, boxes nested.
void expect_valid(const CollapsedBvh& w, const FlatBvh& bvh) {
  ASSERT_FALSE(w.nodes.empty());
  EXPECT_EQ(w.nodes[0], 0u);
  std::multiset<uint32_t> seen;
  for (size_t n = 0; n < w.nodes.size(); ++n) {
    const uint32_t count = w.child_begin[n + 1] - w.child_begin[n];
    EXPECT_LE(count, w.width);
    EXPECT_GE(count, n == 0 ? 1u : 2u);
    for (uint32_t s = w.child_begin[n]; s < w.child_begin[n + 1]; ++s) {
      EXPECT_TRUE(bvh.nodes[w.nodes[n]].box.contains(bvh.nodes[w.children[s]].box));
      if (w.child_is_leaf[s]) {
        const uint32_t l = w.child_index[s];
        seen.insert(w.leaf_triangles.begin() + w.leaf_begin[l], w.leaf_triangles.begin() + w.leaf_begin[l + 1]);
      } else {
        EXPECT_GT(w.child_index[s], n);
        EXPECT_EQ(w.nodes[w.child_index[s]], w.children[s]);
      }
    }
  }
  // Without subdivision every triangle is referenced once, so it lies in exactly one leaf.
  std::multiset<uint32_t> want(bvh.triangle_ids.begin(), bvh.triangle_ids.end());
  EXPECT_EQ(seen, want);
  // Numbered as one depth-first walk (the layout places subtrees by it): from the root,
  // inner children in slot order, each node numbered when reached and each leaf when its
  // parent is; the leaves' triangle ranges follow one another.
  uint32_t next_node = 0, next_leaf = 0;
  std::vector<uint32_t> todo{0};
  while (!todo.empty()) {
    const uint32_t n = todo.back();
    todo.pop_back();
    ASSERT_EQ(n, next_node++);
    for (uint32_t s = w.child_begin[n]; s < w.child_begin[n + 1]; ++s) {
      if (w.child_is_leaf[s]) {
        ASSERT_EQ(w.child_index[s], next_leaf++);
      }
    }
    for (uint32_t s = w.child_begin[n + 1]; s-- > w.child_begin[n];)
      if (!w.child_is_leaf[s]) todo.push_back(w.child_index[s]);
  }
  EXPECT_EQ(next_node, w.nodes.size());
  EXPECT_EQ(next_leaf, w.leaf_count());
  EXPECT_EQ(w.leaf_begin.back(), w.leaf_triangles.size());
}

TEST(WideCollapse, DynamicProgramIsOptimalAgainstExhaustiveEnumeration) {
  size_t cases = 0;
  for (uint64_t seed = 1; seed <= 12; ++seed) {
    for (BuilderKind kind : all_builders()) {
      for (uint32_t leaf : {1u, 2u}) {
        const FlatBvh bvh = small_tree(uint32_t(5 + seed % 8), seed, kind, leaf);
        for (uint32_t width : {4u, 8u}) {
          for (const WideCostModel cost : {WideCostModel{1.0, 1.0}, WideCostModel{3.0, 1.0}, WideCostModel{0.5, 2.0}}) {
            for (uint32_t limit : {2u, 4u, 8u}) {
              CollapseOptions o;
              o.width = width;
              o.cost = cost;
              o.max_leaf_triangles = limit;
              const CollapsedBvh dp = collapse_to_wide(bvh, o);
              expect_valid(dp, bvh);
              const double want = Exhaustive(bvh, o).root_cost();
              EXPECT_NEAR(dp.sah_cost, want, 1e-5 * want) << "seed " << seed << " " << builder_name(kind) << " width "
                                                          << width << " limit " << limit;
              EXPECT_NEAR(wide_sah_cost(dp, bvh, cost), dp.sah_cost, 1e-12 * want);
              o.method = CollapseMethod::greedy;
              const CollapsedBvh greedy = collapse_to_wide(bvh, o);
              expect_valid(greedy, bvh);
              EXPECT_GE(greedy.sah_cost, dp.sah_cost * (1.0 - 1e-6));
              ++cases;
            }
          }
        }
      }
    }
  }
  EXPECT_GT(cases, 1000u);
}

TEST(WideCollapse, GreedyNeverBeatsTheDpOnLargerTreesAndTheDpGains) {
  double gain = 0.0;
  for (uint64_t seed : {3u, 4u}) {
    for (uint32_t leaf : {1u, 4u}) {
      const FlatBvh bvh = small_tree(3000, seed, BuilderKind::sweep_sah, leaf);
      for (uint32_t width : {4u, 8u}) {
        CollapseOptions o;
        o.width = width;
        const CollapsedBvh dp = collapse_to_wide(bvh, o);
        expect_valid(dp, bvh);
        o.method = CollapseMethod::greedy;
        const CollapsedBvh greedy = collapse_to_wide(bvh, o);
        expect_valid(greedy, bvh);
        EXPECT_GE(greedy.sah_cost, dp.sah_cost * (1.0 - 1e-6));
        gain = std::max(gain, greedy.sah_cost / dp.sah_cost);
      }
    }
  }
  EXPECT_GT(gain, 1.05);  // on leaf-size-1 trees the DP makes leaves the greedy cannot
}

TEST(WideCollapse, SameResultOnAnyThreadCount) {
  const FlatBvh bvh = small_tree(4000, 9, BuilderKind::sweep_sah, 1);
  CollapsedBvh one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = collapse_to_wide(bvh);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = collapse_to_wide(bvh);
  }
  // Large enough that the walk is cut into segments (wide_collapse.cpp): they must join
  // into one depth-first numbering.
  expect_valid(one, bvh);
  expect_valid(two, bvh);
  EXPECT_EQ(one.sah_cost, two.sah_cost);
  EXPECT_EQ(one.children, two.children);
  EXPECT_EQ(one.leaf_triangles, two.leaf_triangles);
}

// The recurrence of Ylitie et al. in double, node by node from the root (memoized): C(n, i)
// for i = 1..width, the cheapest representation of n's subtree as at most i subtrees. Its
// cost is what the DP must reach on trees large enough that the DP solves subtrees in
// parallel tasks and joins their rows.
class Recurrence {
 public:
  Recurrence(const FlatBvh& bvh, const CollapseOptions& o) : bvh_(bvh), o_(o), rows_(bvh.nodes.size()) {}

  double root_cost() {
    const FlatNode& root = bvh_.nodes[0];
    return (o_.cost.node * root.box.area() + distribute(0, o_.width)) / root.box.area();
  }

 private:
  uint32_t triangles(uint32_t n) const {  // trees of unsplit triangles: every entry distinct
    const FlatNode& f = bvh_.nodes[n];
    return f.is_leaf() ? f.count : triangles(n + 1) + triangles(f.index);
  }
  // The best split of j slots over n's two children.
  double distribute(uint32_t n, uint32_t j) {
    double best = kInf;
    for (uint32_t k = 1; k < j; ++k) best = std::min(best, row(n + 1)[k - 1] + row(bvh_.nodes[n].index)[j - k - 1]);
    return best;
  }
  const std::vector<double>& row(uint32_t n) {
    std::vector<double>& r = rows_[n];
    if (!r.empty()) return r;
    const FlatNode& f = bvh_.nodes[n];
    const uint32_t t = triangles(n);
    const double leaf = f.is_leaf() || t <= o_.max_leaf_triangles ? o_.cost.block * f.box.area() * double((t + 3) / 4) : kInf;
    std::vector<double> c(o_.width, leaf);
    if (!f.is_leaf()) {
      c[0] = std::min(leaf, o_.cost.node * f.box.area() + distribute(n, o_.width));
      for (uint32_t i = 2; i <= o_.width; ++i) c[i - 1] = std::min(c[i - 2], distribute(n, i));
    }
    return r = std::move(c);
  }

  const FlatBvh& bvh_;
  CollapseOptions o_;
  std::vector<std::vector<double>> rows_;
};

TEST(WideCollapse, LargeTreesReachTheRecurrencesOptimum) {
  for (const uint32_t leaf : {1u, 4u}) {
    const FlatBvh bvh = small_tree(20000, 12, BuilderKind::sweep_sah, leaf);
    ASSERT_GT(bvh.nodes.size(), 3u * 4096u) << "too small for the DP's parallel subtrees";
    for (const uint32_t width : {4u, 8u}) {
      CollapseOptions o;
      o.width = width;
      const double expected = Recurrence(bvh, o).root_cost();
      const CollapsedBvh w = collapse_to_wide(bvh, o);
      // The DP compares costs in float: a near tie may go the other way.
      EXPECT_NEAR(w.sah_cost, expected, 1e-5 * expected) << "leaf " << leaf << ", width " << width;
    }
  }
}

TEST(WideCollapse, LeafLimitAndWidthAreHonoured) {
  const FlatBvh bvh = small_tree(2000, 10, BuilderKind::sweep_sah, 1);
  for (uint32_t limit : {1u, 3u, 16u}) {
    CollapseOptions o;
    o.max_leaf_triangles = limit;
    const CollapsedBvh w = collapse_to_wide(bvh, o);
    for (size_t l = 0; l < w.leaf_count(); ++l) EXPECT_LE(w.leaf_begin[l + 1] - w.leaf_begin[l], limit);
  }
  CollapseOptions bad;
  bad.width = 6;
  EXPECT_THROW(collapse_to_wide(bvh, bad), Error);
}

}  // namespace
}  // namespace bvhopt
