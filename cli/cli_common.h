// What every subcommand shares: thread count, scene options, JSON output, the progress line.
#pragma once

#include <CLI/CLI.hpp>
#include <tbb/global_control.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "bvhopt/build.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"
#include "bvhopt/spatial_split_builder.h"
#include "bvhopt/vec3.h"

namespace bvhopt::cli {

// Refuses NaN and infinities, which pass CLI11's range checks (every comparison with NaN is
// false). Put it before the range check: `->check(finite_number())->check(CLI::Range(...))`.
CLI::Validator finite_number();

// A number > 0 (or >= 0), said in those words: CLI11's PositiveNumber and NonNegativeNumber
// print the largest double, 309 digits, as the range's upper bound. Put finite_number()
// first.
CLI::Validator positive_number();
CLI::Validator non_negative_number();

// A whole number written in digits from `lo` to `hi` (CLI11 reads "-1" into an unsigned
// option as 2^64 - 1).
CLI::Validator whole_number(uint64_t lo, uint64_t hi);

// --threads N (default: all cores). Keep the returned object alive for the command's run.
struct ThreadsOption {
  int threads = 0;
  void add_to(CLI::App* app);
  std::unique_ptr<tbb::global_control> apply() const;
  int effective() const;  // the number of threads actually used
};

// A scene argument plus the options that shape it wherever a scene is loaded.
struct SceneOption {
  std::string spec;       // a file, or builtin[:atrium][?triangles=N&seed=S]
  std::string rotate;     // "X,Y,Z" degrees, empty for none
  void add_to(CLI::App* app, const std::string& name = "scene", bool required = true);
  Mesh load() const;      // loads, checks and rotates; throws Error
};

// --evh [--evh-t N]: Dammertz and Keller's edge volume subdivision of the triangles into
// references, wherever a scene is built.
struct EvhOption {
  bool enabled = false;
  int t = EdgeVolumeConfig{}.t;
  double max_ratio = EdgeVolumeConfig{}.max_reference_ratio;
  void add_to(CLI::App* app);
  // One reference per triangle, or the subdivided references when enabled; `report` gets a
  // line saying what was done (empty when not enabled).
  PrimitiveRefs make_refs(const Mesh& mesh, std::string* report = nullptr) const;
};

// The sbvh builder's settings (SpatialSplitParams): --budget R (most references per
// triangle), --split-alpha A, --spatial-bins N and --spatial-from N.
void add_budget_option(CLI::App* app, SpatialSplitParams& params);

// --builder NAME [--budget R] for the commands that build a scene to optimize it (bake,
// optimize): leaves of one reference, the optimizers' starting point.
struct SceneBuilderOption {
  std::string name = "sweep";
  SpatialSplitParams sbvh;
  void add_to(CLI::App* app);
  // Leaves of one reference unless asked (the SAH builders then test each leaf's cost).
  BuiltTree build(const Mesh& mesh, PrimitiveRefs refs, const CostModel& cost, uint32_t max_leaf_size = 1) const;
};

// --ct / --ci: the SAH cost constants.
struct CostOption {
  double traversal = CostModel{}.traversal;
  double intersection = CostModel{}.intersection;
  void add_to(CLI::App* app);
  CostModel model() const { return CostModel{traversal, intersection}; }
};

// Seconds since construction.
class Stopwatch {
 public:
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// A single status line redrawn on stderr, only when stderr is a terminal and at most a few
// times a second, so pipes and CI logs stay clean.
class ProgressLine {
 public:
  ProgressLine();
  ~ProgressLine();
  void update(const std::string& text, bool force = false);
  void finish();  // clears the line
 private:
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_{};
};

bool stderr_is_terminal();

// Prints JSON to stdout (pretty, with a trailing newline).
void print_json(const nlohmann::json& j);
// An sbvh build's counts, as build and bake report them under "spatial_split".
nlohmann::json spatial_split_json(const SpatialSplitStats& s);

// Fixed-width table printing for human output.
std::string format_double(double v, int precision);

}  // namespace bvhopt::cli
