#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <set>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "bvhopt/cost.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/testing/insertion_hooks.h"
#include "bvhopt/validate.h"
#include "optimize/in_subtree.h"
#include "optimize/largest_from_root.h"
#include "optimize/largest_keys.h"
#include "optimize/near_moves.h"
#include "optimize/node_set.h"
#include "optimize/reinsertion_search.h"
#include "optimize/undo_log.h"
#include "test_support.h"

namespace bvhopt {
namespace {

// The selection's shortcuts (every key of a small array; one scan that also gathers the
// keys; a second scan when the threshold falls below the last pass's guess or the gathering
// overflows) each give exactly the k largest keys a full sort gives, pass after pass while
// the keys drift down and jump up.
TEST(LargestKeys, EveryPathGivesTheKLargestAsAFullSortDoes) {
  using detail::LargestKeys;
  using Path = LargestKeys::Path;
  std::mt19937_64 rng(11);
  std::vector<uint64_t> keys;
  std::vector<char> member;
  auto make = [&](size_t count, float lo, float hi) {
    keys.assign(count, 0);
    member.assign(count, 0);
    std::uniform_real_distribution<float> value(lo, hi);
    for (size_t i = 0; i < count; ++i) {
      member[i] = rng() % 3 != 0;  // like leaves between inner nodes
      keys[i] = (uint64_t{std::bit_cast<uint32_t>(value(rng))} << 32) | (0xffffffffu - i);
    }
  };
  LargestKeys selection;
  std::set<Path> paths;
  auto check = [&](size_t k) {
    std::vector<uint64_t> got;
    const Path path = selection.largest(
        keys.size(), k, [&](size_t i) { return member[i] != 0; }, [&](size_t i) { return keys[i]; }, got);
    paths.insert(path);
    std::vector<uint64_t> expected;
    for (size_t i = 0; i < keys.size(); ++i)
      if (member[i]) expected.push_back(keys[i]);
    std::sort(expected.begin(), expected.end(), std::greater<uint64_t>());
    expected.resize(std::min(k, expected.size()));
    EXPECT_EQ(got, expected) << "k " << k << ", " << keys.size() << " entries";
    return path;
  };
  const size_t big = 3 * LargestKeys::kBuckets + 17;
  make(big, 1.0f, 2.0f);
  EXPECT_EQ(check(1000), Path::two_scans);  // no guess yet
  make(big, 1.0f, 2.0f);
  EXPECT_EQ(check(1000), Path::one_scan);   // keys drift a little: the guess holds
  EXPECT_EQ(check(1), Path::two_scans);     // a guess for k = 1000 gathers more than 4k keys
  make(big, 1e-3f, 2e-3f);
  EXPECT_EQ(check(1000), Path::two_scans);  // keys fall below the guess
  make(big, 1e3f, 2e3f);
  EXPECT_EQ(check(1000), Path::two_scans);  // every key above the guess: the gathering overflows
  EXPECT_EQ(check(big), Path::two_scans);   // k beyond the members: all of them
  make(LargestKeys::kBuckets, 1.0f, 2.0f);
  EXPECT_EQ(check(50), Path::all_keys);
  make(0, 1.0f, 2.0f);
  EXPECT_EQ(check(5), Path::all_keys);
  EXPECT_EQ(paths.size(), 3u);
}

Bvh build_start(const PrimitiveRefs& refs, int kind) {
  switch (kind % 3) {
    case 0: return build_sweep_sah(refs);
    case 1: return build_spatial_median(refs);
    default: return build_object_median(refs);
  }
}


// The optimizer's area keys of a tree (the root's the smallest), and the k largest of them
// by a full sort, without the root's: what LargestFromRoot must give.
struct AreaKeys {
  const Bvh& bvh;
  double root_area = bvh[bvh.root].area();
  uint64_t operator()(size_t i) const {
    const float m = i == bvh.root ? 0.0f : static_cast<float>(bvh.nodes[i].area() / root_area);
    return (uint64_t{std::bit_cast<uint32_t>(m)} << 32) | (0xffffffffu - static_cast<uint32_t>(i));
  }
  std::vector<uint64_t> largest_by_sort(size_t k) const {
    std::vector<uint64_t> keys;
    for (size_t i = 0; i < bvh.nodes.size(); ++i)
      if (!bvh.nodes[i].is_leaf()) keys.push_back((*this)(i));
    std::sort(keys.begin(), keys.end(), std::greater<uint64_t>());
    keys.resize(std::min(k, keys.size()));
    // The walk leaves out the root (which the optimizer skips), of all the keys the smallest
    // or tied at 0 with zero-area nodes.
    std::erase(keys, (*this)(bvh.root));
    return keys;
  }
};

// The walk from the root gives exactly the keys a full sort of the inner nodes' keys gives
// (the optimizer's area keys: the root's the smallest), on built trees, on trees whose ids
// the optimizer's moves have shuffled, with many nodes tied at the k-th key (copies of one
// box), and it declines where the k-th key is 0 (zero-area boxes), which the root ties.
// Each k is asked for twice: the second time from the threshold the first one left (one
// walker for every tree, so other k's thresholds, from other trees, start many of the
// first times: too high or too low, they must still give the same keys).
TEST(LargestFromRoot, GivesTheKLargestAreaKeysAsAFullSortDoes) {
  detail::LargestFromRoot walk;
  int walked = 0, declined = 0, from_threshold = 0;
  auto check = [&](const Bvh& bvh, size_t k, const std::string& what) {
    const AreaKeys key_of{bvh};
    const std::vector<uint64_t> expected = key_of.largest_by_sort(k);
    for (int time = 0; time < 2; ++time) {
      std::vector<uint64_t> got;
      if (!walk.largest(bvh, k, key_of, got)) {
        ++declined;
        EXPECT_EQ(walk.last_path(), detail::LargestFromRoot::Path::declined);
        EXPECT_EQ(expected.size() == k ? expected.back() >> 32 : 0u, 0u) << what << ": declined, k " << k;
        return;
      }
      ++walked;
      from_threshold += walk.last_path() == detail::LargestFromRoot::Path::from_threshold;
      EXPECT_EQ(got, expected) << what << ", k " << k << ", time " << time;
    }
  };
  for (uint32_t trial = 0; trial < 40; ++trial) {
    const uint32_t count = 2 + trial * 97;
    PrimitiveRefs refs = testing::random_refs(count, 700 + trial);
    if (trial % 4 == 1)  // every fifth box a copy of the first: whole subtrees tied
      for (size_t i = 5; i < refs.boxes.size(); i += 5) refs.boxes[i] = refs.boxes[0];
    if (trial % 4 == 2)  // a third of the boxes one point: zero-area subtrees
      for (size_t i = 0; i < refs.boxes.size(); i += 3) refs.boxes[i] = Box(refs.boxes[1].min, refs.boxes[1].min);
    Bvh bvh = build_start(refs, static_cast<int>(trial));
    if (trial % 2 == 1 && count >= 20) {  // ids shuffled by moves: parents after children
      InsertionConfig config;
      config.form = InsertionForm::sequential;
      config.limits.max_passes = 3;
      config.batch = 0.1;
      Bvh work = bvh, moved;
      int moves = 0;
      testing::optimize_insertion_observed(work, config, [&](const Bvh& t, double) {
        if (++moves == 5) moved = t;
      });
      ASSERT_GE(moves, 5) << "trial " << trial;
      ASSERT_FALSE(moved.numbered_depth_first());
      bvh = std::move(moved);
    }
    for (size_t k = 1; k <= count; k += 1 + count / 64) check(bvh, k, "trial " + std::to_string(trial));
    check(bvh, count, "trial " + std::to_string(trial));
  }
  // Every box the same: all tied at the root's area, and the walk reads them all.
  PrimitiveRefs same = testing::random_refs(300, 5);
  for (Box& b : same.boxes) b = same.boxes[0];
  check(build_sweep_sah(same), 10, "one box");
  // A child tied with its parent and numbered before it, so with the larger key: the walk
  // meets the parent first, and the k-th key (k = 1) is the child's.
  Bvh tied;
  tied.nodes.resize(9);
  auto inner = [&](uint32_t n, uint32_t l, uint32_t r, float size) {
    tied[n].make_inner(l, r);
    tied[n].set_box(Box(Vec3(0.0f), Vec3(size)));
    tied[l].parent = tied[r].parent = n;
  };
  for (uint32_t leaf = 4; leaf < 9; ++leaf) {
    tied[leaf].make_leaf(leaf - 4, 1);
    tied[leaf].set_box(Box(Vec3(0.0f), Vec3(0.25f)));
  }
  inner(0, 3, 1, 10.0f);
  inner(3, 2, 4, 1.0f);
  inner(2, 5, 6, 1.0f);
  inner(1, 7, 8, 0.5f);
  tied.root = 0;
  tied.ref_indices = {0, 1, 2, 3, 4};
  for (size_t k = 1; k <= 3; ++k) check(tied, k, "a child tied with its parent");
  // Nearly all one point: the k-th key 0, tied with the root's.
  PrimitiveRefs points = testing::random_refs(300, 6);
  for (size_t i = 10; i < points.boxes.size(); ++i) points.boxes[i] = Box(points.boxes[0].min, points.boxes[0].min);
  check(build_object_median(points), 100, "points");
  EXPECT_GT(walked, 2000);
  EXPECT_GT(from_threshold, 1000);
  EXPECT_GT(declined, 0);
}

// While the optimizer's moves change the tree, the walk keeps its threshold for k from one
// selection to the next, as it does from pass to pass, and still gives exactly the keys of a
// full sort.
TEST(LargestFromRoot, KeepsItsThresholdWhileMovesChangeTheTree) {
  const PrimitiveRefs refs = testing::random_refs(3000, 91);
  Bvh bvh = build_sweep_sah(refs);
  detail::LargestFromRoot walk;
  InsertionConfig config;
  config.form = InsertionForm::sequential;
  config.limits.max_passes = 3;
  config.batch = 0.1;
  int moves = 0, selections = 0, from_threshold = 0;
  testing::optimize_insertion_observed(bvh, config, [&](const Bvh& t, double) {
    if (++moves % 5 != 0) return;
    const AreaKeys key_of{t};
    for (size_t k : {size_t{40}, size_t{90}}) {
      std::vector<uint64_t> got;
      ASSERT_TRUE(walk.largest(t, k, key_of, got)) << "move " << moves;
      ++selections;
      from_threshold += walk.last_path() == detail::LargestFromRoot::Path::from_threshold;
      ASSERT_EQ(got, key_of.largest_by_sort(k)) << "move " << moves << ", k " << k;
    }
  });
  EXPECT_GT(selections, 100);
  EXPECT_GT(from_threshold, selections * 9 / 10);
}

// in_subtree stops its walk up at the first box outside the subtree's: it must say what a
// walk to the root says, for every pair of nodes, on built trees, on trees the optimizer has
// reshaped, and where boxes tie (copies of one box, zero-area points), so that containment
// says little.
TEST(InSubtree, AgreesWithTheWalkToTheRootForEveryPair) {
  int inside = 0;
  for (uint32_t trial = 0; trial < 12; ++trial) {
    PrimitiveRefs refs = testing::random_refs(40 + 13 * trial, 900 + trial);
    if (trial % 3 == 1)
      for (size_t i = 3; i < refs.boxes.size(); i += 3) refs.boxes[i] = refs.boxes[0];
    if (trial % 3 == 2)
      for (size_t i = 0; i < refs.boxes.size(); i += 2) refs.boxes[i] = Box(refs.boxes[1].min, refs.boxes[1].min);
    Bvh bvh = build_sweep_sah(refs);
    if (trial % 2 == 1) {
      InsertionConfig config;
      config.form = InsertionForm::parallel;
      config.limits.max_passes = 4;
      config.batch = 0.2;
      optimize_insertion(bvh, config);
    }
    ASSERT_TRUE(validate(bvh, refs).ok()) << "trial " << trial;
    for (uint32_t r = 0; r < bvh.nodes.size(); ++r)
      for (uint32_t x = 0; x < bvh.nodes.size(); ++x) {
        bool expected = false;
        for (uint32_t a = x; a != kInvalidNode; a = bvh[a].parent) expected = expected || a == r;
        inside += expected;
        ASSERT_EQ(detail::in_subtree(bvh, x, r), expected) << "trial " << trial << ", x " << x << ", subtree " << r;
      }
  }
  EXPECT_GT(inside, 1000);
}

// A threshold kept from another tree can gather far too many nodes (here every node of a
// tree of nearly equal boxes lies above the one a tree of random boxes left): the walks stop
// past their limit, on all threads, and the best-first walk still gives the keys of a full
// sort. One a little too high is walked again lower: the same keys.
TEST(LargestFromRoot, GivesTheSameKeysWhenAThresholdGathersFarTooManyOrTooFew) {
  detail::LargestFromRoot walk;
  const Bvh spread = build_sweep_sah(testing::random_refs(20000, 31));
  PrimitiveRefs near_refs = testing::random_refs(20000, 32);
  // Boxes of nearly the whole scene, each a little different: about 20k inner nodes whose
  // areas are all close to the root's, none tied.
  Box all = near_refs.boxes[0];
  for (const Box& b : near_refs.boxes) all = merge(all, b);
  for (size_t i = 0; i < near_refs.boxes.size(); ++i) {
    const float f = 0.9f + 0.1f * static_cast<float>(i) / static_cast<float>(near_refs.boxes.size());
    near_refs.boxes[i] = Box(all.min, all.min + (all.max - all.min) * f);
    near_refs.centroids[i] = near_refs.boxes[i].center();
  }
  const Bvh near_whole = build_sweep_sah(near_refs);
  for (size_t k : {size_t{8}, size_t{300}}) {
    for (const Bvh* bvh : {&spread, &near_whole, &spread, &near_whole}) {
      const AreaKeys key_of{*bvh};
      std::vector<uint64_t> got;
      ASSERT_TRUE(walk.largest(*bvh, k, key_of, got)) << "k " << k;
      EXPECT_EQ(got, key_of.largest_by_sort(k)) << "k " << k;
    }
    // A k asked for the first time starts from the threshold the tree of nearly equal boxes
    // left for k, far too high on the spread tree: lowered and walked again, then best first.
    const AreaKeys key_of{spread};
    std::vector<uint64_t> got;
    ASSERT_TRUE(walk.largest(spread, k + 1, key_of, got));
    EXPECT_EQ(got, key_of.largest_by_sort(k + 1)) << "k " << k + 1;
  }
}

// Algorithm 1 must find the same minimum as trying every node, including when a subtree
// is excluded (the parallel form's searches).
TEST(InsertionSearch, BranchAndBoundEqualsBruteForce) {
  std::mt19937_64 rng(12345);
  int with_exclusion = 0;
  for (uint32_t trial = 0; trial < 3000; ++trial) {
    const uint32_t count = 2 + static_cast<uint32_t>(rng() % 150);
    PrimitiveRefs refs = testing::random_refs(count, trial);
    Bvh bvh = build_start(refs, static_cast<int>(trial));
    // The query: a random box, sometimes tiny, sometimes larger than the whole scene.
    PrimitiveRefs q = testing::random_refs(1, 100000 + trial);
    Box box = q.boxes[0];
    if (trial % 5 == 0) box = Box(box.min * 0.5f - Vec3(5.0f), box.max * 1.5f);
    if (trial % 7 == 0) box = Box(box.min, box.min);  // a point
    uint32_t skip = kInvalidNode, through = kInvalidNode;
    if (trial % 2 == 1) {
      std::vector<uint32_t> inner;
      for (uint32_t n : bvh.depth_first_order())
        if (!bvh[n].is_leaf() && n != bvh.root) inner.push_back(n);
      if (!inner.empty()) {
        skip = inner[rng() % inner.size()];
        through = bvh[skip].parent;
        ++with_exclusion;
      }
    }
    ReinsertionCandidate fast = find_reinsertion(bvh, box, skip, through);
    ReinsertionCandidate slow = testing::find_reinsertion_brute_force(bvh, box, skip, through);
    ASSERT_NE(fast.node, kInvalidNode) << "trial " << trial;
    ASSERT_EQ(fast.cost, slow.cost) << "trial " << trial << " refs " << count;
    ASSERT_NE(fast.node, skip);
    ASSERT_NE(fast.node, through);
  }
  EXPECT_GT(with_exclusion, 1000);
}

// The removal-aware search (the parallel form's) must equal a brute-force scan of the tree
// after an actual removal, and its freed area must equal the drop in the sum of inner areas.
TEST(InsertionSearch, AfterRemovalEqualsBruteForceOnTheRemovedTree) {
  std::mt19937_64 rng(777);
  int checked = 0;
  for (uint32_t trial = 0; trial < 2000; ++trial) {
    const uint32_t count = 3 + static_cast<uint32_t>(rng() % 150);
    PrimitiveRefs refs = testing::random_refs(count, 20000 + trial);
    Bvh bvh = build_start(refs, static_cast<int>(trial));
    std::vector<uint32_t> inner;
    for (uint32_t n : bvh.depth_first_order())
      if (!bvh[n].is_leaf() && n != bvh.root) inner.push_back(n);
    if (inner.empty()) continue;
    const uint32_t n = inner[rng() % inner.size()];
    const Box box = bvh[trial % 2 ? bvh[n].left() : bvh[n].right()].box;
    double freed = 0.0;
    ReinsertionCandidate fast = find_reinsertion_after_removal(bvh, box, n, &freed);

    auto inner_sum = [](const Bvh& t, uint32_t from) {
      double sum = 0.0;
      std::vector<uint32_t> stack{from};
      while (!stack.empty()) {
        const uint32_t v = stack.back();
        stack.pop_back();
        if (t[v].is_leaf()) continue;
        sum += t[v].area();
        stack.push_back(t[v].left());
        stack.push_back(t[v].right());
      }
      return sum;
    };
    const double before = inner_sum(bvh, bvh.root);
    // What stays inner but leaves the tree with n: the subtrees below n's children.
    const double carried = inner_sum(bvh, bvh[n].left()) + inner_sum(bvh, bvh[n].right());
    Bvh removed = bvh;
    const uint32_t p = removed[n].parent, s = removed.sibling(n), g = removed[p].parent;
    if (g == kInvalidNode) {
      removed.root = s;
      removed[s].parent = kInvalidNode;
    } else {
      removed[g].set_child(removed.child_slot(p), s);
      removed[s].parent = g;
      removed.refit_upwards(g);
    }
    ReinsertionCandidate slow = testing::find_reinsertion_brute_force(removed, box);
    ASSERT_EQ(fast.cost, slow.cost) << "trial " << trial;
    ASSERT_NEAR(freed, before - inner_sum(removed, removed.root) - carried, 1e-9 * before) << "trial " << trial;
    ++checked;
  }
  EXPECT_GT(checked, 1900);
}

// The sequential form's search starts from a given node (the removed node's neighbourhood)
// with that node's cost as the first bound: it must still find the exhaustive minimum, from
// any start, and the start's cost must be the cost the search itself would give that node,
// also when taken from the start's nearby ancestors only (placement_cost_near).
TEST(InsertionSearch, SearchFromAnyStartEqualsBruteForce) {
  std::mt19937_64 rng(4242);
  std::vector<detail::SearchEntry> heap;
  std::vector<uint32_t> path;
  int start_kept = 0;
  for (uint32_t trial = 0; trial < 3000; ++trial) {
    const uint32_t count = 2 + static_cast<uint32_t>(rng() % 150);
    PrimitiveRefs refs = testing::random_refs(count, 50000 + trial);
    Bvh bvh = build_start(refs, static_cast<int>(trial));
    Box box = testing::random_refs(1, 90000 + trial).boxes[0];
    if (trial % 5 == 0) box = Box(box.min * 0.5f - Vec3(5.0f), box.max * 1.5f);
    const std::vector<uint32_t> all = bvh.depth_first_order();
    const uint32_t start = all[rng() % all.size()];
    const ReinsertionCandidate seed{start, detail::placement_cost(bvh, box, start, path)};
    // The optimizer's walk, cut short where an ancestor already contains the box, gives the
    // same cost to the last bit.
    ASSERT_EQ(detail::placement_cost_near(bvh, box, start, path), seed.cost) << "trial " << trial;
    const ReinsertionCandidate fast = detail::search_reinsertion(bvh, box, kInvalidNode, kInvalidNode, heap, seed);
    const ReinsertionCandidate slow = testing::find_reinsertion_brute_force(bvh, box);
    ASSERT_EQ(fast.cost, slow.cost) << "trial " << trial;
    ASSERT_EQ(detail::placement_cost(bvh, box, fast.node, path), fast.cost) << "trial " << trial;
    start_kept += fast.node == start;
  }
  // Starts that are already the best place happen, and are kept.
  EXPECT_GT(start_kept, 10);
}

// The regional passes' search: only inside the subtree of a region's root, the root itself
// excluded, for a box that came from that subtree. It must find the exhaustive minimum over
// those places, from any start inside, with costs that are the whole tree's placement costs
// (nothing above the root grows).
TEST(InsertionSearch, SearchInsideASubtreeEqualsBruteForceThere) {
  std::mt19937_64 rng(5151);
  std::vector<detail::SearchEntry> heap;
  std::vector<uint32_t> path;
  for (uint32_t trial = 0; trial < 2000; ++trial) {
    const uint32_t count = 4 + static_cast<uint32_t>(rng() % 150);
    PrimitiveRefs refs = testing::random_refs(count, 70000 + trial);
    Bvh bvh = build_start(refs, static_cast<int>(trial));
    std::vector<uint32_t> roots;
    for (uint32_t n : bvh.depth_first_order())
      if (!bvh[n].is_leaf()) roots.push_back(n);
    const uint32_t root = roots[rng() % roots.size()];
    std::vector<uint32_t> inside;  // the subtree without its root
    for (std::vector<uint32_t> stack{bvh[root].left(), bvh[root].right()}; !stack.empty();) {
      const uint32_t v = stack.back();
      stack.pop_back();
      inside.push_back(v);
      if (!bvh[v].is_leaf()) stack.insert(stack.end(), {bvh[v].left(), bvh[v].right()});
    }
    // A box from inside: one of the subtree's nodes, or a random part of the root's box.
    Box box = bvh[inside[rng() % inside.size()]].box;
    if (trial % 3 == 0) {
      const Box& r = bvh[root].box;
      std::uniform_real_distribution<float> u(0.0f, 1.0f);
      Vec3 a, b;
      for (int k = 0; k < 3; ++k) {
        const float lo = r.min[k], hi = r.max[k], s = u(rng), t = u(rng);
        a[k] = lo + std::min(s, t) * (hi - lo);
        b[k] = std::min(hi, lo + std::max(s, t) * (hi - lo));
      }
      box = Box(a, b);
    }
    const uint32_t start = inside[rng() % inside.size()];
    const ReinsertionCandidate seed{start, detail::placement_cost_near(bvh, box, start, path)};
    const ReinsertionCandidate fast = detail::search_reinsertion(bvh, box, kInvalidNode, root, heap, seed, root);
    double best = std::numeric_limits<double>::infinity();
    for (uint32_t x : inside) best = std::min(best, detail::placement_cost(bvh, box, x, path));
    ASSERT_EQ(fast.cost, best) << "trial " << trial;
    ASSERT_NE(std::find(inside.begin(), inside.end(), fast.node), inside.end()) << "trial " << trial;
    ASSERT_EQ(detail::placement_cost(bvh, box, fast.node, path), fast.cost) << "trial " << trial;
  }
}

// The undo log gives back exactly the tree of its restore point, whatever was changed after.
TEST(UndoLog, RestoresTheExactTree) {
  std::mt19937_64 rng(31);
  detail::UndoLog log;
  PrimitiveRefs refs = testing::random_refs(400, 5);
  Bvh bvh = build_sweep_sah(refs);
  for (int round = 0; round < 20; ++round) {
    const Bvh before = bvh;
    double sum = 1.5 * round;
    log.begin(bvh, sum);
    for (int change = 0; change < 1 + round * 10; ++change) {
      const uint32_t n = static_cast<uint32_t>(rng() % bvh.nodes.size());
      log.save(bvh, n);
      bvh[n].parent = static_cast<uint32_t>(rng());
      bvh[n].set_box(Box(Vec3(0.0f), Vec3(static_cast<float>(rng() % 100))));
    }
    bvh.root = static_cast<uint32_t>(rng() % bvh.nodes.size());
    sum = -1.0;
    log.restore(bvh, sum);
    ASSERT_EQ(sum, 1.5 * round);
    ASSERT_EQ(bvh.root, before.root);
    ASSERT_EQ(0, std::memcmp(bvh.nodes.data(), before.nodes.data(), bvh.nodes.size() * sizeof(BvhNode))) << round;
    // A node changed again after a restore is saved again (the marks were cleared).
    log.save(bvh, 0);
    EXPECT_EQ(log.size(), 1u);
    log.begin(bvh, sum);
    EXPECT_EQ(log.size(), 0u);
  }
}

// Lanes (the regional passes' records, saved by several threads at once into shares of the
// log's room) gather into the log: each node once, whichever lane or the log itself saved it
// first, also past a lane's share; a restore then gives back exactly the old tree.
TEST(UndoLog, LanesGatherIntoTheLogAndRestoreTheExactTree) {
  PrimitiveRefs refs = testing::random_refs(400, 6);
  Bvh bvh = build_sweep_sah(refs);
  const Bvh before = bvh;
  const uint32_t node_count = static_cast<uint32_t>(bvh.nodes.size());
  for (size_t room : {size_t{0}, size_t{40}, size_t{4000}}) {
    detail::UndoLog log;
    log.reserve(room);
    double sum = 2.5;
    log.begin(bvh, sum);
    for (uint32_t n = 0; n < 10; ++n) log.save(bvh, n);  // the log's own records
    // Four lanes, lane j taking the ids equal to j mod 4: neighbours in every word of the
    // marks belong to different threads. Lane 3 has no weight (no share: all overflow).
    std::vector<detail::UndoLog::Lane> lanes;
    log.open_lanes({5, 1, 2, 0}, lanes);
    tbb::parallel_for(0, 4, [&](int j) {
      for (uint32_t n = static_cast<uint32_t>(j); n < node_count; n += 4) {
        log.save(bvh, n, lanes[j]);
        log.save(bvh, n, lanes[j]);  // twice: still one record
        bvh[n].parent = ~n;
        bvh[n].set_box(Box(Vec3(0.0f), Vec3(static_cast<float>(n))));
      }
    });
    log.close_lanes(lanes);
    ASSERT_EQ(log.size(), node_count) << "room " << room;
    bvh.root = 3;
    sum = -1.0;
    log.restore(bvh, sum);
    ASSERT_EQ(sum, 2.5);
    ASSERT_EQ(bvh.root, before.root);
    ASSERT_EQ(0, std::memcmp(bvh.nodes.data(), before.nodes.data(), bvh.nodes.size() * sizeof(BvhNode))) << room;
  }
}

// The sequential form oscillates near its end and must leave the lowest-cost tree of all its
// passes, which it gets back through the undo log: the final tree must be, node for node,
// the tree seen at the end of the best pass. (When the log fills up mid-pass below the best
// cost, that better tree becomes the restore point: then the final cost is lower still.)
TEST(InsertionOptimizer, SequentialEndsOnTheBestPassTree) {
  int restored = 0, exact = 0;
  for (uint64_t seed = 0; seed < 16; ++seed) {
    PrimitiveRefs refs = testing::random_refs(600, 70 + seed);
    Bvh bvh = build_object_median(refs);
    InsertionConfig cfg;
    cfg.form = InsertionForm::sequential;
    cfg.seed = seed;
    cfg.batch = seed % 4 == 3 ? 0.2 : 0.01;
    cfg.random_after = 1;
    cfg.stop_after = 8;
    cfg.limits.max_passes = 80;
    Bvh last_move;
    Bvh best_tree = bvh;
    double best = sah_cost(bvh, cfg.cost), last_pass = best;
    cfg.limits.on_pass = [&](const PassRecord& p) {
      last_pass = p.cost;
      if (p.cost < best) {
        best = p.cost;
        best_tree = last_move;
      }
    };
    OptimizeReport r = testing::optimize_insertion_observed(bvh, cfg, [&](const Bvh& t, double) { last_move = t; });
    restored += last_pass > best;
    ASSERT_TRUE(validate(bvh, refs).ok());
    EXPECT_LE(r.final_cost, best) << seed;
    EXPECT_NEAR(sah_cost(bvh, cfg.cost), r.final_cost, 1e-9 * best);
    if (r.final_cost == best) {
      ++exact;
      best_tree.renumber_depth_first();
      EXPECT_EQ(testing::tree_signature(bvh, refs), testing::tree_signature(best_tree, refs)) << seed;
    }
  }
  // Runs ended above their best, so the restore was exercised, mostly onto the best pass's tree.
  EXPECT_GE(restored, 4) << exact;
  EXPECT_GE(exact, 8) << restored;
}

// Brute force on a hand-made tree: the best place is the leaf the new box overlaps.
TEST(InsertionSearch, HandExample) {
  PrimitiveRefs refs = make_references({Box({0, 0, 0}, {1, 1, 1}), Box({10, 0, 0}, {11, 1, 1}),
                                        Box({20, 0, 0}, {21, 1, 1}), Box({30, 0, 0}, {31, 1, 1})});
  Bvh bvh = build_object_median(refs);
  ReinsertionCandidate c = find_reinsertion(bvh, Box({30.2f, 0, 0}, {30.8f, 1, 1}));
  ASSERT_TRUE(bvh[c.node].is_leaf());
  EXPECT_EQ(refs.boxes[bvh.ref_indices[bvh[c.node].first_ref()]].min.x, 30.0f);
  // Merged with the leaf: SA = 6, nothing above grows.
  EXPECT_DOUBLE_EQ(c.cost, 6.0);
}

void check_every_move(InsertionForm form, InsertionMeasure measure) {
  PrimitiveRefs refs = testing::random_refs(400, 7 + static_cast<int>(form));
  Bvh bvh = build_spatial_median(refs);
  InsertionConfig cfg;
  cfg.form = form;
  cfg.measure = measure;
  cfg.batch = 0.05;
  cfg.limits.max_passes = 30;
  // The regional form's first two stages end at their first pass without a gain, so that
  // most of the 30 passes are regional.
  if (form == InsertionForm::regional) cfg.random_after = 1;
  uint64_t checked = 0;
  auto after_move = [&](const Bvh& t, double tracked) {
    ValidationReport v = validate(t, refs);
    ASSERT_TRUE(v.ok()) << v.summary();
    ASSERT_EQ(t.nodes.size(), 2 * refs.size() - 1);
    ASSERT_LT(testing::relative_gap(tracked, sah_cost(t)), 1e-9) << tracked << " vs " << sah_cost(t);
    ++checked;
  };
  OptimizeReport r = testing::optimize_insertion_observed(bvh, cfg, after_move);
  EXPECT_GT(checked, 20u);
  EXPECT_TRUE(validate(bvh, refs).ok());
  EXPECT_LT(testing::relative_gap(r.final_cost, sah_cost(bvh)), 1e-9);
  EXPECT_LT(r.final_cost, r.initial_cost * 0.99);
}

TEST(InsertionOptimizer, ValidAndCostTrackedAfterEveryMoveSequential) {
  check_every_move(InsertionForm::sequential, InsertionMeasure::area);
}
TEST(InsertionOptimizer, ValidAndCostTrackedAfterEveryMoveParallel) {
  check_every_move(InsertionForm::parallel, InsertionMeasure::area);
}
TEST(InsertionOptimizer, ValidAndCostTrackedAfterEveryMoveHybrid) {
  check_every_move(InsertionForm::hybrid, InsertionMeasure::area);
}
TEST(InsertionOptimizer, ValidAndCostTrackedAfterEveryMoveRegional) {
  check_every_move(InsertionForm::regional, InsertionMeasure::area);
}
TEST(InsertionOptimizer, ValidWithEveryMeasure) {
  for (InsertionMeasure m : {InsertionMeasure::sum, InsertionMeasure::min, InsertionMeasure::comb}) {
    check_every_move(InsertionForm::parallel, m);
    check_every_move(InsertionForm::sequential, m);
  }
}

TEST(InsertionOptimizer, ParallelFormNeverRaisesTheCost) {
  PrimitiveRefs refs = testing::random_refs(3000, 3);
  Bvh bvh = build_sweep_sah(refs);
  InsertionConfig cfg;
  cfg.form = InsertionForm::parallel;
  OptimizeReport r = optimize_insertion(bvh, cfg);
  ASSERT_FALSE(r.trace.empty());
  double prev = r.initial_cost;
  for (const PassRecord& p : r.trace) {
    EXPECT_LE(p.cost, prev * (1 + 1e-12)) << "pass " << p.pass;
    prev = p.cost;
  }
  EXPECT_LT(r.final_cost, r.initial_cost);
}

// Small inputs against the exact optimum (dynamic programming over subsets). Greedy
// reinsertion is not guaranteed to find it; the test demands that it never reports less
// than the optimum (which would mean a wrong cost), reaches it in most cases and stays
// close on average.
TEST(InsertionOptimizer, CloseToTheExactOptimumOnSmallInputs) {
  for (InsertionForm form :
       {InsertionForm::sequential, InsertionForm::parallel, InsertionForm::hybrid, InsertionForm::regional}) {
    int cases = 0, optimal = 0;
    double gap_sum = 0.0, worst = 0.0;
    for (uint32_t seed = 0; seed < 300; ++seed) {
      const uint32_t count = 3 + seed % 8;  // 3..10 references
      PrimitiveRefs refs = testing::random_refs(count, 5000 + seed);
      Bvh bvh = build_start(refs, static_cast<int>(seed));
      InsertionConfig cfg;
      cfg.form = form;
      cfg.seed = seed;
      // On a handful of nodes 1 % means one node per pass; every node per pass and a
      // longer patience give the local search a fair chance.
      cfg.batch = 1.0;
      cfg.stop_after = 30;
      OptimizeReport r = optimize_insertion(bvh, cfg);
      ASSERT_TRUE(validate(bvh, refs).ok());
      const double root_area = bvh[bvh.root].area();
      const double opt = testing::optimal_tree_cost(refs, 3, 2) / root_area;
      ASSERT_GE(r.final_cost, opt * (1 - 1e-9)) << "below the optimum: seed " << seed;
      const double gap = r.final_cost / opt - 1.0;
      gap_sum += gap;
      worst = std::max(worst, gap);
      optimal += gap < 1e-9;
      ++cases;
    }
    const double mean_gap = gap_sum / cases;
    std::printf("%s: optimal in %d of %d, mean gap %.4f%%, worst %.3f%%\n", std::string(form_name(form)).c_str(),
                optimal, cases, 100 * mean_gap, 100 * worst);
    // Measured: sequential 287/300 optimal, mean gap 0.07 %, worst 7.8 % (hybrid 288/300,
    // 0.07 %, 7.8 %); the parallel form never accepts a worse move, so it sticks in more
    // local minima: 244/300, 0.8 %, 14.4 %.
    if (form == InsertionForm::parallel) {
      EXPECT_GE(optimal, cases * 75 / 100);
      EXPECT_LT(mean_gap, 0.015);
      EXPECT_LT(worst, 0.25);
    } else {
      EXPECT_GE(optimal, cases * 90 / 100);
      EXPECT_LT(mean_gap, 0.005);
      EXPECT_LT(worst, 0.10);
    }
  }
}

TEST(InsertionOptimizer, SameTreeOnOneAndTwoThreads) {
  PrimitiveRefs refs = testing::random_refs(6000, 11);
  for (InsertionForm form : {InsertionForm::parallel, InsertionForm::hybrid, InsertionForm::regional}) {
    std::string sig[2];
    double cost[2];
    uint32_t passes[2];
    for (int t = 0; t < 2; ++t) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, t + 1);
      Bvh bvh = build_spatial_median(refs);
      InsertionConfig cfg;
      cfg.form = form;
      cfg.seed = 99;
      cfg.limits.max_passes = 400;
      cfg.random_after = 1;         // random passes too
      cfg.stop_after = 4;           // so that both stages end well within the pass limit
      cfg.min_improvement = 1e-3;
      OptimizeReport r = optimize_insertion(bvh, cfg);
      sig[t] = testing::tree_signature(bvh, refs);
      cost[t] = r.final_cost;
      passes[t] = r.passes;
      // Enough moves for the thread count to matter (the parallel form makes 98 here).
      EXPECT_GT(r.moves, 50u);
      // Both stages of the hybrid ran to convergence within the pass limit.
      EXPECT_EQ(r.stop_reason, StopReason::converged);
      EXPECT_LT(r.passes, cfg.limits.max_passes);
    }
    EXPECT_EQ(passes[0], passes[1]);
    EXPECT_EQ(cost[0], cost[1]);
    EXPECT_EQ(sig[0], sig[1]) << form_name(form);
  }
}

