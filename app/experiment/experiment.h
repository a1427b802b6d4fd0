// The experiment runner: regenerates the results tables and figures of the three papers
// (Kensler 2008, Bittner et al. 2013, Dammertz and Keller 2008) on any set of scenes, and
// writes them as report.md, results.json and one CSV per table (docs/experiments.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "bvhopt/any_tracer.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {

// What the runner tells its caller after every step, for a progress line.
struct ExperimentProgress {
  std::string scene;
  std::string step;          // "hill climbing", "annealing", "rays primary", "t = 14", ...
  uint32_t pass = 0;         // optimizer pass within the step, 0 when none
  double elapsed = 0.0;      // seconds since the run started
  double remaining = 0.0;    // estimate, seconds; < 0 when unknown
  uint32_t task = 0;         // task (scene x protocol) being run, 1-based, of task_count
  uint32_t task_count = 0;
};
using ExperimentProgressCallback = std::function<void(const ExperimentProgress&)>;

struct ExperimentConfig {
  // Scene specs as load_scene takes them (files or builtin?triangles=N), in report order.
  std::vector<std::string> scenes;
  // Every random choice (ray sets, annealing, random insertion passes) flows from it.
  uint64_t seed = 1;
  // Seconds per scene for the optimizers. Annealing is shortened first: its schedule
  // (Kensler's N = 1250 passes, f = 50) is scaled down so that its estimated time fits
  // anneal_budget_fraction of the budget. The estimate is deterministic (inner nodes times
  // anneal_seconds_per_node_pass, not a clock), so the trees, and so every cost in
  // results.json, are the same on every machine, thread count and shard split. 0 = no budget:
  // the paper's full schedule.
  double time_budget = 150.0;
  double anneal_budget_fraction = 0.5;
  // Measured on the project's shared 2-core machine (Sponza, 2 threads): 25 ns per inner node
  // per annealing pass when quiet, up to 100 ns under heavy load; 40 ns assumed. With the
  // default budget every shared scene (up to 1.5 M inner nodes) gets the full schedule.
  double anneal_seconds_per_node_pass = 40e-9;
  // Rays per set (primary, random, ao, path) for the optimizer tables; each set is traced
  // once for the counters and `repeats` times for the clock, on 6 trees per scene.
  uint64_t rays = 1'000'000;
  // Rays per frame and per t for the Dammertz-Keller experiments (primary rays).
  uint64_t evh_rays = 300'000;
  // Timed passes per ray measurement (median reported).
  int repeats = 3;
  // The layout every ray measurement traces the trees in (the default: the fastest measured,
  // see any_tracer.h). Heat maps always show the binary tree's traversal steps.
  TraceLayout layout = kDefaultTraceLayout;
  // The cost model of the wide layout's collapse (its c_blk: --wide-block).
  WideCostModel wide_cost;
  // Figure 4's sweep of t (subdivision threshold exponent); Figure 5's frame count and t.
  std::vector<int> evh_t_values = {8, 10, 12, 14, 16, 18, 20};
  uint32_t rotation_frames = 64;
  int rotation_t = 14;
  // Scene for Figure 5: the first scene whose name contains this (case-insensitive), else
  // the first scene. Empty: no Figure 5.
  std::string rotation_scene = "sponza";
  // Heat map resolution (primary rays of the unoptimized and the best tree per scene).
  uint32_t heatmap_width = 512;
  uint32_t heatmap_height = 384;
  // Which part of the scene x protocol grid to run: task k runs in shard k mod shard_count.
  uint32_t shard_index = 0;
  uint32_t shard_count = 1;
  // Threads recorded in the report (the caller limits oneTBB itself); 0 = all cores.
  int threads = 0;
  // The plotting script (scripts/plot_experiment.py); empty or missing: no plots, and the
  // report says so.
  std::filesystem::path plot_script;
  ExperimentProgressCallback on_progress;
};

// Smaller settings for tests and trial runs: 20k rays, 4 frames, t in {10, 14}, a 10 s budget.
ExperimentConfig quick_experiment_config(ExperimentConfig base);

// The insertion of Bittner et al.'s Table 1 as published: the sequential form, batch
// k = 1 %, M_AREA, random selection after p_R = 5 and the stop after p_T = 10 passes in
// which the cost does not fall (any fall counts: no minimum improvement), no pass cap.
InsertionConfig bittner_paper_insertion_config(uint64_t seed);
// Our own form, a row of its own: the library's defaults (sequential, then a parallel
// polish and rotation sweeps; an improvement must exceed min_improvement; at most
// max_passes).
InsertionConfig hybrid_insertion_config(uint64_t seed);

// Runs this shard's part of the grid and writes results.json, the CSVs, the heat maps, the
// plots and report.md into `out` (created). Throws Error for a bad config or scene.
void run_experiment(const ExperimentConfig& config, const std::filesystem::path& out);

// Joins the results.json of several shard folders (each must hold a different part of one
// grid, run with the same settings) into `out`: results.json, CSVs, heat maps (copied),
// plots and report.md. Throws Error naming the folder for a missing or mismatched part.
void merge_experiments(const std::vector<std::filesystem::path>& parts, const std::filesystem::path& out,
                       const std::filesystem::path& plot_script = {});

// The fields of a results.json that do not depend on the clock: costs, counts, references,
// traversal steps, per-pass costs. Sharded and whole runs give the same text. Throws Error
// for a missing or unreadable file.
std::string deterministic_results(const std::filesystem::path& results_json);

}  // namespace bvhopt
