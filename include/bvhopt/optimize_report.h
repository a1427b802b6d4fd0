// What every optimizer reports: the cost trace of its passes and a summary.
#pragma once

#include <cstdint>
#include <functional>
#include <string_view>
#include <vector>

namespace bvhopt {

// One row per pass: the data of Kensler's Figures 3 and 4.
struct PassRecord {
  uint32_t pass = 0;
  double cost = 0.0;         // tree cost (normalized SAH) after the pass
  double best_cost = 0.0;    // lowest cost seen so far
  double temperature = 0.0;  // annealing only; 0 otherwise
  uint64_t moves = 0;        // moves applied in this pass
  double seconds = 0.0;      // elapsed since the optimizer started
  // Which stage of the method ran the pass, from 0: insertion's forms run several in turn
  // (OptimizeReport::stages names them); the other methods have one.
  uint32_t stage = 0;
  // That stage's name, as in OptimizeReport::stages (a string with static storage).
  std::string_view stage_name;
};

// One stage of a run, in the order the stages ran: where the time went. Insertion's forms
// run several ("sequential", "parallel", "regional" passes and "sweeps" of rotations; the
// regional form of a large tree: parallel, sequential, sweeps, regional, sweeps, parallel,
// sweeps); hill climbing and annealing run one ("hill-climb", "anneal"). A stage that a
// limit stopped before its first pass is listed with no passes: it was set up, not run.
struct StageReport {
  std::string_view name;  // static storage
  uint32_t passes = 0;
  double seconds = 0.0;   // from the last stage's end (the first: its start) to the end of its last pass
  double cost = 0.0;      // the tree's cost when the stage ended (its best tree, if it kept one)
};

// Why an optimizer stopped.
enum class StopReason : uint8_t {
  converged,            // the method's own stopping rule
  pass_limit,           // OptimizeLimits::max_passes
  time_limit,           // OptimizeLimits::time_limit
  empty_tree,           // no tree to optimize
  nothing_to_optimize,  // a tree too small (or of zero area) for any move
  interrupted,          // OptimizeLimits::stop_requested
};
// "converged", "pass limit", "time limit", "empty tree", "nothing to optimize", "interrupted": the words the
// command line's --json "stop_reason" and the experiment's files carry.
std::string_view stop_reason_name(StopReason r);

struct OptimizeReport {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  uint32_t passes = 0;
  uint64_t moves = 0;
  double seconds = 0.0;
  StopReason stop_reason = StopReason::converged;
  std::vector<PassRecord> trace;
  std::vector<StageReport> stages;
  // The seconds before the first stage (insertion: numbering and refitting the tree, the
  // first stage's scan of it) and after the last (insertion: the final renumbering); with the
  // stages' seconds they add up to `seconds`. A run without stages (nothing to optimize)
  // spent all of it setting up.
  double setup_seconds = 0.0;
  double finish_seconds = 0.0;
};

// Called after every pass, from the calling thread; the command line draws its progress
// line from it.
using PassCallback = std::function<void(const PassRecord&)>;

}  // namespace bvhopt