// A node array of several megabytes, whose parallel passes plan many groups of candidates
// on each thread: the tree and every pass's cost stay those of one thread, and the tree
// stays valid.
TEST(InsertionOptimizer, SameTreeOnOneAndTwoThreadsOnALargeArray) {
  PrimitiveRefs refs = testing::random_refs(80000, 13);
  std::string sig[2];
  std::vector<double> trace[2];
  for (int t = 0; t < 2; ++t) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, t + 1);
    Bvh bvh = build_sweep_sah(refs);
    ASSERT_GT(bvh.nodes.size() * sizeof(BvhNode), size_t(4) << 20);
    InsertionConfig cfg;
    cfg.seed = 5;
    cfg.limits.max_passes = 6;
    OptimizeReport r = optimize_insertion(bvh, cfg);
    ASSERT_TRUE(validate(bvh, refs).ok());
    EXPECT_LT(r.final_cost, r.initial_cost);
    for (const PassRecord& p : r.trace) trace[t].push_back(p.cost);
    sig[t] = testing::tree_signature(bvh, refs);
  }
  EXPECT_EQ(trace[0], trace[1]);
  EXPECT_EQ(sig[0], sig[1]);
}

TEST(InsertionOptimizer, SameSeedSameTreeSequential) {
  PrimitiveRefs refs = testing::random_refs(2000, 12);
  std::string sig[2];
  for (int t = 0; t < 2; ++t) {
    Bvh bvh = build_object_median(refs);
    InsertionConfig cfg;
    cfg.form = InsertionForm::sequential;
    cfg.random_after = 1;
    cfg.limits.max_passes = 30;
    optimize_insertion(bvh, cfg);
    sig[t] = testing::tree_signature(bvh, refs);
  }
  EXPECT_EQ(sig[0], sig[1]);
}

