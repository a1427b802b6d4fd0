// bvhopt bake: the one command from a scene to a finished tree. Builds with sweep SAH, or
// spatial splits for --quality best (one reference per leaf, what the optimizer does best
// with; --builder overrides), optimizes with insertion under a
// time budget, collapses subtrees into leaves where cheaper, and writes the file, with the
// cost, the time and the peak memory of every step. --quality best runs this from three
// starts, leaves of one, the builder's SAH leaves of up to 8, and those again with spatial
// splits only in nodes of at most 256 references, and keeps the cheapest tree
// (default_starts says why).
//
// The quality levels differ in the optimizer's default budget, as a multiple of the
// build time (the insertion optimizer makes most of its gain early, docs in README), and
// best in its builder (docs/spatial-splits.md).
#include <sys/resource.h>

#include <algorithm>
#include <cctype>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "bvhopt/bvh_file.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/references.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/atomic_file.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/wide_bvh.h"
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
  std::vector<uint32_t> start_leaf_sizes;  // empty: the quality's
  std::vector<std::string> starts;         // LEAF[:SPATIAL_MAX] each; empty: the above
  // The collapse never makes a leaf of more references than the wide layouts hold, so that
  // what bake writes traces in every layout (0: no limit, the paper's ocost).
  uint32_t max_leaf_size = kWideMaxLeafTriangles;
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

// Where a start begins: the build's largest leaf (1: one reference per leaf; more: the
// builder's SAH leaf test decides) and, for sbvh, the largest node that tries spatial
// splits (0: every node, SpatialSplitParams::spatial_max).
struct StartSpec {
  uint32_t leaf_size = 1;
  uint32_t spatial_max = 0;
  bool operator==(const StartSpec&) const = default;
};

// One start of the pipeline: the build, insertion, the collapse.
struct BakeStart {
  StartSpec spec;
  double build_seconds = 0.0, optimize_seconds = 0.0, collapse_seconds = 0.0;
  double budget_seconds = 0.0;  // the optimizer's (0: until it converges)
  double cost_built = 0.0, cost_optimized = 0.0, cost_final = 0.0;
  OptimizeReport report;
  uint64_t leaves = 0;
  uint64_t references = 0;  // made by the builder (before the collapse keeps one per triangle in a leaf)
  std::optional<SpatialSplitStats> spatial_split;  // the sbvh builder's counts
  std::string insertion_form;  // the form the optimizer took (hybrid resolves by the tree's size)
  bool insertion_parallel_start = false;  // the regional form's parallel first stage ran
  Bvh bvh;
  PrimitiveRefs refs;
};

struct BakeResult {
  uint64_t triangles = 0;
  double load_seconds = 0.0;
  double budget_seconds = 0.0;
  std::string builder;
  std::vector<BakeStart> starts;  // every start, trees dropped but the kept one's
  size_t kept = 0;                // the start with the lowest final cost
  uint64_t peak_rss = 0;
  const BakeStart& best() const { return starts[kept]; }
};

// The starts of --quality best. Insertion moves whole leaves, so what it optimizes depends
// on the build's leaves: from leaves of one it reaches the lowest final cost on the scanned
// and character meshes, from the SBVH's own SAH leaves (up to 8) on the architectural
// scenes and the CAD engine, where the collapse after a one-per-leaf optimization undoes
// part of its gain (Sponza 142.77 from leaves of one, 141.76 from leaves of up to 8; with
// an earlier builder 142.86 at 4, 142.45 at 8, 142.69 at 16). Insertion also never merges
// a triangle's pieces again, so the spatial splits the greedy build makes near the root
// stay: with them only in nodes of at most 256 references, Conference reaches 75.11
// instead of 76.55 and staircase 35.25 instead of 36.55, and their rays visit fewer nodes;
// Sponza and the CAD engine lose (143.58 against 141.76, 225.86 against 213.98). The tables are in
// docs/spatial-splits.md. No start wins everywhere, and all converge in seconds on the
// shared scenes, so best runs them all and keeps the cheapest.
// The first two take --spatial-max (0 unless given).
std::vector<StartSpec> default_starts(const std::string& quality, uint32_t spatial_max) {
  if (quality != "best") return {{1, spatial_max}};
  return {{1, spatial_max}, {8, spatial_max}, {8, 256}};
}

