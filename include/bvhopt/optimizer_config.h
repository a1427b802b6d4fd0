// What every optimizer's configuration shares: the cost model, when to stop, the seed.
#pragma once

#include <cstdint>
#include <functional>

#include "bvhopt/cost_model.h"
#include "bvhopt/optimize_report.h"

namespace bvhopt {

// Limits that cut a run short of the method's own stopping rule; 0 means no limit. The pass
// and time limits are checked after every pass, so a run always completes the pass that
// reaches one; the time budget is also checked before every pass but the first.
struct OptimizeLimits {
  uint32_t max_passes = 0;  // stop after this many passes (over all stages of a method)
  double time_limit = 0.0;  // seconds since the optimizer started
  // Seconds the whole run should take, its work after the last pass included: a pass is not
  // started when, judged by the length of the pass before it, it would end too late to leave
  // that work its time (the insertion optimizer's final renumbering, estimated from the
  // tree's size). Stops with StopReason::time_limit. So `bake --time-budget 10` ends its
  // optimizer within about 10 s, where time_limit lets the pass under way finish and counts
  // nothing after it (on the hall at 10M triangles a pass takes up to 0.45 s and the
  // renumbering 1.3 s). The first pass always runs, and the first pass of each of
  // a method's stages is judged only by the time it leaves for that work (the stage
  // before's passes say little about its length), so one such pass can overrun the budget.
  double time_budget = 0.0;
  PassCallback on_pass;     // called after every pass (may be empty)
  // Asked after every pass (after on_pass); true stops the run with the best tree so far
  // (StopReason::interrupted). The Python module stops on Ctrl-C through it.
  std::function<bool()> stop_requested;
};

// The base of HillClimbConfig, AnnealConfig and InsertionConfig.
struct OptimizerConfig {
  CostModel cost;         // the reported cost; what the moves depend on is said per method
  OptimizeLimits limits;
  uint64_t seed = 1;      // every random choice flows from it (hill climbing makes none)
};

}  // namespace bvhopt