// The sequential form may raise the cost slightly (both children out at once) and then
// oscillates; the pass limit must still end the run.
TEST(InsertionOptimizer, PassLimitEndsAnOscillatingRun) {
  PrimitiveRefs refs = testing::random_refs(500, 13);
  for (InsertionForm form :
       {InsertionForm::sequential, InsertionForm::parallel, InsertionForm::hybrid, InsertionForm::regional}) {
    Bvh bvh = build_sweep_sah(refs);
    InsertionConfig cfg;
    cfg.form = form;
    cfg.stop_after = std::numeric_limits<uint32_t>::max();
    cfg.limits.max_passes = 200;
    cfg.batch = 0.2;
    uint32_t callbacks = 0;
    cfg.limits.on_pass = [&](const PassRecord&) { ++callbacks; };
    OptimizeReport r = optimize_insertion(bvh, cfg);
    EXPECT_EQ(r.passes, 200u);
    EXPECT_EQ(callbacks, 200u);
    EXPECT_EQ(r.trace.size(), 200u);
    EXPECT_EQ(r.stop_reason, StopReason::pass_limit);
    EXPECT_TRUE(validate(bvh, refs).ok());
  }
}

// The trace's passes, one list per stage; the stage numbers must run 0, 1, ... in order.
std::vector<std::vector<PassRecord>> passes_by_stage(const OptimizeReport& r) {
  std::vector<std::vector<PassRecord>> stages;
  for (const PassRecord& p : r.trace) {
    EXPECT_TRUE(p.stage == stages.size() || p.stage + 1 == stages.size()) << "pass " << p.pass;
    if (p.stage == stages.size()) stages.emplace_back();
    stages.back().push_back(p);
  }
  return stages;
}