// "8" or "8:256" (leaf size, spatial_max).
StartSpec parse_start(const std::string& text) {
  const size_t colon = text.find(':');
  const auto number = [&](const std::string& part, uint64_t lo, uint64_t hi) {
    size_t used = 0;
    uint64_t v = 0;
    bool ok = !part.empty() && std::isdigit(static_cast<unsigned char>(part[0]));
    if (ok) {
      try {
        v = std::stoull(part, &used);
      } catch (const std::exception&) {
        ok = false;
      }
    }
    if (!ok || used != part.size() || v < lo || v > hi)
      throw Error("'" + text + "' is not LEAF[:SPATIAL_MAX] (LEAF 1 to 65535, SPATIAL_MAX 0 to 4294967295)");
    return static_cast<uint32_t>(v);
  };
  StartSpec s;
  s.leaf_size = number(text.substr(0, colon), 1, 65535);
  if (colon != std::string::npos) s.spatial_max = number(text.substr(colon + 1), 0, 0xffffffffu);
  return s;
}

// The starts this bake runs: --starts, else --start-leaf-sizes (each with the builder's
// --spatial-max), else the quality's. spatial_max means nothing to other builders than
// sbvh, so there it is 0 and a start equal to an earlier one is dropped.
std::vector<StartSpec> starts_of(const BakeOptions& opt, const SceneBuilderOption& builder) {
  std::vector<StartSpec> wanted;
  if (!opt.starts.empty())
    for (const std::string& t : opt.starts) wanted.push_back(parse_start(t));
  else if (!opt.start_leaf_sizes.empty())
    for (uint32_t leaf : opt.start_leaf_sizes) wanted.push_back({leaf, builder.sbvh.spatial_max});
  else
    wanted = default_starts(opt.quality, builder.sbvh.spatial_max);
  std::vector<StartSpec> out;
  for (StartSpec s : wanted) {
    if (builder.name != "sbvh") s.spatial_max = 0;
    if (std::find(out.begin(), out.end(), s) == out.end()) out.push_back(s);
  }
  return out;
}

std::string start_text(const StartSpec& s) {
  std::string text = "leaves of up to " + std::to_string(s.leaf_size);
  if (s.spatial_max) text += ", spatial splits in nodes of at most " + std::to_string(s.spatial_max) + " references";
  return text;
}

