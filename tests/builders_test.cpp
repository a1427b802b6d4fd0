// Every builder over many random scenes: tree invariants, exact costs, the optimal-tree
// oracle, a brute-force reference for the sweep, and the same tree on 1 and 2 threads.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace bvhopt {
namespace {

using testing::optimal_tree_cost;
using testing::random_mesh;
using testing::random_refs;
using testing::tree_signature;

Bvh build_with(BuilderKind kind, const PrimitiveRefs& refs, uint32_t max_leaf, uint32_t parallel_threshold) {
  LeafConfig leaf{max_leaf};
  switch (kind) {
    case BuilderKind::sweep_sah: {
      SweepSahConfig c;
      c.leaf = leaf;
      c.parallel_threshold = parallel_threshold;
      // Low enough that the three-axes-at-once path runs in the tests too.
      c.parallel_split_threshold = std::max<uint32_t>(parallel_threshold, 64);
      return build_sweep_sah(refs, c);
    }
    case BuilderKind::binned_sah: {
      BinnedSahConfig c;
      c.leaf = leaf;
      c.parallel_threshold = parallel_threshold;
      // Low enough that the parallel binning path runs in the tests too.
      c.parallel_binning_threshold = std::max<uint32_t>(parallel_threshold, 64);
      return build_binned_sah(refs, c);
    }
    case BuilderKind::spatial_median: {
      MedianConfig c;
      c.leaf = leaf;
      c.parallel_threshold = parallel_threshold;
      return build_spatial_median(refs, c);
    }
    case BuilderKind::object_median: {
      MedianConfig c;
      c.leaf = leaf;
      c.parallel_threshold = parallel_threshold;
      return build_object_median(refs, c);
    }
    case BuilderKind::spatial_split: break;  // needs triangles: spatial_split_test.cpp
  }
  return {};
}

// Invariants checked independently of validate(): every reference in exactly one leaf,
// links agree, boxes are exact unions, leaf sizes within the limit, nodes all reachable.
void check_tree(const Bvh& bvh, const PrimitiveRefs& refs, uint32_t max_leaf, const std::string& what) {
  SCOPED_TRACE(what);
  ValidationReport report = validate(bvh, refs);
  ASSERT_TRUE(report.ok()) << report.summary();
  if (refs.empty()) {
    EXPECT_TRUE(bvh.empty());
    return;
  }
  ASSERT_FALSE(bvh.empty());
  ASSERT_EQ(bvh[bvh.root].parent, kInvalidNode);
  std::vector<int> seen(refs.size(), 0);
  size_t reached = 0;
  std::vector<uint32_t> stack{bvh.root};
  while (!stack.empty()) {
    uint32_t n = stack.back();
    stack.pop_back();
    ASSERT_LT(n, bvh.nodes.size());
    ++reached;
    const BvhNode& nd = bvh[n];
    ASSERT_EQ(nd.area(), nd.box.area()) << "node " << n;
    Box expect;
    if (nd.is_leaf()) {
      ASSERT_GE(nd.ref_count(), 1u) << "node " << n;
      ASSERT_LE(nd.ref_count(), max_leaf) << "node " << n;
      ASSERT_LE(size_t(nd.first_ref()) + nd.ref_count(), bvh.ref_indices.size());
      for (uint32_t i = 0; i < nd.ref_count(); ++i) {
        uint32_t id = bvh.ref_indices[nd.first_ref() + i];
        ASSERT_LT(id, refs.size());
        ++seen[id];
        expect.extend(refs.boxes[id]);
      }
    } else {
      for (int c = 0; c < 2; ++c) {
        ASSERT_LT(nd.child(c), bvh.nodes.size());
        ASSERT_EQ(bvh[nd.child(c)].parent, n) << "node " << n;
        expect.extend(bvh[nd.child(c)].box);
        stack.push_back(nd.child(c));
      }
    }
    ASSERT_EQ(nd.box, expect) << "node " << n;
  }
  // The builders compact their trees: no unused nodes are left behind.
  EXPECT_EQ(reached, bvh.nodes.size());
  for (size_t i = 0; i < refs.size(); ++i) ASSERT_EQ(seen[i], 1) << "reference " << i;
}

// The SAH cost recomputed from scratch, boxes from the references, not from the nodes.
double cost_from_scratch(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& m) {
  double total = 0.0;
  auto rec = [&](auto&& self, uint32_t n) -> Box {
    const BvhNode& nd = bvh[n];
    Box b;
    if (nd.is_leaf()) {
      for (uint32_t i = 0; i < nd.ref_count(); ++i) b.extend(refs.boxes[bvh.ref_indices[nd.first_ref() + i]]);
      total += m.intersection * double(b.area()) * nd.ref_count();
    } else {
      b = merge(self(self, nd.left()), self(self, nd.right()));
      total += m.traversal * double(b.area());
    }
    return b;
  };
  Box root = rec(rec, bvh.root);
  return total / double(root.area());
}

std::string name_of(BuilderKind k) { return std::string(builder_name(k)); }

TEST(Builders, RandomScenesGiveValidTreesWithExactCosts) {
  for (BuilderKind kind : all_builders()) {
    for (uint32_t max_leaf : {1u, 4u}) {
      for (uint64_t seed = 0; seed < 12; ++seed) {
        uint32_t count = 1 + static_cast<uint32_t>((seed * 977) % 3000);
        PrimitiveRefs refs = seed % 2 ? random_refs(count, seed)
                                      : make_references(random_mesh(count, seed, /*with_degenerate=*/true));
        Bvh bvh = build_with(kind, refs, max_leaf, 256);
        std::string what = name_of(kind) + " leaf " + std::to_string(max_leaf) + " seed " + std::to_string(seed);
        check_tree(bvh, refs, max_leaf, what);
        if (::testing::Test::HasFatalFailure()) return;
        double reported = sah_cost(bvh);
        EXPECT_NEAR(cost_from_scratch(bvh, refs, {}), reported, 1e-9 * reported) << what;
      }
    }
  }
}

TEST(Builders, NoBuilderBeatsTheOptimalTree) {
  const CostModel m;
  for (BuilderKind kind : all_builders()) {
    for (uint32_t count = 2; count <= 10; ++count) {
      for (uint64_t seed = 0; seed < 25; ++seed) {
        PrimitiveRefs refs = random_refs(count, 1000 * count + seed);
        Bvh bvh = build_with(kind, refs, 1, 4096);
        double ours = sah_cost(bvh, m) * double(bvh[bvh.root].area());
        double best = optimal_tree_cost(refs, m.traversal, m.intersection);
        EXPECT_GE(ours, best * (1.0 - 1e-6)) << name_of(kind) << " n=" << count << " seed " << seed;
      }
    }
  }
}

TEST(Builders, SahBuildersComeCloseToTheOptimumOnTinyInputs) {
  // Not a bound the algorithms guarantee, but a broken sweep or binning lands far above.
  const CostModel m;
  for (BuilderKind kind : {BuilderKind::sweep_sah, BuilderKind::binned_sah}) {
    double ratio_sum = 0.0;
    int runs = 0;
    for (uint32_t count = 4; count <= 10; ++count)
      for (uint64_t seed = 0; seed < 10; ++seed) {
        PrimitiveRefs refs = random_refs(count, 77 * count + seed);
        Bvh bvh = build_with(kind, refs, 1, 4096);
        ratio_sum += sah_cost(bvh, m) * double(bvh[bvh.root].area()) / optimal_tree_cost(refs, m.traversal, m.intersection);
        ++runs;
      }
    EXPECT_LT(ratio_sum / runs, 1.10) << name_of(kind);
  }
}

// The textbook top-down sweep: per node, sort the node's references on each axis by
// (centroid, id) and try every position, with the tie rules the builder documents.
// O(n^2 log n), written for clarity only.
std::string brute_force_sweep(const PrimitiveRefs& refs, uint32_t max_leaf, const CostModel& m) {
  auto sorted_by = [&](std::vector<uint32_t> ids, int a) {
    std::sort(ids.begin(), ids.end(), [&](uint32_t x, uint32_t y) {
      float cx = refs.centroids[x][a] + 0.0f, cy = refs.centroids[y][a] + 0.0f;
      return cx < cy || (cx == cy && x < y);
    });
    return ids;
  };
  auto bounds = [&](const std::vector<uint32_t>& ids, size_t from, size_t to) {
    Box b;
    for (size_t k = from; k < to; ++k) b.extend(refs.boxes[ids[k]]);
    return b;
  };
  auto rec = [&](auto&& self, const std::vector<uint32_t>& ids) -> std::string {
    const size_t count = ids.size();
    std::vector<uint32_t> by_x = sorted_by(ids, 0);
    auto leaf = [&] {
      std::string s = "[";
      for (size_t k = 0; k < count; ++k) {
        if (k) s += ' ';
        s += std::to_string(refs.triangle_ids[by_x[k]]);
      }
      return s + "]";
    };
    if (count == 1) return leaf();
    bool coincide = true;
    for (int a = 0; a < 3; ++a) {
      std::vector<uint32_t> s = sorted_by(ids, a);
      if (refs.centroids[s.front()][a] != refs.centroids[s.back()][a]) coincide = false;
    }
    std::vector<uint32_t> best_order;
    size_t best_k = 0;
    double best_cost = std::numeric_limits<double>::infinity();
    size_t best_balance = ~size_t(0);
    if (coincide) {
      best_order = by_x;
      best_k = count / 2;
      best_cost = bounds(by_x, 0, best_k).area() * double(best_k) + bounds(by_x, best_k, count).area() * double(count - best_k);
    } else {
      for (int a = 0; a < 3; ++a) {
        std::vector<uint32_t> s = sorted_by(ids, a);
        for (size_t k = 1; k < count; ++k) {
          double c = bounds(s, 0, k).area_unchecked() * double(k) + bounds(s, k, count).area_unchecked() * double(count - k);
          size_t balance = k * 2 > count ? k * 2 - count : count - k * 2;
          if (c < best_cost || (c == best_cost && balance < best_balance)) {
            best_cost = c;
            best_balance = balance;
            best_k = k;
            best_order = s;
          }
        }
      }
    }
    double area = bounds(ids, 0, count).area();
    if (count <= max_leaf && m.intersection * area * double(count) <= m.traversal * area + m.intersection * double(best_cost))
      return leaf();
    std::vector<uint32_t> l(best_order.begin(), best_order.begin() + best_k), r(best_order.begin() + best_k, best_order.end());
    std::string s = "(";
    s += self(self, l);
    s += ',';
    s += self(self, r);
    s += ')';
    return s;
  };
  std::vector<uint32_t> all(refs.size());
  std::iota(all.begin(), all.end(), 0u);
  return rec(rec, all);
}

TEST(Builders, SweepEqualsBruteForceSweep) {
  for (uint32_t max_leaf : {1u, 4u}) {
    for (uint64_t seed = 0; seed < 40; ++seed) {
      uint32_t count = 1 + static_cast<uint32_t>(seed * 7 % 90);
      PrimitiveRefs refs = seed % 3 == 0 ? make_references(random_mesh(count, seed, true)) : random_refs(count, seed);
      if (seed % 5 == 1)  // some exact duplicates, to exercise the tie rules
        for (size_t i = 0; i + 3 < refs.size(); i += 4) {
          refs.boxes[i + 1] = refs.boxes[i];
          refs.centroids[i + 1] = refs.centroids[i];
        }
      SweepSahConfig c;
      c.leaf.max_leaf_size = max_leaf;
      c.parallel_threshold = 8;
      if (seed % 2) c.parallel_split_threshold = 16;  // both split paths against the reference
      Bvh bvh = build_sweep_sah(refs, c);
      EXPECT_EQ(tree_signature(bvh, refs), brute_force_sweep(refs, max_leaf, c.cost))
          << "seed " << seed << " leaf " << max_leaf;
    }
  }
}

// The sweep's top nodes sweep and partition in chunks of 8192 positions on all threads; with
// tens of thousands of references there are several chunks per node, and the tree must be
// the one the sequential sweep builds, ties included (duplicated boxes).
TEST(Builders, SweepInChunksBuildsTheSequentialTree) {
  // Unit boxes in a row: every split k costs what n - k costs, so an odd row ties exactly at
  // its middle and the tie rule (the earlier of two equally balanced) decides: inside a
  // chunk for 40001 boxes, across the boundary of the second and third chunk for 32767.
  auto row = [](int n) {
    std::vector<Box> boxes;
    for (int i = 0; i < n; ++i) boxes.push_back(Box(Vec3(float(i), 0.0f, 0.0f), Vec3(float(i) + 1.0f, 1.0f, 1.0f)));
    return make_references(boxes);
  };
  for (uint32_t max_leaf : {1u, 4u}) {
    for (uint64_t seed : {1u, 2u, 3u, 4u}) {
      PrimitiveRefs refs = seed == 1   ? make_references(random_mesh(50000, 7, true))
                           : seed == 2 ? random_refs(50000, 8)
                           : seed == 3 ? row(40001)
                                       : row(32767);
      if (seed < 3)
        for (size_t i = 0; i + 3 < refs.size(); i += 4) {
          refs.boxes[i + 1] = refs.boxes[i];
          refs.centroids[i + 1] = refs.centroids[i];
        }
      SweepSahConfig sequential;
      sequential.leaf.max_leaf_size = max_leaf;
      sequential.parallel_split_threshold = std::numeric_limits<uint32_t>::max();
      SweepSahConfig chunked = sequential;
      chunked.parallel_split_threshold = 64;
      EXPECT_EQ(tree_signature(build_sweep_sah(refs, chunked), refs),
                tree_signature(build_sweep_sah(refs, sequential), refs))
          << "seed " << seed << " leaf " << max_leaf;
    }
  }
}

// The sweep over a mesh with its leaves in place must be the sweep over make_references,
// node for node: the same boxes, parents, children and leaf slots at the same indices.
TEST(Builders, SweepOverAMeshBuildsTheTreeOfItsReferences) {
  Mesh same;  // ten copies of one triangle: every centroid coincides, so nodes are halved
  same.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  for (int i = 0; i < 10; ++i) same.add_triangle(0, 1, 2);
  Mesh pairs = random_mesh(20000, 5, true);  // every fourth triangle repeated: ties between centroids
  for (size_t t = 0; t + 3 < pairs.triangle_count(); t += 4)
    for (int k = 0; k < 3; ++k) pairs.indices[3 * (t + 1) + k] = pairs.indices[3 * t + k];
  // Coordinates that are not finite (loaded scenes refuse them; a mesh made by hand may
  // hold them): a NaN, an infinity.
  Mesh nan = random_mesh(300, 6), inf = random_mesh(300, 7);
  nan.positions[40] = std::numeric_limits<float>::quiet_NaN();
  inf.positions[41] = std::numeric_limits<float>::infinity();
  // Whole triangles of NaN and of +infinity: a box of +infinity has extents inf - inf, so
  // no split of a node holding it has a cost, and the reference path keeps such a node as
  // one leaf.
  for (Mesh* m : {&nan, &inf}) {
    const uint32_t v = static_cast<uint32_t>(m->positions.size() / 3);
    const float x = m == &nan ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
    for (int k = 0; k < 9; ++k) m->positions.push_back(x);
    m->add_triangle(v, v + 1, v + 2);
  }
  const std::vector<Mesh> meshes = {random_mesh(1, 1), random_mesh(2, 2), random_mesh(3, 3), same,
                                    random_mesh(5000, 4, true), pairs, nan, inf};
  for (size_t m = 0; m < meshes.size(); ++m) {
    const PrimitiveRefs refs = make_references(meshes[m]);
    for (uint32_t max_leaf : {1u, 4u, 8u}) {
      for (uint32_t chunked_from : {64u, std::numeric_limits<uint32_t>::max()}) {
        SweepSahConfig config;
        config.leaf.max_leaf_size = max_leaf;
        config.parallel_split_threshold = chunked_from;
        config.parallel_threshold = 32;
        const Bvh expected = build_sweep_sah(refs, config);
        for (int threads : {1, 2}) {
          tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
          const Bvh in_place = build_sweep_sah(meshes[m], config);
          EXPECT_TRUE(testing::same_nodes(in_place, expected))
              << "mesh " << m << " leaf " << max_leaf << " chunks from " << chunked_from << " threads " << threads;
          if (m < 6) {
            EXPECT_TRUE(validate(in_place, refs).ok()) << "mesh " << m << " leaf " << max_leaf;
          }
        }
      }
    }
  }
  EXPECT_TRUE(build_sweep_sah(Mesh{}).empty());
}

TEST(Builders, SameTreeOnOneAndTwoThreads) {
  for (BuilderKind kind : all_builders()) {
    for (uint32_t max_leaf : {1u, 4u}) {
      PrimitiveRefs refs = make_references(random_mesh(6000, 99 + max_leaf, true));
      std::string one, two;
      {
        tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
        one = tree_signature(build_with(kind, refs, max_leaf, 32), refs);
      }
      {
        tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 2);
        // Twice, since task scheduling differs from run to run.
        for (int rep = 0; rep < 2; ++rep) {
          two = tree_signature(build_with(kind, refs, max_leaf, 32), refs);
          EXPECT_EQ(one, two) << name_of(kind) << " leaf " << max_leaf;
        }
      }
      {
        // More threads than cores: an arena of 8 (the process-wide limit raised to allow it).
        tbb::global_control allow(tbb::global_control::max_allowed_parallelism, 8);
        tbb::task_arena arena(8);
        std::string eight;
        arena.execute([&] { eight = tree_signature(build_with(kind, refs, max_leaf, 32), refs); });
        EXPECT_EQ(one, eight) << name_of(kind) << " leaf " << max_leaf << " on 8 threads";
      }
    }
  }
}