// Passes at the end of `stage` (of a run that began at `start` cost) that each fail to lower
// the stage's best by more than the margin.
uint32_t trailing_stalls(const std::vector<PassRecord>& stage, double start, double margin) {
  double best = start;
  uint32_t stalls = 0;
  for (const PassRecord& p : stage) {
    stalls = p.cost < best * (1.0 - margin) ? 0 : stalls + 1;
    best = std::min(best, p.cost);
  }
  return stalls;
}

// Where each stage ends, read from the trace's stage numbers: the hybrid form's stages
// (sequential, parallel, rotation sweeps) and the regional form's seven (parallel and
// sequential by the measure, sweeps, regional, sweeps, parallel, sweeps) run in order, and
// the regional form's sequential stage (its second) hands over at its second pass in a row
// that does not lower the stage's best cost by the hand-over margin, or at the first where
// random_after is 1. Without rotations, the insertion stages alone.
TEST(InsertionOptimizer, StagesRunInOrderAndTheSequentialStageHandsOverAfterTwoStalls) {
  constexpr double kHandOverMargin = 3e-4;  // the optimizer's, for stages that hand over
  for (uint32_t random_after : {5u, 1u}) {
    PrimitiveRefs refs = testing::random_refs(3000, 31);
    Bvh bvh = build_sweep_sah(refs);
    InsertionConfig cfg;
    cfg.form = InsertionForm::regional;
    cfg.random_after = random_after;
    OptimizeReport r = optimize_insertion(bvh, cfg);
    ASSERT_EQ(r.stop_reason, StopReason::converged);
    const std::vector<std::vector<PassRecord>> stages = passes_by_stage(r);
    ASSERT_EQ(stages.size(), 7u);
    // The sequential stage starts from the tree the first stage left.
    const double start = stages[0].back().best_cost;
    EXPECT_EQ(trailing_stalls(stages[1], start, kHandOverMargin), std::min(random_after, 2u))
        << "random_after " << random_after << ", " << stages[1].size() << " sequential passes";
    // The first stage keeps the config's patience.
    EXPECT_EQ(trailing_stalls(stages[0], r.initial_cost, kHandOverMargin), random_after);
    // Each stage of sweeps never raises the cost, and ends at its first sweep that gains
    // less than the margin.
    for (size_t k : {2u, 4u, 6u}) {
      double prev = stages[k - 1].back().best_cost;
      const double stage_start = prev;
      for (const PassRecord& p : stages[k]) {
        EXPECT_LE(p.cost, prev) << "stage " << k << ", pass " << p.pass;
        prev = p.cost;
      }
      EXPECT_EQ(trailing_stalls(stages[k], stage_start, kHandOverMargin), 1u) << "stage " << k;
    }
    bvh = build_sweep_sah(refs);
    cfg.rotations = false;
    r = optimize_insertion(bvh, cfg);
    EXPECT_EQ(passes_by_stage(r).size(), 4u);
    // Without the parallel start, the sequential passes by the measure come first: each
    // updates the batch's candidates one by one (a parallel pass applies only some).
    bvh = build_sweep_sah(refs);
    cfg.rotations = true;
    cfg.parallel_start = false;
    r = optimize_insertion(bvh, cfg);
    const std::vector<std::vector<PassRecord>> without = passes_by_stage(r);
    ASSERT_EQ(without.size(), 6u);
    const uint64_t batch = static_cast<uint64_t>(std::ceil(cfg.batch * (refs.size() - 1)));
    EXPECT_EQ(without[0].front().moves, batch);
    EXPECT_LT(stages[0].front().moves, batch);
    cfg.parallel_start = true;
  }
  PrimitiveRefs refs = testing::random_refs(3000, 32);
  Bvh bvh = build_sweep_sah(refs);
  InsertionConfig cfg;
  cfg.form = InsertionForm::hybrid;
  OptimizeReport r = optimize_insertion(bvh, cfg);
  EXPECT_EQ(passes_by_stage(r).size(), 3u);
  cfg.rotations = false;
  bvh = build_sweep_sah(refs);
  r = optimize_insertion(bvh, cfg);
  EXPECT_EQ(passes_by_stage(r).size(), 2u);
  cfg.form = InsertionForm::parallel;
  cfg.rotations = true;  // the paper's forms never sweep
  r = optimize_insertion(bvh, cfg);
  EXPECT_EQ(passes_by_stage(r).size(), 1u);
}