// `share`: this start's part of a --time-budget given in seconds (a multiple of the build
// time, or the quality's, applies to each start's own build).
BakeStart bake_start(const BakeOptions& opt, const Mesh& mesh, SceneBuilderOption builder, const StartSpec& spec,
                     double share, ProgressLine& progress, const std::string& label) {
  BakeStart s;
  s.spec = spec;
  builder.sbvh.spatial_max = spec.spatial_max;
  progress.update("building " + std::to_string(mesh.triangle_count()) + " triangles" + label, true);
  const CostModel cost = opt.cost.model();
  Stopwatch build_clock;
  if (builder.name == "sweep" && spec.leaf_size == 1) {
    // Over the mesh itself, with no references beside the tree: the same tree, at 93 bytes
    // a triangle instead of 133 (build_sweep_sah(const Mesh&)). The references are made
    // for the file, after the collapse (below).
    BuildOptions options;
    options.cost = cost;
    s.bvh = build_sweep_sah(mesh, sweep_sah_config(options));
    s.references = mesh.triangle_count();
    s.build_seconds = build_clock.seconds();
    s.cost_built = sah_cost(s.bvh, cost);  // one triangle a leaf: nothing counted twice
  } else {
    BuiltTree built = builder.build(mesh, make_references(mesh), cost, spec.leaf_size);
    s.bvh = std::move(built.bvh);
    s.refs = std::move(built.refs);
    s.references = s.refs.size();
    s.spatial_split = built.spatial_split;
    s.build_seconds = build_clock.seconds();
    s.cost_built = sah_cost(s.bvh, s.refs, cost);
  }

  const std::string& text = opt.time_budget;
  const bool in_seconds = !text.empty() && text.back() != 'x' && text.back() != 'X';
  s.budget_seconds = text.empty() ? budget_in_build_times(opt.quality) * s.build_seconds
                                  : parse_time_budget(text, s.build_seconds) * (in_seconds ? share : 1.0);
  InsertionConfig insertion;
  insertion.cost = cost;
  insertion.limits.time_budget = s.budget_seconds;
  // Within one build time the sequential passes by the measure gain the most at first: fast
  // starts with them, without the regional form's parallel first stage (hall, 10M triangles,
  // 9 s: 468.29, against 481.98 with that stage and 477.50 for the paper's sequential form,
  // which fast took before the rotation sweeps).
  if (opt.quality == "fast") insertion.parallel_start = false;
  const InsertionForm form = resolved_form(insertion.form, s.bvh.nodes.size());
  s.insertion_form = std::string(form_name(form));
  s.insertion_parallel_start = form == InsertionForm::regional && insertion.parallel_start;
  GainEstimate gain(s.cost_built);
  insertion.limits.on_pass = [&](const PassRecord& p) {
    gain.add(p.best_cost);
    progress.update("optimizing" + label + ": " + progress_text(p, gain, false));
  };
  // The optimizer needs only the tree: one reference per triangle (40 bytes a triangle) is
  // dropped while it runs. Nothing is counted twice then, so the costs and the collapse
  // need no references either: they are made again, the same, for the file only, once the
  // collapse has freed its scratch and the tree has shrunk to its nodes in use (bake's peak
  // had been the collapse, with the references made again beside it: about 190 bytes
  // a triangle at 2M and 10M). Split references (sbvh) are the builder's own and stay.
  const bool remade = (s.refs.empty() || s.refs.size() == mesh.triangle_count()) && builder.name != "sbvh";
  if (remade) s.refs = PrimitiveRefs{};
  s.report = optimize_insertion(s.bvh, insertion);
  s.optimize_seconds = s.report.seconds;
  s.cost_optimized = remade ? sah_cost(s.bvh, cost) : sah_cost(s.bvh, s.refs, cost);

  progress.update("collapsing leaves" + label, true);
  Stopwatch collapse_clock;
  CollapseConfig collapse;
  collapse.cost = cost;
  collapse.max_leaf_size = opt.max_leaf_size;
  // With split references a leaf keeps each triangle once and the cost counts triangles.
  const CollapseResult c = remade ? collapse_leaves(s.bvh, collapse) : collapse_leaves(s.bvh, s.refs, collapse);
  s.collapse_seconds = collapse_clock.seconds();
  if (remade) {
    s.bvh.nodes.shrink_to_fit();
    s.refs = make_references(mesh);
  }
  s.cost_final = c.cost_after;
  s.leaves = c.leaves_after;
  return s;
}

