// The pass loop every optimizer runs (private to the library): the clock, the limits, the
// per-pass record and callback, the stop reason, and keeping the best tree seen.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string_view>
#include <utility>

#include "bvhopt/cost.h"
#include "bvhopt/optimize_report.h"
#include "bvhopt/optimizer_config.h"

namespace bvhopt::detail {

// What one pass tells the driver.
struct PassResult {
  double cost = 0.0;         // the tree's cost after the pass
  uint64_t moves = 0;
  double temperature = 0.0;
  bool converged = false;    // the method's own stopping rule is met
};

// One optimizer run. The clock starts at construction, so setup counts in the reported
// seconds. A method with several stages (insertion's hybrid form) calls run() once per stage
// on the same driver: pass numbers, limits and the trace run across the stages.
class PassDriver {
 public:
  explicit PassDriver(const OptimizeLimits& limits) : limits_(limits) {}

  // The cost before the first pass (also the final cost of a run that makes no pass).
  // A cost that is not a number is an error (Error), never a result: no run converges on it.
  void set_initial_cost(double cost) {
    check_finite_cost(cost, "optimize");
    report_.initial_cost = report_.final_cost = cost;
    best_ = cost;
  }

  double elapsed() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

  // The seconds the method will spend after its last pass, kept from the time budget.
  void reserve_for_finish(double seconds) { finish_reserve_ = seconds; }
  // How long the next stage's first pass is expected to take, where the method can tell
  // (the time budget judges it by that, and by the last pass's callback).
  void expect_first_pass(double seconds) { first_pass_estimate_ = seconds; }

  // Runs passes of `work` until its stopping rule or a limit, then leaves the lowest-cost
  // tree of this stage in it if the work asked for that. Work provides:
  //   double cost() const                      the tree's cost now
  //   bool keep_best_before(uint32_t pass)     whether `pass` may raise the cost and the
  //                                            best tree is wanted back if it does
  //   Snapshot snapshot() const; void restore(const Snapshot&)
  //   PassResult run_pass(uint32_t pass, double stage_best)
  // Passes are numbered from 0 over the whole run; stage_best is the lowest cost of this
  // stage before the pass (its starting cost included).
  // `name` (static storage) names the stage in the report.
  template <class Work>
  void run(Work& work, std::string_view name) {
    // A later stage's time runs from the last one's end, so that it counts its own start
    // (insertion: the new stage's scan of the tree) and the stages add up to the run.
    const double stage_begin = report_.stages.empty() ? elapsed() : stage_end_;
    if (report_.stages.empty()) report_.setup_seconds = stage_begin;
    const uint32_t passes_before = report_.passes;
    stage_name_ = name;
    double stage_best = work.cost();
    bool current_is_best = true;
    // Valid only while it holds the tree of cost stage_best. Taken lazily, just before a pass
    // that may lose that tree, and only if the current tree is that one.
    std::optional<decltype(work.snapshot())> best_tree;
    // A later stage's start: the last stage ended by its own rule, which record() reports
    // before the limits, so they are looked at here again. Without this a stage that ended
    // past the time limit handed on to one more pass (at 4M triangles within 1x the build
    // time, a pass of 0.17 s beyond it).
    bool stage_start = true;
    while (true) {
      if (limits_.max_passes != 0 && report_.passes >= limits_.max_passes) {  // a later stage's start
        report_.stop_reason = StopReason::pass_limit;
        break;
      }
      if (stage_start && report_.passes > 0) {
        if (limits_.time_limit > 0.0 && elapsed() >= limits_.time_limit) {
          report_.stop_reason = StopReason::time_limit;
          break;
        }
        if (limits_.stop_requested && limits_.stop_requested()) {
          report_.stop_reason = StopReason::interrupted;
          break;
        }
      }
      const bool first_of_stage = stage_start;
      stage_start = false;
      // The time budget, before a pass: one as long as the last would end too late. A
      // stage's first pass is not judged by the stage before's, which say little about it
      // (hall 10M, insertion: 0.30 s after passes of 0.50, 0.40 after 0.22), and a guess
      // from them can cost a whole stage: the 4M hall within 1x the build time, judged by
      // the sequential stage's last pass (or twice it), stopped before its first
      // rotation sweep (0.1 s) in two runs of three, at 373.13 instead of about 367. So a
      // budget can be overrun by a stage's first pass, unless the method said what to expect
      // of it. The callback's time, which the pass would add again, counts either way.
      const double pass_start = elapsed();
      const double next_pass = first_of_stage ? first_pass_estimate_ + last_callback_seconds_ : last_pass_seconds_;
      if (first_of_stage) first_pass_estimate_ = 0.0;
      if (limits_.time_budget > 0.0 && report_.passes > 0 &&
          pass_start + next_pass + finish_reserve_ > limits_.time_budget) {
        report_.stop_reason = StopReason::time_limit;
        break;
      }
      const uint32_t pass = report_.passes;
      if (current_is_best && !best_tree && work.keep_best_before(pass)) best_tree = work.snapshot();
      const PassResult r = work.run_pass(pass, stage_best);
      if (r.cost < stage_best) {
        stage_best = r.cost;
        best_tree.reset();
      }
      current_is_best = r.cost <= stage_best;
      const bool stop = record(r);
      last_pass_seconds_ = elapsed() - pass_start;
      if (stop) break;
    }
    if (!current_is_best && best_tree) work.restore(std::move(*best_tree));
    report_.final_cost = work.cost();
    check_finite_cost(report_.final_cost, "optimize");
    stage_end_ = elapsed();
    report_.stages.push_back({name, report_.passes - passes_before, stage_end_ - stage_begin, report_.final_cost});
    ++stage_;
  }