TEST(Builders, BinnedParallelBinningAndPartitionGiveTheSameTree) {
  // Large enough for several partition blocks; the binned tree depends only on each
  // node's set of references, so the sequential and parallel paths must agree.
  PrimitiveRefs refs = make_references(random_mesh(50000, 17, true));
  for (uint32_t max_leaf : {1u, 4u, 40u}) {
    BinnedSahConfig sequential, parallel;
    sequential.leaf.max_leaf_size = parallel.leaf.max_leaf_size = max_leaf;
    sequential.parallel_binning_threshold = std::numeric_limits<uint32_t>::max();
    parallel.parallel_binning_threshold = 100;
    parallel.parallel_threshold = 64;
    Bvh a = build_binned_sah(refs, sequential);
    Bvh b = build_binned_sah(refs, parallel);
    check_tree(b, refs, max_leaf, "parallel paths, leaf " + std::to_string(max_leaf));
    EXPECT_EQ(tree_signature(a, refs), tree_signature(b, refs)) << "leaf " << max_leaf;
  }
}

TEST(Builders, EdgeCases) {
  for (BuilderKind kind : all_builders()) {
    SCOPED_TRACE(name_of(kind));
    for (uint32_t max_leaf : {1u, 4u}) {
      PrimitiveRefs none;
      Bvh empty = build_with(kind, none, max_leaf, 4096);
      EXPECT_TRUE(empty.empty());
      EXPECT_TRUE(empty.nodes.empty());
      EXPECT_EQ(sah_cost(empty), 0.0);

      PrimitiveRefs one = random_refs(1, 5);
      Bvh b1 = build_with(kind, one, max_leaf, 4096);
      check_tree(b1, one, max_leaf, "one ref");
      EXPECT_EQ(b1.nodes.size(), 1u);

      PrimitiveRefs two = random_refs(2, 6);
      Bvh b2 = build_with(kind, two, max_leaf, 4096);
      check_tree(b2, two, max_leaf, "two refs");

      // Identical boxes: every split costs the same; the tree must still be balanced.
      std::vector<Box> same(1000, Box(Vec3(1, 2, 3), Vec3(2, 3, 5)));
      PrimitiveRefs identical = make_references(same);
      Bvh bi = build_with(kind, identical, max_leaf, 64);
      check_tree(bi, identical, max_leaf, "identical boxes");
      uint32_t depth = 0;
      auto rec = [&](auto&& self, uint32_t n, uint32_t d) -> void {
        depth = std::max(depth, d);
        if (!bi[n].is_leaf()) {
          self(self, bi[n].left(), d + 1);
          self(self, bi[n].right(), d + 1);
        }
      };
      rec(rec, bi.root, 0);
      EXPECT_LE(depth, 11u);

      // Points (zero-area boxes), some coincident, some on one line.
      std::vector<Box> points;
      for (int i = 0; i < 300; ++i) {
        Vec3 p(float(i % 17), i % 3 == 0 ? 0.0f : float(i % 5), 0.0f);
        points.emplace_back(p, p);
      }
      PrimitiveRefs pr = make_references(points);
      check_tree(build_with(kind, pr, max_leaf, 64), pr, max_leaf, "points");
    }
  }
}

