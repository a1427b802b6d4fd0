// Simulated annealing: the schedule, the exact optimum on small inputs (the DP oracle),
// keep-best, seeds and threads.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <numbers>

#include "bvhopt/cost.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace bvhopt {
namespace {


TEST(AnnealSchedule, MatchesKenslersFormula) {
  const uint32_t n = 1250, f = 50;
  const double h = 1.5;
  for (uint32_t i = 0; i < 1300; ++i) {
    double t = annealing_temperature(i, n, f, h);
    double want = i < n ? std::max(0.0, -std::sin(2.0 * std::numbers::pi * i / f)) * (n - i) * h / n : 0.0;
    EXPECT_NEAR(t, want, 1e-12);
    // Cold for the first half of every period (hill climbing), warm in the second half.
    if (i < n && i % f != 0 && i % f != f / 2) {
      EXPECT_EQ(t > 0.0, i % f > f / 2) << i;
    }
    EXPECT_LE(t, h);
  }
  EXPECT_EQ(annealing_temperature(0, n, f, h), 0.0);
  // The hottest pass of the first period is i = 37 or 38, near h.
  EXPECT_GT(annealing_temperature(37, n, f, h), 0.95 * h);
}

struct OracleResult {
  int cases = 0, exact = 0;
  double worst_gap = 0.0;
};

// Random inputs of 3..10 references: the annealed tree against the exact optimum.
OracleResult run_oracle(uint32_t sizes_from, uint32_t sizes_to, uint64_t seeds) {
  const CostModel model;
  OracleResult r;
  for (uint32_t count = sizes_from; count <= sizes_to; ++count) {
    for (uint64_t s = 1; s <= seeds; ++s) {
      PrimitiveRefs refs = testing::random_refs(count, 1000 * count + s);
      Bvh bvh = testing::median_tree(refs);
      AnnealConfig cfg;
      cfg.seed = s;
      OptimizeReport rep = anneal(bvh, cfg);
      EXPECT_TRUE(validate(bvh, refs).ok());
      const double opt = testing::optimal_tree_cost(refs, model.traversal, model.intersection) / bvh[bvh.root].area();
      const double got = sah_cost(bvh, model);
      EXPECT_EQ(got, rep.final_cost);
      EXPECT_GE(got, opt * (1 - 1e-9)) << "below the optimum: the oracle or the cost is wrong";
      const double gap = got / opt - 1.0;
      ++r.cases;
      if (gap <= 1e-9) ++r.exact;
      r.worst_gap = std::max(r.worst_gap, gap);
    }
  }
  return r;
}

// The demand: at least 90 % of 64 cases exactly optimal, none more than 5 % above.
TEST(Anneal, ReachesTheExactOptimumOnSmallInputs) {
  OracleResult r = run_oracle(3, 10, 8);
  RecordProperty("exact", r.exact);
  RecordProperty("cases", r.cases);
  std::printf("annealing: %d of %d exactly optimal, worst gap %.4f %%\n", r.exact, r.cases, 100.0 * r.worst_gap);
  EXPECT_GE(r.exact, r.cases * 9 / 10);
  EXPECT_LE(r.worst_gap, 0.05);
}

TEST(Anneal, HillClimbingAloneDoesNotAlwaysReachTheOptimum) {
  // The reason annealing exists: with the same inputs hill climbing stops short more often.
  const CostModel model;
  int exact = 0, cases = 0;
  for (uint32_t count = 6; count <= 10; ++count)
    for (uint64_t s = 1; s <= 8; ++s) {
      PrimitiveRefs refs = testing::random_refs(count, 1000 * count + s);
      Bvh bvh = testing::median_tree(refs);
      hill_climb(bvh);
      const double opt = testing::optimal_tree_cost(refs, model.traversal, model.intersection) / bvh[bvh.root].area();
      ++cases;
      exact += sah_cost(bvh, model) / opt - 1.0 <= 1e-9;
    }
  EXPECT_LT(exact, cases);
}

TEST(Anneal, KeepBestReturnsTheBestPassAndNeverWorsens) {
  PrimitiveRefs refs = testing::random_refs(3000, 21);
  Bvh bvh = testing::median_tree(refs);
  AnnealConfig cfg;
  cfg.schedule_passes = 150;
  cfg.h = 2.2;
  OptimizeReport rep = anneal(bvh, cfg);
  ASSERT_TRUE(validate(bvh, refs).ok());
  double best = rep.initial_cost;
  bool rose = false;
  double prev = rep.initial_cost;
  for (const PassRecord& p : rep.trace) {
    best = std::min(best, p.cost);
    EXPECT_EQ(p.best_cost, best);
    EXPECT_EQ(p.temperature, annealing_temperature(p.pass - 1, cfg.schedule_passes, cfg.period, cfg.h));
    if (p.cost > prev) {
      rose = true;
      EXPECT_GT(p.temperature, 0.0) << "a cold pass raised the cost";
    }
    prev = p.cost;
  }
  EXPECT_TRUE(rose) << "hot passes should accept some worse moves";
  EXPECT_EQ(rep.final_cost, best);
  EXPECT_EQ(sah_cost(bvh), best);
  EXPECT_EQ(rep.stop_reason, StopReason::converged);
  EXPECT_GT(rep.passes, cfg.schedule_passes);
  EXPECT_EQ(rep.trace.back().moves, 0u);
}

TEST(Anneal, WithoutKeepBestReturnsTheLastTree) {
  PrimitiveRefs refs = testing::random_refs(2000, 22);
  Bvh bvh = testing::median_tree(refs);
  AnnealConfig cfg;
  cfg.schedule_passes = 1250;  // stopped by the pass limit while hot
  cfg.limits.max_passes = 40;
  cfg.h = 2.2;
  cfg.keep_best = false;
  OptimizeReport rep = anneal(bvh, cfg);
  EXPECT_EQ(rep.stop_reason, StopReason::pass_limit);
  EXPECT_EQ(rep.passes, 40u);
  EXPECT_EQ(rep.final_cost, rep.trace.back().cost);
  EXPECT_EQ(sah_cost(bvh), rep.trace.back().cost);
  EXPECT_GT(rep.final_cost, rep.trace.back().best_cost);  // a hot pass left it above the best
}

TEST(Anneal, SameSeedSameTreeOnOneAndTwoThreadsAndSeedsDiffer) {
  PrimitiveRefs refs = testing::random_refs(30000, 23);
  Bvh start = testing::median_tree(refs);
  auto run = [&](uint64_t seed, int threads) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
    Bvh bvh = start;
    AnnealConfig cfg;
    cfg.seed = seed;
    cfg.schedule_passes = 60;
    anneal(bvh, cfg);
    return testing::tree_signature(bvh, refs);
  };
  const std::string a1 = run(5, 1), a2 = run(5, 2), b2 = run(6, 2);
  EXPECT_EQ(a1, a2);
  EXPECT_NE(a1, b2);
}

TEST(Anneal, PassLimitOfOneGivesOnePass) {
  PrimitiveRefs refs = testing::random_refs(500, 24);
  Bvh bvh = testing::median_tree(refs);
  AnnealConfig cfg;
  cfg.limits.max_passes = 1;
  OptimizeReport rep = anneal(bvh, cfg);
  EXPECT_EQ(rep.passes, 1u);
  EXPECT_EQ(rep.stop_reason, StopReason::pass_limit);
  EXPECT_TRUE(validate(bvh, refs).ok());
}

}  // namespace
}  // namespace bvhopt
