// What every optimizer reports: the cost trace of its passes and a summary.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
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
};

struct OptimizeReport {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  uint32_t passes = 0;
  uint64_t moves = 0;
  double seconds = 0.0;
  std::string stop_reason;  // "converged", "pass limit", "time limit", ...
  std::vector<PassRecord> trace;
};

// Called after every pass, from the calling thread; the command line draws its progress
// line from it.
using PassCallback = std::function<void(const PassRecord&)>;

}  // namespace bvhopt