TEST(Builders, SahBuildersBeatMediansOnRandomMeshes) {
  PrimitiveRefs refs = make_references(random_mesh(20000, 3, true));
  double sweep = sah_cost(build_with(BuilderKind::sweep_sah, refs, 1, 4096));
  double binned = sah_cost(build_with(BuilderKind::binned_sah, refs, 1, 4096));
  double spatial = sah_cost(build_with(BuilderKind::spatial_median, refs, 1, 4096));
  double object = sah_cost(build_with(BuilderKind::object_median, refs, 1, 4096));
  EXPECT_LT(sweep, spatial);
  EXPECT_LT(sweep, object);
  EXPECT_LT(binned, spatial);
  EXPECT_LT(binned, object);
  // Binning approximates the sweep: within a few percent on uniform random input.
  EXPECT_LT(binned, sweep * 1.05);
}

// Each count up to the maximum is used as given: every count gives a valid tree, and on a
// scene this large no two counts give the same tree (clamping would merge the top ones).
TEST(Builders, BinnedSahHonoursBinCount) {
  PrimitiveRefs refs = make_references(random_mesh(5000, 8, false));
  std::vector<std::string> signatures;
  for (uint32_t bins : {2u, 4u, 16u, 64u, 127u, kMaxBinCount}) {
    BinnedSahConfig c;
    c.bin_count = bins;
    c.refs_per_bin = 0;  // exactly bin_count bins in every node
    Bvh bvh = build_binned_sah(refs, c);
    check_tree(bvh, refs, 1, "bins " + std::to_string(bins));
    signatures.push_back(tree_signature(bvh, refs));
  }
  for (size_t i = 0; i < signatures.size(); ++i)
    for (size_t j = i + 1; j < signatures.size(); ++j) EXPECT_NE(signatures[i], signatures[j]) << i << " " << j;
  BinnedSahConfig few, many;
  few.bin_count = 4;
  many.bin_count = 64;
  few.refs_per_bin = many.refs_per_bin = 0;
  EXPECT_LT(sah_cost(build_binned_sah(refs, many)), sah_cost(build_binned_sah(refs, few)));
}