// The hybrid form's sweeps come after its insertion stages, which run as they would
// without them: the final tree can only be cheaper, and every sweep keeps the tree valid
// and its tracked cost that of a recount (also in the regional form, whose sweeps run in
// parallel over its regions).
TEST(InsertionOptimizer, RotationSweepsOnlyLowerTheTreeAndKeepItValid) {
  for (int seed : {41, 42, 43}) {
    PrimitiveRefs refs = testing::random_refs(2000, seed);
    double final_cost[2];
    for (int rotations = 0; rotations < 2; ++rotations) {
      Bvh bvh = build_sweep_sah(refs);
      InsertionConfig cfg;
      cfg.form = InsertionForm::hybrid;
      cfg.rotations = rotations == 1;
      uint64_t checked = 0;
      auto after_move = [&](const Bvh& t, double tracked) {
        ValidationReport v = validate(t, refs);
        ASSERT_TRUE(v.ok()) << v.summary();
        ASSERT_LT(testing::relative_gap(tracked, sah_cost(t)), 1e-9) << tracked << " vs " << sah_cost(t);
        ++checked;
      };
      OptimizeReport r = testing::optimize_insertion_observed(bvh, cfg, after_move);
      ASSERT_EQ(r.stop_reason, StopReason::converged);
      EXPECT_GT(checked, 0u);
      EXPECT_LT(testing::relative_gap(r.final_cost, sah_cost(bvh)), 1e-9);
      final_cost[rotations] = r.final_cost;
    }
    EXPECT_LE(final_cost[1], final_cost[0]) << "seed " << seed;
  }
  // The regional form, to convergence: its sweeps run over several regions.
  PrimitiveRefs refs = testing::random_refs(6000, 44);
  Bvh bvh = build_spatial_median(refs);
  InsertionConfig cfg;
  cfg.form = InsertionForm::regional;
  cfg.random_after = 1;
  cfg.stop_after = 3;
  uint32_t sweeps = 0;
  auto after_move = [&](const Bvh& t, double tracked) {
    ASSERT_TRUE(validate(t, refs).ok());
    ASSERT_LT(testing::relative_gap(tracked, sah_cost(t)), 1e-9) << tracked << " vs " << sah_cost(t);
  };
  cfg.limits.on_pass = [&](const PassRecord& p) { sweeps += p.stage == 2 || p.stage == 4 || p.stage == 6; };
  OptimizeReport r = testing::optimize_insertion_observed(bvh, cfg, after_move);
  EXPECT_EQ(r.stop_reason, StopReason::converged);
  EXPECT_GE(sweeps, 3u);
  EXPECT_TRUE(validate(bvh, refs).ok());
}