BakeResult bake(const BakeOptions& opt) {
  BakeResult r;
  ProgressLine progress;
  progress.update("loading " + opt.scene.spec, true);
  Stopwatch load_clock;
  Mesh mesh = opt.scene.load();
  r.triangles = mesh.triangle_count();
  r.load_seconds = load_clock.seconds();

  SceneBuilderOption builder = opt.builder;
  if (builder.name.empty()) builder.name = builder_for(opt.quality);
  r.builder = builder.name;
  const std::vector<StartSpec> specs = starts_of(opt, builder);
  for (size_t k = 0; k < specs.size(); ++k) {
    const std::string label =
        specs.size() > 1 ? " (start " + std::to_string(k + 1) + " of " + std::to_string(specs.size()) + ", " +
                               start_text(specs[k]) + ")"
                         : std::string();
    BakeStart s = bake_start(opt, mesh, builder, specs[k], 1.0 / double(specs.size()), progress, label);
    r.budget_seconds += s.budget_seconds;
    r.starts.push_back(std::move(s));
    BakeStart& last = r.starts.back();
    if (last.cost_final < r.best().cost_final) {
      r.starts[r.kept].bvh = Bvh{};
      r.starts[r.kept].refs = PrimitiveRefs{};
      r.kept = r.starts.size() - 1;
    } else if (r.starts.size() - 1 != r.kept) {
      last.bvh = Bvh{};
      last.refs = PrimitiveRefs{};
    }
  }
  // The file holds the binary tree: trace and render rebuild their wide layout (--layout
  // bvh4|bvh8, wide_bvh.h) from it on load. A stored wide layout would be written here.
  const BvhFileInfo info = scene_info(mesh, opt.cost.model(), r.builder + "+insertion+collapse");
  progress.update("writing " + opt.output, true);
  write_bvh_file(opt.output, r.best().bvh, r.best().refs, info);
  progress.finish();
  r.peak_rss = peak_rss_bytes();
  return r;
}

// Times are the whole bake's (every start); costs, passes and leaves are the kept start's.
void print_bake_json(const BakeOptions& opt, const BakeResult& r) {
  const BakeStart& best = r.best();
  double build = 0.0, optimize = 0.0, collapse = 0.0;
  nlohmann::json starts = nlohmann::json::array();
  for (const BakeStart& s : r.starts) {
    build += s.build_seconds, optimize += s.optimize_seconds, collapse += s.collapse_seconds;
    starts.push_back({{"leaf_size", s.spec.leaf_size},
                      {"spatial_max", s.spec.spatial_max},
                      {"references", s.references},
                      {"build_seconds", s.build_seconds},
                      {"time_budget_seconds", s.budget_seconds},
                      {"optimize_seconds", s.optimize_seconds},
                      {"collapse_seconds", s.collapse_seconds},
                      {"cost_built", s.cost_built},
                      {"cost_optimized", s.cost_optimized},
                      {"cost", s.cost_final},
                      {"passes", s.report.passes},
                      {"stop_reason", std::string(stop_reason_name(s.report.stop_reason))},
                      {"insertion_form", s.insertion_form},
                      {"insertion_parallel_start", s.insertion_parallel_start},
                      {"optimize_profile", stages_json(s.report)},
                      {"leaves", s.leaves}});
    if (s.spatial_split) starts.back()["spatial_split"] = spatial_split_json(*s.spatial_split);
  }
  nlohmann::json out = {{"scene", opt.scene.spec},
                        {"triangles", r.triangles},
                        {"quality", opt.quality},
                        {"builder", r.builder},
                        {"references", best.references},
                        {"threads", opt.threads.effective()},
                        {"load_seconds", r.load_seconds},
                        {"build_seconds", build},
                        {"time_budget_seconds", r.budget_seconds},
                        {"optimize_seconds", optimize},
                        {"collapse_seconds", collapse},
                        {"cost_built", best.cost_built},
                        {"cost_optimized", best.cost_optimized},
                        {"cost", best.cost_final},
                        {"passes", best.report.passes},
                        {"stop_reason", std::string(stop_reason_name(best.report.stop_reason))},
                        {"insertion_form", best.insertion_form},
                        {"insertion_parallel_start", best.insertion_parallel_start},
                        {"optimize_profile", stages_json(best.report)},
                        {"leaves", best.leaves},
                        {"start_leaf_size", best.spec.leaf_size},
                        {"start_spatial_max", best.spec.spatial_max},
                        {"max_leaf_size", opt.max_leaf_size},
                        {"starts", starts},
                        {"peak_rss_bytes", r.peak_rss},
                        {"output", opt.output}};
  if (best.spatial_split) out["spatial_split"] = spatial_split_json(*best.spatial_split);
  print_json(out);
}