// BuildOptions passes the binned builder's own settings through: a fixed count differs
// from the adaptive default (whose large nodes get more bins), and two fixed counts differ.
TEST(Builders, BuildOptionsCarryTheBinnedSettings) {
  PrimitiveRefs refs = make_references(random_mesh(20000, 5, false));
  BuildOptions adaptive;
  adaptive.kind = BuilderKind::binned_sah;
  BuildOptions fixed32 = adaptive, fixed8 = adaptive;
  fixed32.binned.refs_per_bin = fixed8.binned.refs_per_bin = 0;
  fixed8.binned.bin_count = 8;
  const std::string a = tree_signature(build_bvh(refs, adaptive), refs);
  const std::string f32 = tree_signature(build_bvh(refs, fixed32), refs);
  const std::string f8 = tree_signature(build_bvh(refs, fixed8), refs);
  EXPECT_NE(a, f32);
  EXPECT_NE(f32, f8);
  // And the shared settings reach the builder: the same tree as the builder called directly.
  EXPECT_EQ(a, tree_signature(build_binned_sah(refs, BinnedSahConfig{}), refs));
  EXPECT_EQ(f8, tree_signature(build_binned_sah(refs, binned_sah_config(fixed8)), refs));
  EXPECT_EQ(binned_sah_config(fixed8).bin_count, 8u);
  EXPECT_EQ(binned_sah_config(fixed8).refs_per_bin, 0u);
}