TEST(InsertionOptimizer, ConvergesWithoutAPassLimit) {
  PrimitiveRefs refs = testing::random_refs(1000, 14);
  Bvh bvh = build_sweep_sah(refs);
  InsertionConfig cfg;
  cfg.limits.max_passes = std::numeric_limits<uint32_t>::max();
  OptimizeReport r = optimize_insertion(bvh, cfg);
  EXPECT_EQ(r.stop_reason, StopReason::converged);
  double lowest = r.initial_cost;
  for (const PassRecord& p : r.trace) lowest = std::min(lowest, p.cost);
  EXPECT_EQ(r.trace.back().best_cost, lowest);
}

// The paper's observation: from a spatial-median tree the optimizer ends close to where it
// ends from an SAH tree.
TEST(InsertionOptimizer, SpatialMedianStartApproachesSahStart) {
  Mesh mesh = testing::random_mesh(20000, 21);
  PrimitiveRefs refs = make_references(mesh);
  Bvh sah = build_sweep_sah(refs);
  Bvh med = build_spatial_median(refs);
  const double sah_start = sah_cost(sah), med_start = sah_cost(med);
  OptimizeReport rs = optimize_insertion(sah);
  OptimizeReport rm = optimize_insertion(med);
  std::printf("SAH start %.3f -> %.3f; spatial median start %.3f -> %.3f\n", sah_start, rs.final_cost, med_start,
              rm.final_cost);
  EXPECT_LT(rs.final_cost, sah_start);
  EXPECT_LT(rm.final_cost, sah_start * 1.03);
  EXPECT_LT(rm.final_cost, rs.final_cost * 1.01);  // measured: 0.3 % apart
}

