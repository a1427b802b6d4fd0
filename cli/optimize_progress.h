// The optimizers' progress: the time budget a user gives (seconds, or a multiple of the build
// time) and the line redrawn after every pass, with the share of the gain reached so far.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bvhopt/optimize_report.h"

namespace bvhopt::cli {

// "S" (seconds) or "Nx" (N times the build time, for a scene built by the command).
// Throws Error for anything else, or for "Nx" when nothing was built (build_seconds 0).
double parse_time_budget(const std::string& text, double build_seconds);

// Estimates the cost the run converges to from the best costs so far: the gains of the last
// two windows of passes shrink geometrically, the rest of that series is what is left.
// Without two shrinking windows there is no estimate.
class GainEstimate {
 public:
  explicit GainEstimate(double initial_cost) : initial_(initial_cost) {}
  void add(double best_cost) { best_.push_back(best_cost); }
  // Share in [0, 1] of the estimated total gain reached; negative when unknown.
  double fraction() const;

 private:
  static constexpr size_t kWindow = 5;
  double initial_;
  std::vector<double> best_;
};

// "pass 12  regional  cost 210.4  best 209.9  gain 87 %  3.1 s" (the stage's name, and T too
// when the method has one).
std::string progress_text(const PassRecord& p, const GainEstimate& gain, bool with_temperature);

// Where a run's time went, stage by stage: "parallel 20 passes 0.15 s -> 269.79, ...; setup
// 0.02 s, finish 0.05 s" for the summary, and the same as --json's "stages" (name, passes,
// seconds, cost), "setup_seconds" and "finish_seconds".
std::string stages_text(const OptimizeReport& report);
nlohmann::json stages_json(const OptimizeReport& report);

}  // namespace bvhopt::cli