// Runs `build` and expects an Error whose message contains every one of `parts`.
void expect_config_error(const std::function<void()>& build, std::initializer_list<const char*> parts,
                         const std::string& what) {
  try {
    build();
    ADD_FAILURE() << what << ": no error";
  } catch (const Error& e) {
    for (const char* part : parts) EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << what << ": " << e.what();
  }
}

TEST(Builders, BinnedConfigOutOfRangeIsAnError) {
  PrimitiveRefs refs = make_references(random_mesh(200, 2, false));
  for (uint32_t bins : {0u, 1u, kMaxBinCount + 1, 1024u}) {
    BinnedSahConfig c;
    c.bin_count = bins;
    expect_config_error([&] { build_binned_sah(refs, c); }, {"bin_count", "2 to 128"}, "bin_count " + std::to_string(bins));
    BuildOptions o;
    o.kind = BuilderKind::binned_sah;
    o.binned.bin_count = bins;
    expect_config_error([&] { build_bvh(refs, o); }, {"bin_count", "2 to 128"}, "BuildOptions bins " + std::to_string(bins));
    expect_config_error([&] { validate(o); }, {"bin_count"}, "validate bins " + std::to_string(bins));
  }
  BinnedSahConfig c;
  c.max_bin_count = 1000;
  expect_config_error([&] { build_binned_sah(refs, c); }, {"max_bin_count", "1000", "2 to 128"}, "max_bin_count");
  c = BinnedSahConfig{};
  c.exact_sweep_below = kMaxExactSweepBelow + 1;
  expect_config_error([&] { build_binned_sah(refs, c); }, {"exact_sweep_below", "0 to 256"}, "exact_sweep_below");
  // The limits themselves are allowed.
  c = BinnedSahConfig{};
  c.bin_count = c.max_bin_count = kMaxBinCount;
  c.exact_sweep_below = kMaxExactSweepBelow;
  EXPECT_NO_THROW(check_tree(build_binned_sah(refs, c), refs, 1, "limits"));
  c.exact_sweep_below = 0;
  c.bin_count = kMinBinCount;
  EXPECT_NO_THROW(check_tree(build_binned_sah(refs, c), refs, 1, "lower limits"));
}