TEST(InsertionOptimizer, TinyTreesAreLeftAlone) {
  for (uint32_t count : {1u, 2u}) {
    PrimitiveRefs refs = testing::random_refs(count, count);
    Bvh bvh = build_sweep_sah(refs);
    std::string before = testing::tree_signature(bvh, refs);
    OptimizeReport r = optimize_insertion(bvh);
    EXPECT_EQ(r.stop_reason, StopReason::nothing_to_optimize);
    EXPECT_EQ(testing::tree_signature(bvh, refs), before);
  }
}

// The candidates around the last pass's moves: exactly the inner non-root nodes among the
// moved ones and their parents and grandparents, each once, in the order the moves list
// them, and no more than the limit.
TEST(NearMoves, TheMovedNodesAndTheirTwoAncestorsOnceEachUpToTheLimit) {
  const PrimitiveRefs refs = testing::random_refs(500, 17);
  const Bvh bvh = build_sweep_sah(refs);
  detail::NodeBits inner;
  inner.reset(bvh.nodes.size());
  for (uint32_t i = 0; i < bvh.nodes.size(); ++i)
    if (!bvh.nodes[i].is_leaf()) inner.insert(i);
  std::mt19937 rng(3);
  std::uniform_int_distribution<uint32_t> pick(0, static_cast<uint32_t>(bvh.nodes.size() - 1));
  std::vector<uint32_t> moved;
  for (int i = 0; i < 60; ++i) moved.push_back(pick(rng));
  moved.push_back(bvh.root);
  moved.push_back(moved.front());  // listed twice
  // The expectation, spelled out: each moved node, then its parent, then its grandparent.
  std::vector<uint32_t> expected;
  for (uint32_t v : moved) {
    const uint32_t p = bvh[v].parent;
    const uint32_t g = p == kInvalidNode ? kInvalidNode : bvh[p].parent;
    for (uint32_t u : {v, p, g})
      if (u != kInvalidNode && u != bvh.root && !bvh[u].is_leaf() &&
          std::find(expected.begin(), expected.end(), u) == expected.end())
        expected.push_back(u);
  }
  ASSERT_GT(expected.size(), 40u);
  detail::NodeSet seen;
  for (size_t limit : {expected.size() + 10, expected.size(), size_t{25}, size_t{0}}) {
    std::vector<uint32_t> out = {7};  // appended to, never cleared
    detail::append_near_moves(bvh, moved, inner, limit + 1, seen, out);
    ASSERT_EQ(out.front(), 7u);
    out.erase(out.begin());
    const size_t n = std::min(limit, expected.size());
    EXPECT_EQ(out, std::vector<uint32_t>(expected.begin(), expected.begin() + n)) << "limit " << limit;
  }
}

