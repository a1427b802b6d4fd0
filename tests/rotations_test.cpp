// Tree rotations: single moves against recomputation from scratch, hill climbing against
// brute force over every node and move, determinism over thread counts, limits.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <random>

#include "bvhopt/cost.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/validate.h"
#include "optimize/tree_rotations_engine.h"
#include "test_support.h"

namespace bvhopt {
namespace {


std::vector<uint32_t> inner_nodes(const Bvh& bvh) {
  std::vector<uint32_t> inner;
  for (uint32_t n : bvh.depth_first_order())
    if (!bvh[n].is_leaf()) inner.push_back(n);
  return inner;
}

// Every applicable move at every inner node: the lowest cost change found, by brute force on
// the public Bvh functions (which share no code with the optimizers' working copy).
double best_single_move(const Bvh& bvh, const CostModel& model) {
  double best = 0.0;
  for (uint32_t n : inner_nodes(bvh))
    for (int m = 0; m < kRotationCount; ++m)
      if (rotation_applies(bvh, n, Rotation(m))) best = std::min(best, rotation_cost_delta(bvh, n, Rotation(m), model));
  return best;
}

TEST(Rotations, PublicMovesKeepTreeValidAndChangeCostByTheirDelta) {
  const CostModel model;
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    PrimitiveRefs refs = testing::random_refs(60, seed);
    Bvh bvh = testing::median_tree(refs);
    std::vector<uint32_t> inner = inner_nodes(bvh);
    std::mt19937_64 rng(seed);
    const double root_area = bvh[bvh.root].area();
    for (int step = 0; step < 300; ++step) {
      uint32_t n = inner[rng() % inner.size()];
      Rotation r = Rotation(rng() % kRotationCount);
      if (!rotation_applies(bvh, n, r)) continue;
      const double before = sah_cost(bvh, model);
      const double delta = rotation_cost_delta(bvh, n, r, model);
      apply_rotation(bvh, n, r);
      // Moves never change the node's own box, so nothing above needs refitting.
      ValidationReport v = validate(bvh, refs);
      ASSERT_TRUE(v.ok()) << "seed " << seed << " step " << step << " " << rotation_name(r) << ": " << v.summary();
      EXPECT_EQ(bvh[bvh.root].area(), root_area);
      EXPECT_NEAR(sah_cost(bvh, model), before + delta / root_area, 1e-9 * before);
    }
  }
}

// The working copy: every move, through the engine, gives the same tree as the public move,
// a valid Bvh when written back, and a tracked cost equal to the one recomputed from scratch.
// Moves are made on a bottom-up walk, as the optimizers make them, at random nodes with a
// random applicable move; nodes left alone get their cost refreshed as a pass would.
TEST(Rotations, EngineMovesMatchPublicMovesAndTrackCosts) {
  const CostModel model;
  for (uint64_t seed = 11; seed <= 15; ++seed) {
    PrimitiveRefs refs = testing::random_refs(80, seed);
    Bvh reference = testing::median_tree(refs);
    detail::RotationEngine engine(reference, model);
    std::mt19937_64 rng(seed);
    double tracked = engine.tree_cost() * engine.root_area();  // unnormalized, updated by deltas
    int applied = 0;
    for (int walk = 0; walk < 4; ++walk) {
      std::vector<uint32_t> order;  // post-order of the engine's inner nodes at walk start
      {
        std::vector<uint32_t> pre, stack{engine.root()};
        while (!stack.empty()) {
          uint32_t x = stack.back();
          stack.pop_back();
          if (engine.is_leaf(x)) continue;
          pre.push_back(x);
          stack.push_back(engine.child(x, 0));
          stack.push_back(engine.child(x, 1));
        }
        order.assign(pre.rbegin(), pre.rend());
      }
      for (uint32_t n : order) {
        const uint32_t bn = engine.bvh_index(n);
        int m = static_cast<int>(rng() % kRotationCount);
        const double delta = engine.area_delta(n, m);
        ASSERT_EQ(std::isfinite(delta), rotation_applies(reference, bn, Rotation(m)));
        if (!std::isfinite(delta) || rng() % 2) {
          engine.refresh_cost(n);
          continue;
        }
        EXPECT_EQ(model.traversal * delta, rotation_cost_delta(reference, bn, Rotation(m), model));
        engine.apply(n, m);
        apply_rotation(reference, bn, Rotation(m));
        tracked += model.traversal * delta;
        ++applied;

        Bvh written = reference;
        engine.write_to(written);
        ValidationReport v = validate(written, refs);
        ASSERT_TRUE(v.ok()) << v.summary();
        ASSERT_EQ(testing::tree_signature(written, refs), testing::tree_signature(reference, refs));
        std::vector<double> fresh = subtree_costs(written, model);
        // The moved node and its children are exact at once; ancestors as the walk reaches them.
        EXPECT_NEAR(engine.node_cost(n), fresh[bn], 1e-9 * fresh[bn]);
        for (int i = 0; i < 2; ++i) {
          uint32_t c = engine.child(n, i);
          EXPECT_NEAR(engine.node_cost(c), fresh[engine.bvh_index(c)], 1e-9 * fresh[engine.bvh_index(c)]);
        }
        EXPECT_NEAR(sah_cost(written, model) * engine.root_area(), tracked, 1e-9 * tracked);
      }
      EXPECT_NEAR(engine.tree_cost() * engine.root_area(), tracked, 1e-9 * tracked);
    }
    EXPECT_GT(applied, 50);
  }
}

// After whole passes (hill climbing and annealing alike) every node's tracked cost equals
// its cost recomputed from scratch.
TEST(Rotations, PassesKeepEveryNodeCostExact) {
  const CostModel model;
  PrimitiveRefs refs = testing::random_refs(3000, 7);
  Bvh bvh = testing::median_tree(refs);
  detail::RotationEngine engine(bvh, model);
  for (uint32_t pass = 0; pass < 6; ++pass) {
    uint64_t moves = engine.run_pass(pass % 2 ? 1.5 : 0.0, 10.0, 99, pass);
    EXPECT_GT(moves, 0u);
    Bvh written = bvh;
    engine.write_to(written);
    ASSERT_TRUE(validate(written, refs).ok());
    std::vector<double> fresh = subtree_costs(written, model);
    std::vector<uint32_t> stack{engine.root()};
    size_t seen = 0;
    while (!stack.empty()) {
      uint32_t n = stack.back();
      stack.pop_back();
      ++seen;
      ASSERT_EQ(engine.node_cost(n), fresh[engine.bvh_index(n)]) << "slot " << n << " pass " << pass;
      if (engine.is_leaf(n)) continue;
      stack.push_back(engine.child(n, 0));
      stack.push_back(engine.child(n, 1));
    }
    EXPECT_EQ(seen, written.nodes.size());
    EXPECT_EQ(engine.tree_cost(), sah_cost(written, model));
  }
}

// Relayout renumbers the slots only: the same passes give the same tree with or without it.
TEST(Rotations, RelayoutChangesNothingButMemoryOrder) {
  const CostModel model;
  PrimitiveRefs refs = testing::random_refs(6000, 8);
  Bvh bvh = testing::median_tree(refs);
  detail::RotationEngine a(bvh, model), b(bvh, model);
  for (uint32_t pass = 0; pass < 8; ++pass) {
    const double t = pass % 2 ? 1.0 : 0.0;
    b.relayout();
    EXPECT_EQ(a.run_pass(t, 10.0, 3, pass), b.run_pass(t, 10.0, 3, pass));
  }
  Bvh wa = bvh, wb = bvh;
  a.write_to(wa);
  b.write_to(wb);
  EXPECT_EQ(testing::tree_signature(wa, refs), testing::tree_signature(wb, refs));
  EXPECT_EQ(a.tree_cost(), b.tree_cost());
}

TEST(HillClimb, LeavesWithSeveralReferencesStayAsTheyAre) {
  PrimitiveRefs refs = testing::random_refs(3000, 31);
  MedianConfig leaves_of_four;
  leaves_of_four.leaf.max_leaf_size = 4;
  Bvh bvh = build_object_median(refs, leaves_of_four);
  const size_t leaves = bvh.leaf_count();
  OptimizeReport rep = hill_climb(bvh);
  ASSERT_TRUE(validate(bvh, refs).ok());
  EXPECT_LT(rep.final_cost, rep.initial_cost);
  EXPECT_EQ(bvh.leaf_count(), leaves);
  EXPECT_GE(best_single_move(bvh, CostModel{}), 0.0);
}

TEST(HillClimb, NeverRaisesCostAndEndsInALocalMinimum) {
  const CostModel model;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    for (uint32_t count : {2u, 3u, 17u, 500u, 5000u}) {
      PrimitiveRefs refs = testing::random_refs(count, seed * 100 + count);
      Bvh bvh = seed % 2 ? testing::median_tree(refs) : build_sweep_sah(refs);
      const double before = sah_cost(bvh, model);
      OptimizeReport rep = hill_climb(bvh);
      ASSERT_TRUE(validate(bvh, refs).ok()) << validate(bvh, refs).summary();
      EXPECT_EQ(rep.stop_reason, StopReason::converged);
      EXPECT_NEAR(rep.initial_cost, before, 1e-12 * before);
      EXPECT_EQ(rep.final_cost, sah_cost(bvh, model));
      EXPECT_LE(rep.final_cost, before);
      double prev = rep.initial_cost;
      for (const PassRecord& p : rep.trace) {
        EXPECT_LE(p.cost, prev);
        EXPECT_EQ(p.temperature, 0.0);
        prev = p.cost;
      }
      if (!rep.trace.empty()) {
        EXPECT_EQ(rep.trace.back().moves, 0u);
      }
      // No single move anywhere lowers the cost.
      EXPECT_GE(best_single_move(bvh, model), 0.0) << "count " << count << " seed " << seed;
      EXPECT_EQ(bvh.leaf_count(), count);
    }
  }
}