TEST(Builders, SharedConfigOutOfRangeIsAnErrorForEveryBuilder) {
  PrimitiveRefs refs = make_references(random_mesh(50, 2, false));
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (BuilderKind kind : all_builders()) {
    const std::string name(builder_name(kind));
    BuildOptions o;
    o.kind = kind;
    o.leaf.max_leaf_size = 0;
    expect_config_error([&] { build_bvh(refs, o); }, {"max_leaf_size", "at least 1"}, name + " leaf 0");
    // Also on empty input: a bad config is an error whatever the scene.
    expect_config_error([&] { build_bvh(PrimitiveRefs{}, o); }, {"max_leaf_size"}, name + " leaf 0, no refs");
    for (double bad : {nan, inf, -1.0}) {
      o = BuildOptions{};
      o.kind = kind;
      o.cost.traversal = bad;
      expect_config_error([&] { build_bvh(refs, o); }, {"c_T", "finite and >= 0"}, name + " c_T");
      o = BuildOptions{};
      o.kind = kind;
      o.cost.intersection = bad;
      expect_config_error([&] { build_bvh(refs, o); }, {"c_I", "finite and >= 0"}, name + " c_I");
    }
  }
  SweepSahConfig sweep;
  sweep.leaf.max_leaf_size = 0;
  expect_config_error([&] { build_sweep_sah(refs, sweep); }, {"max_leaf_size"}, "sweep direct");
  MedianConfig median;
  median.cost.intersection = -2.0;
  expect_config_error([&] { build_object_median(refs, median); }, {"c_I"}, "median direct");
}

