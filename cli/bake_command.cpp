// bvhopt bake: the one command from a scene to a finished tree. Builds with sweep SAH, or
// spatial splits for --quality best (one reference per leaf, what the optimizer does best
// with; --builder overrides), optimizes with insertion under a
// time budget, collapses subtrees into leaves where cheaper, and writes the file, with the
// cost, the time and the peak memory of every step.
//
// The quality levels differ in the optimizer's default budget, as a multiple of the
// build time (the insertion optimizer makes most of its gain early, docs in README), and
// best in its builder (docs/spatial-splits.md).
#include <sys/resource.h>

#include <iostream>
#include <string>

#include "bvhopt/bvh_file.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/references.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/atomic_file.h"
#include "bvhopt/triangle_cost.h"
#include "cli_common.h"
#include "commands.h"
#include "optimize_progress.h"

namespace bvhopt::cli {
namespace {

struct BakeOptions {
  SceneOption scene;
  SceneBuilderOption builder;  // name empty: the quality's builder
  ThreadsOption threads;
  CostOption cost;
  std::string quality = "balanced";
  std::string time_budget;  // empty: the quality's default
  std::string output;
  bool json = false;
};

// The optimizer's budget of each quality, in build times; 0 = until it converges.
double budget_in_build_times(const std::string& quality) {
  if (quality == "fast") return 1.0;
  if (quality == "balanced") return 5.0;
  return 0.0;  // best
}

// The builder of each quality when --builder is not given: spatial splits for best, where
// their lower cost is worth their build time and 1.3x references (the table in
// docs/spatial-splits.md), sweep SAH otherwise.
std::string builder_for(const std::string& quality) { return quality == "best" ? "sbvh" : "sweep"; }

// Peak resident memory of the process so far (Linux reports kilobytes).
uint64_t peak_rss_bytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<uint64_t>(usage.ru_maxrss) * 1024u;
}

struct BakeResult {
  uint64_t triangles = 0;
  double load_seconds = 0.0, build_seconds = 0.0, optimize_seconds = 0.0, collapse_seconds = 0.0;
  double budget_seconds = 0.0;
  double cost_built = 0.0, cost_optimized = 0.0, cost_final = 0.0;
  OptimizeReport report;
  uint64_t leaves = 0;
  uint64_t peak_rss = 0;
  std::string builder;
  uint64_t references = 0;  // made by the builder (before the collapse keeps one per triangle in a leaf)
};

BakeResult bake(const BakeOptions& opt) {
  BakeResult r;
  ProgressLine progress;
  progress.update("loading " + opt.scene.spec, true);
  Stopwatch load_clock;
  Mesh mesh = opt.scene.load();
  r.triangles = mesh.triangle_count();
  r.load_seconds = load_clock.seconds();

  progress.update("building " + std::to_string(r.triangles) + " triangles", true);
  const CostModel cost = opt.cost.model();
  Stopwatch build_clock;
  SceneBuilderOption builder = opt.builder;
  if (builder.name.empty()) builder.name = builder_for(opt.quality);
  r.builder = builder.name;
  BuiltTree built = builder.build(mesh, make_references(mesh), cost);
  Bvh& bvh = built.bvh;
  PrimitiveRefs& refs = built.refs;
  r.references = refs.size();
  r.build_seconds = build_clock.seconds();
  r.cost_built = sah_cost(bvh, cost);

  r.budget_seconds = opt.time_budget.empty() ? budget_in_build_times(opt.quality) * r.build_seconds
                                             : parse_time_budget(opt.time_budget, r.build_seconds);
  InsertionConfig insertion;
  insertion.cost = cost;
  insertion.limits.time_limit = r.budget_seconds;
  GainEstimate gain(r.cost_built);
  insertion.limits.on_pass = [&](const PassRecord& p) {
    gain.add(p.best_cost);
    progress.update("optimizing: " + progress_text(p, gain, false));
  };
  // The optimizer needs only the tree: one reference per triangle (40 bytes a triangle) is
  // dropped while it runs and made again, the same, for the collapse and the file. Split
  // references (sbvh) are the builder's own and stay.
  const bool remade = refs.size() == mesh.triangle_count() && builder.name != "sbvh";
  if (remade) refs = PrimitiveRefs{};
  r.report = optimize_insertion(bvh, insertion);
  if (remade) refs = make_references(mesh);
  r.optimize_seconds = r.report.seconds;
  r.cost_optimized = r.report.final_cost;

  progress.update("collapsing leaves", true);
  Stopwatch collapse_clock;
  CollapseConfig collapse;
  collapse.cost = cost;
  // With split references a leaf keeps each triangle once and the cost counts triangles.
  const CollapseResult c = collapse_leaves(bvh, refs, collapse);
  r.collapse_seconds = collapse_clock.seconds();
  r.cost_final = c.cost_after;
  r.leaves = c.leaves_after;
  // The file holds the binary tree: trace and render rebuild their wide layout (--layout
  // bvh4|bvh8, wide_bvh.h) from it on load. A stored wide layout would be written here.

  const BvhFileInfo info = scene_info(mesh, cost, r.builder + "+insertion+collapse");
  progress.update("writing " + opt.output, true);
  write_bvh_file(opt.output, bvh, refs, info);
  progress.finish();
  r.peak_rss = peak_rss_bytes();
  return r;
}

void print_bake_json(const BakeOptions& opt, const BakeResult& r) {
  print_json({{"scene", opt.scene.spec},
              {"triangles", r.triangles},
              {"quality", opt.quality},
              {"builder", r.builder},
              {"references", r.references},
              {"threads", opt.threads.effective()},
              {"load_seconds", r.load_seconds},
              {"build_seconds", r.build_seconds},
              {"time_budget_seconds", r.budget_seconds},
              {"optimize_seconds", r.optimize_seconds},
              {"collapse_seconds", r.collapse_seconds},
              {"cost_built", r.cost_built},
              {"cost_optimized", r.cost_optimized},
              {"cost", r.cost_final},
              {"passes", r.report.passes},
              {"stop_reason", std::string(stop_reason_name(r.report.stop_reason))},
              {"leaves", r.leaves},
              {"peak_rss_bytes", r.peak_rss},
              {"output", opt.output}});
}

void print_bake_summary(const BakeOptions& opt, const BakeResult& r) {
  const double mib = 1024.0 * 1024.0;
  std::cout << "scene      " << opt.scene.spec << " (" << r.triangles << " triangles, loaded in "
            << format_double(r.load_seconds, 2) << " s)\n"
            << "build      " << r.builder << " (" << r.references << " references), cost " << format_double(r.cost_built, 4) << ", "
            << format_double(r.build_seconds, 2) << " s\n"
            << "optimize   insertion, cost " << format_double(r.cost_optimized, 4) << ", "
            << format_double(r.optimize_seconds, 2) << " s, " << r.report.passes << " passes ("
            << stop_reason_name(r.report.stop_reason) << "; budget "
            << (r.budget_seconds > 0 ? format_double(r.budget_seconds, 2) + " s" : std::string("none")) << ")\n"
            << "collapse   cost " << format_double(r.cost_final, 4) << ", " << r.leaves << " leaves, "
            << format_double(r.collapse_seconds, 2) << " s\n"
            << "memory     peak " << format_double(r.peak_rss / mib, 1) << " MiB ("
            << format_double(r.triangles ? double(r.peak_rss) / double(r.triangles) : 0.0, 1)
            << " bytes per triangle)\n"
            << "written    " << opt.output << " (quality " << opt.quality << ", "
            << opt.threads.effective() << " threads)\n";
}

}  // namespace