  // After the last stage (or instead of any): the report, with the total time.
  OptimizeReport finish() {
    report_.seconds = elapsed();
    // A run without stages (nothing to optimize) spent its time setting up.
    if (report_.stages.empty())
      report_.setup_seconds = report_.seconds;
    else
      report_.finish_seconds = report_.seconds - stage_end_;
    return std::move(report_);
  }
  StopReason stop_reason() const { return report_.stop_reason; }
  void stop(StopReason reason) { report_.stop_reason = reason; }

 private:
  using Clock = std::chrono::steady_clock;

  // Adds the pass to the report and calls back; true when the run must stop.
  bool record(const PassResult& r) {
    check_finite_cost(r.cost, "optimize");
    best_ = std::min(best_, r.cost);
    PassRecord rec;
    rec.pass = ++report_.passes;
    rec.cost = r.cost;
    rec.best_cost = best_;
    rec.temperature = r.temperature;
    rec.moves = r.moves;
    rec.seconds = elapsed();
    rec.stage = stage_;
    rec.stage_name = stage_name_;
    report_.trace.push_back(rec);
    report_.moves += r.moves;
    if (limits_.on_pass) {
      const double before = elapsed();
      limits_.on_pass(rec);
      last_callback_seconds_ = elapsed() - before;
    }
    if (r.converged) {
      report_.stop_reason = StopReason::converged;
    } else if (limits_.max_passes != 0 && report_.passes >= limits_.max_passes) {
      report_.stop_reason = StopReason::pass_limit;
    } else if ((limits_.time_limit > 0.0 && rec.seconds >= limits_.time_limit) ||
               (limits_.time_budget > 0.0 && rec.seconds + finish_reserve_ >= limits_.time_budget)) {
      report_.stop_reason = StopReason::time_limit;
    } else if (limits_.stop_requested && limits_.stop_requested()) {
      report_.stop_reason = StopReason::interrupted;
    } else {
      return false;
    }
    return true;
  }

  const Clock::time_point start_ = Clock::now();
  const OptimizeLimits& limits_;
  OptimizeReport report_;
  double best_ = 0.0;  // lowest cost of the whole run, for the records
  double last_pass_seconds_ = 0.0;  // the last pass's, its record and callback included
  double finish_reserve_ = 0.0;
  double first_pass_estimate_ = 0.0;  // the next stage's first pass, if the method told
  double last_callback_seconds_ = 0.0;  // the last pass's on_pass
  uint32_t stage_ = 0;  // run() calls finished: the stage the next records belong to
  std::string_view stage_name_;  // its name
  double stage_end_ = 0.0;       // when the last stage ended
};

}  // namespace bvhopt::detail
