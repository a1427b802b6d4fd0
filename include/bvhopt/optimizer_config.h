// What every optimizer's configuration shares: the cost model, when to stop, the seed.
#pragma once

#include <cstdint>
#include <functional>

#include "bvhopt/cost_model.h"
#include "bvhopt/optimize_report.h"

namespace bvhopt {

// Limits that cut a run short of the method's own stopping rule; 0 means no limit. Both are
// checked after every pass, so a run always completes the pass that reaches a limit.
struct OptimizeLimits {
  uint32_t max_passes = 0;  // stop after this many passes (over all stages of a method)
  double time_limit = 0.0;  // seconds since the optimizer started
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