void print_bake_summary(const BakeOptions& opt, const BakeResult& r) {
  const double mib = 1024.0 * 1024.0;
  std::cout << "scene      " << opt.scene.spec << " (" << r.triangles << " triangles, loaded in "
            << format_double(r.load_seconds, 2) << " s)\n";
  for (size_t k = 0; k < r.starts.size(); ++k) {
    const BakeStart& s = r.starts[k];
    if (r.starts.size() > 1)
      std::cout << "start " << k + 1 << "    " << start_text(s.spec)
                << (k == r.kept ? " (kept: lowest cost)" : "") << "\n";
    std::string made = std::to_string(s.references) + " references";
    if (s.spatial_split)
      made += ", " + std::to_string(s.spatial_split->spatial_splits) + " spatial splits, " +
              std::to_string(s.spatial_split->split_references) + " references cut";
    std::cout << "build      " << r.builder << " (" << made << "), cost "
              << format_double(s.cost_built, 4) << ", " << format_double(s.build_seconds, 2) << " s\n"
              << "optimize   insertion, cost " << format_double(s.cost_optimized, 4) << ", "
              << format_double(s.optimize_seconds, 2) << " s, " << s.report.passes << " passes ("
              << stop_reason_name(s.report.stop_reason) << "; budget "
              << (s.budget_seconds > 0 ? format_double(s.budget_seconds, 2) + " s" : std::string("none")) << ")\n"
              << "  stages   " << stages_text(s.report) << "\n"
              << "collapse   cost " << format_double(s.cost_final, 4) << ", " << s.leaves << " leaves, "
              << format_double(s.collapse_seconds, 2) << " s\n";
  }
  std::cout << "memory     peak " << format_double(r.peak_rss / mib, 1) << " MiB ("
            << format_double(r.triangles ? double(r.peak_rss) / double(r.triangles) : 0.0, 1)
            << " bytes per triangle)\n"
            << "written    " << opt.output << " (quality " << opt.quality << ", cost "
            << format_double(r.best().cost_final, 4) << ", " << opt.threads.effective() << " threads)\n";
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
  CLI::Option* leaf_sizes =
      cmd->add_option("--start-leaf-sizes", opt->start_leaf_sizes,
                      "Build, optimize and collapse from each of these leaf sizes (with --spatial-max) and keep the "
                      "cheapest tree; a --time-budget in seconds is shared among them (default: see --starts)")
          ->delimiter(',')
          ->check(CLI::Range(1u, 65535u))
          ->type_name("N,...");
  cmd->add_option("--starts", opt->starts,
                  "As --start-leaf-sizes, each start a leaf size and, for sbvh, the largest node that tries spatial "
                  "splits (0: all). Default: 1,8,8:256 for --quality best, 1 otherwise (with --spatial-max M: 1:M,8:M,8:256 "
                  "and 1:M)")
      ->delimiter(',')
      ->type_name("LEAF[:SPATIAL_MAX],...")
      ->check(
          [](const std::string& text) {
            try {
              parse_start(text);
              return std::string();
            } catch (const Error& e) {
              return std::string(e.what());
            }
          },
          "LEAF[:SPATIAL_MAX]")
      ->excludes(leaf_sizes);
  cmd->add_option("--max-leaf-size", opt->max_leaf_size,
                  "Never collapse into a leaf of more references than this (default: 64, the most a wide leaf "
                  "holds, so the tree traces in every layout; 0: no limit, the paper's ocost)")
      ->check(CLI::Range(0u, 0xffffffffu))
      ->capture_default_str();
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