TEST(HillClimb, ImprovesAMedianTree) {
  PrimitiveRefs refs = testing::random_refs(2000, 3);
  Bvh bvh = testing::median_tree(refs);
  OptimizeReport rep = hill_climb(bvh);
  EXPECT_LT(rep.final_cost, 0.99 * rep.initial_cost);
  EXPECT_GT(rep.moves, 0u);
  EXPECT_GE(rep.passes, 2u);
}

TEST(HillClimb, SameTreeOnOneAndTwoThreads) {
  // Enough leaves that a pass is cut into many parallel pieces plus a top part.
  PrimitiveRefs refs = testing::random_refs(40000, 5);
  Bvh start = testing::median_tree(refs);
  std::string sig[2];
  for (int threads = 1; threads <= 2; ++threads) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
    Bvh bvh = start;
    hill_climb(bvh);
    sig[threads - 1] = testing::tree_signature(bvh, refs);
  }
  EXPECT_EQ(sig[0], sig[1]);
}

TEST(HillClimb, PassAndTimeLimits) {
  PrimitiveRefs refs = testing::random_refs(3000, 9);
  Bvh start = testing::median_tree(refs);
  {
    Bvh bvh = start;
    HillClimbConfig cfg;
    cfg.limits.max_passes = 1;
    int calls = 0;
    cfg.limits.on_pass = [&](const PassRecord& p) {
      ++calls;
      EXPECT_EQ(p.pass, 1u);
    };
    OptimizeReport rep = hill_climb(bvh, cfg);
    EXPECT_EQ(rep.passes, 1u);
    EXPECT_EQ(rep.trace.size(), 1u);
    EXPECT_EQ(calls, 1);
    EXPECT_EQ(rep.stop_reason, StopReason::pass_limit);
    EXPECT_TRUE(validate(bvh, refs).ok());
    EXPECT_EQ(rep.final_cost, sah_cost(bvh));
  }
  {
    Bvh bvh = start;
    HillClimbConfig cfg;
    cfg.limits.max_passes = 3;
    OptimizeReport rep = hill_climb(bvh, cfg);
    EXPECT_EQ(rep.passes, 3u);
  }
  {
    Bvh bvh = start;
    HillClimbConfig cfg;
    cfg.limits.time_limit = 1e-9;  // expires during the first pass
    OptimizeReport rep = hill_climb(bvh, cfg);
    EXPECT_EQ(rep.passes, 1u);
    EXPECT_EQ(rep.stop_reason, StopReason::time_limit);
  }
}