void register_bake_command(CLI::App& app) {
  auto opt = std::make_shared<BakeOptions>();
  CLI::App* cmd = app.add_subcommand(
      "bake", "Build, optimize and collapse a scene's BVH in one step, with the recommended settings, and save it");
  opt->scene.add_to(cmd);
  cmd->add_option("--quality", opt->quality,
                  "fast: optimize for 1x the build time | balanced: 5x | best: until the optimizer converges")
      ->check(CLI::IsMember({"fast", "balanced", "best"}))
      ->capture_default_str();
  opt->builder.name.clear();
  opt->builder.add_to(cmd);
  cmd->get_option("--builder")->description(cmd->get_option("--builder")->get_description() +
                                            ". Default: sbvh for --quality best, sweep otherwise");
  cmd->add_option("--time-budget", opt->time_budget,
                  "The optimizer's budget instead of the quality's, in seconds or as a multiple of the build time: 3x")
      ->type_name("S|Nx");
  opt->cost.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_option("-o,--output", opt->output, "BVH file to write")->required();
  cmd->add_flag("--json", opt->json, "Print the summary as JSON");
  cmd->callback([opt] {
    check_output_path(opt->output, "-o");
    auto threads = opt->threads.apply();
    const BakeResult r = bake(*opt);
    if (opt->json)
      print_bake_json(*opt, r);
    else
      print_bake_summary(*opt, r);
  });
}

}  // namespace bvhopt::cli