// References under node n, sorted.
std::vector<uint32_t> refs_below(const Bvh& bvh, uint32_t n) {
  std::vector<uint32_t> out, stack{n};
  while (!stack.empty()) {
    const BvhNode& node = bvh.nodes[stack.back()];
    stack.pop_back();
    if (node.is_leaf()) {
      for (uint32_t k = 0; k < node.ref_count(); ++k) out.push_back(bvh.ref_indices[node.first_ref() + k]);
    } else {
      stack.push_back(node.left());
      stack.push_back(node.right());
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Hand-made input with one right answer: two clusters of four unit boxes, 100 apart on x
// and interleaved in id order. Every builder must split the root exactly between them.
TEST(Builders, TwoSeparatedClustersAreSplitAtTheRoot) {
  PrimitiveRefs refs;
  refs.resize(8);
  for (uint32_t i = 0; i < 8; ++i) {
    const float x = (i % 2 ? 100.0f : 0.0f) + 0.5f * float(i / 2);
    const float y = float(i / 2) * 0.25f;
    refs.boxes[i] = Box(Vec3(x, y, 0.0f), Vec3(x + 1.0f, y + 1.0f, 1.0f));
    refs.centroids[i] = refs.boxes[i].center();
    refs.triangle_ids[i] = i;
  }
  const std::vector<uint32_t> even{0, 2, 4, 6}, odd{1, 3, 5, 7};
  for (BuilderKind kind : all_builders())
    for (uint32_t leaf : {1u, 4u}) {
      const std::string what = std::string(builder_name(kind)) + " leaf " + std::to_string(leaf);
      BuildOptions o;
      o.kind = kind;
      o.leaf.max_leaf_size = leaf;
      Bvh bvh = build_bvh(refs, o);
      check_tree(bvh, refs, leaf, what);
      const BvhNode& root = bvh.nodes[bvh.root];
      ASSERT_FALSE(root.is_leaf()) << what;
      std::vector<uint32_t> l = refs_below(bvh, root.left()), r = refs_below(bvh, root.right());
      if (l != even) std::swap(l, r);
      EXPECT_EQ(l, even) << what;
      EXPECT_EQ(r, odd) << what;
    }
}

// The tree as nested sets, children in sorted order: "((0,1),(2,3))" whichever child a
// builder put first.
std::string canonical_tree(const Bvh& bvh, uint32_t n) {
  const BvhNode& nd = bvh.nodes[n];
  if (nd.is_leaf()) {
    std::vector<uint32_t> ids(bvh.ref_indices.begin() + nd.first_ref(), bvh.ref_indices.begin() + nd.first_ref() + nd.ref_count());
    std::sort(ids.begin(), ids.end());
    std::string s;
    for (uint32_t id : ids) {
      if (!s.empty()) s += '+';
      s += std::to_string(id);
    }
    return s;
  }
  std::string a = canonical_tree(bvh, nd.left()), b = canonical_tree(bvh, nd.right());
  if (b < a) std::swap(a, b);
  return "(" + a + "," + b + ")";
}

PrimitiveRefs unit_cubes_on_x(const std::vector<float>& xs) {
  std::vector<Box> boxes;
  for (float x : xs) boxes.emplace_back(Vec3(x, 0, 0), Vec3(x + 1, 1, 1));
  return make_references(boxes);
}

// Hand-made inputs whose whole tree is known. Two pairs far apart: every builder, medians
// included, pairs them. Three cubes in a row and one far away: the SAH builders cut off the
// far one (the only cut that saves area), the object median cuts two and two (its rule).
TEST(Builders, HandMadeInputsGiveTheirKnownTrees) {
  const PrimitiveRefs pairs = unit_cubes_on_x({0, 2, 10, 12});
  const PrimitiveRefs row = unit_cubes_on_x({0, 1, 2, 40});
  for (BuilderKind kind : all_builders()) {
    BuildOptions o;
    o.kind = kind;
    o.leaf.max_leaf_size = 1;
    EXPECT_EQ(canonical_tree(build_bvh(pairs, o), 0), "((0,1),(2,3))") << builder_name(kind);
    const Bvh bvh = build_bvh(row, o);
    const BvhNode& root = bvh.nodes[bvh.root];
    ASSERT_FALSE(root.is_leaf());
    std::string l = canonical_tree(bvh, root.left()), r = canonical_tree(bvh, root.right());
    if (r < l) std::swap(l, r);
    if (kind == BuilderKind::object_median) {
      EXPECT_EQ(canonical_tree(bvh, bvh.root), "((0,1),(2,3))");
    } else if (kind != BuilderKind::spatial_median) {
      // ((0,1),2) or (0,(1,2)): the two cost the same.
      EXPECT_EQ(r, "3") << builder_name(kind);
      EXPECT_TRUE(l == "((0,1),2)" || l == "((1,2),0)") << builder_name(kind) << " " << l;
    }
  }
  // Spatial median: the box's middle on x is 20.5, so the far cube is cut off there too.
  BuildOptions o;
  o.kind = BuilderKind::spatial_median;
  o.leaf.max_leaf_size = 1;
  const Bvh sm = build_bvh(row, o);
  const std::string t = canonical_tree(sm, sm.root);
  EXPECT_TRUE(t == "(((0,1),2),3)" || t == "(((1,2),0),3)") << t;
}

}  // namespace
}  // namespace bvhopt