TEST(HillClimb, DegenerateInputs) {
  // One leaf: nothing to do.
  PrimitiveRefs one = make_references({Box({0, 0, 0}, {1, 1, 1})});
  Bvh bvh = testing::median_tree(one);
  OptimizeReport rep = hill_climb(bvh);
  EXPECT_EQ(rep.passes, 0u);
  EXPECT_EQ(rep.stop_reason, StopReason::converged);
  // All boxes one point: zero root area, the cost is defined by the limit and stays.
  PrimitiveRefs points = make_references(std::vector<Box>(9, Box({1, 2, 3}, {1, 2, 3})));
  Bvh p = testing::median_tree(points);
  rep = hill_climb(p);
  EXPECT_TRUE(validate(p, points).ok());
  EXPECT_EQ(rep.final_cost, rep.initial_cost);
  // Many coincident zero-area boxes among ordinary ones (as in Conference).
  std::vector<Box> boxes;
  for (int i = 0; i < 300; ++i) boxes.push_back(i % 3 ? Box({float(i), 0, 0}, {float(i) + 1, 1, 1}) : Box({5, 5, 5}, {5, 5, 5}));
  PrimitiveRefs mixed = make_references(boxes);
  Bvh m = testing::median_tree(mixed);
  rep = hill_climb(m);
  EXPECT_TRUE(validate(m, mixed).ok());
  EXPECT_LE(rep.final_cost, rep.initial_cost);
  EXPECT_GE(best_single_move(m, CostModel{}), 0.0);
}