// hybrid is the regional form from kRegionalFrom nodes on, and only hybrid resolves.
TEST(InsertionOptimizer, HybridResolvesToRegionalOnLargeTrees) {
  EXPECT_EQ(resolved_form(InsertionForm::hybrid, kRegionalFrom - 1), InsertionForm::hybrid);
  EXPECT_EQ(resolved_form(InsertionForm::hybrid, kRegionalFrom), InsertionForm::regional);
  for (InsertionForm f : {InsertionForm::sequential, InsertionForm::parallel, InsertionForm::regional}) {
    EXPECT_EQ(resolved_form(f, 5), f);
    EXPECT_EQ(resolved_form(f, kRegionalFrom * 4), f);
  }
}

TEST(InsertionOptimizer, MeasureNames) {
  for (InsertionMeasure m : {InsertionMeasure::area, InsertionMeasure::sum, InsertionMeasure::min, InsertionMeasure::comb})
    EXPECT_EQ(parse_measure(measure_name(m)), m);
  EXPECT_FALSE(parse_measure("volume").has_value());
  for (InsertionForm f : insertion_forms()) EXPECT_EQ(parse_form(form_name(f)), f);
  EXPECT_EQ(insertion_forms().size(), 4u);
  EXPECT_FALSE(parse_form("greedy").has_value());
}

}  // namespace
}  // namespace bvhopt