// A real scene with zero-area triangles (Staircase has 2,429): both optimizers keep the tree
// valid, lower its cost, and give the same tree on 1 and 2 threads.
TEST(Rotations, RealSceneWithZeroAreaTriangles) {
  const auto path = testing::scenes_dir() / "staircase.obj";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not found (set BVHOPT_SCENES)";
  Mesh mesh = load_scene(path.string());
  PrimitiveRefs refs = make_references(mesh);
  const Bvh start = build_sweep_sah(refs);
  std::string sig[2];
  for (int threads = 1; threads <= 2; ++threads) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
    Bvh hill = start;
    OptimizeReport h = hill_climb(hill);
    ASSERT_TRUE(validate(hill, refs).ok());
    EXPECT_LT(h.final_cost, h.initial_cost);
    EXPECT_GE(best_single_move(hill, CostModel{}), 0.0);
    Bvh bvh = start;
    AnnealConfig cfg;
    cfg.schedule_passes = 100;
    OptimizeReport a = anneal(bvh, cfg);
    ASSERT_TRUE(validate(bvh, refs).ok());
    EXPECT_LE(a.final_cost, h.final_cost * 1.001);
    EXPECT_EQ(a.final_cost, sah_cost(bvh));
    sig[threads - 1] = testing::tree_signature(bvh, refs);
  }
  EXPECT_EQ(sig[0], sig[1]);
}

}  // namespace
}  // namespace bvhopt
