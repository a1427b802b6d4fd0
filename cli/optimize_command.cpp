// bvhopt optimize: improves an existing tree (a BVH file, or a scene built with sweep SAH and
// one reference per leaf) with one of the optimizers, and saves it.
//
// The options bind straight to the library's config structs, so every default is the
// library's own; the method names come from the library too. Loading, the progress line, the
// cost trace, the summary and writing the file know nothing of the method: to add one, give
// it a name in optimizer_method.h, its options in add_method_options and a case in
// run_method.
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "bvhopt/atomic_file.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/optimizer_method.h"
#include "bvhopt/references.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/tree_rotations.h"
#include "cli_common.h"
#include "commands.h"
#include "optimize_progress.h"

namespace bvhopt::cli {
namespace {

struct OptimizeOptions {
  SceneOption input;
  EvhOption evh;
  SceneBuilderOption builder;
  ThreadsOption threads;
  CostOption cost;
  bool cost_given = false;  // --ct or --ci given: they replace a BVH file's own cost model
  // Insertion by default: the lowest cost per second of the three (see README).
  std::string method = std::string(optimizer_method_name(OptimizerMethod::insertion));
  // What every method shares: --passes, --time-limit and --seed (the cost model and the
  // callback are filled in at run time).
  OptimizerConfig shared;
  std::string time_budget;  // --time-budget: seconds or a multiple of the build time; empty for none
  AnnealConfig anneal;
  bool no_keep_best = false;
  bool no_rotations = false;
  bool no_parallel_start = false;
  InsertionConfig insertion;
  std::string measure = std::string(measure_name(InsertionConfig{}.measure));
  std::string form = std::string(form_name(InsertionConfig{}.form));
  std::string trace_path;
  std::string output;
  bool json = false;
};

std::string method_help(OptimizerMethod m) {
  switch (m) {
    case OptimizerMethod::hill_climb: return "Kensler's tree rotations, hill climbing until no move improves";
    case OptimizerMethod::anneal: return "Kensler's tree rotations with simulated annealing";
    case OptimizerMethod::insertion:
      return "Bittner et al.'s insertion-based optimization: remove nodes, reinsert their children at the best place";
  }
  return "";
}

template <class T, class Name>
std::vector<std::string> names_of(const std::vector<T>& values, Name name) {
  std::vector<std::string> names;
  for (T v : values) names.emplace_back(name(v));
  return names;
}

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : " | ") + n;
  return s;
}

void add_method_options(CLI::App* cmd, OptimizeOptions& opt) {
  cmd->add_option("--schedule-passes", opt.anneal.schedule_passes,
                  "anneal: schedule length N in passes (then the quench)")
      ->check(whole_number(1, UINT32_MAX))
      ->capture_default_str();
  cmd->add_option("--period", opt.anneal.period, "anneal: period f of the sine schedule, in passes")
      ->check(whole_number(1, UINT32_MAX))
      ->capture_default_str();
  cmd->add_option("--h", opt.anneal.h, "anneal: hottest temperature, in Kensler's units (0.8-2.2)")
      ->check(finite_number())
      ->check(non_negative_number())
      ->capture_default_str();
  cmd->add_flag("--no-keep-best", opt.no_keep_best,
                "anneal: return the last tree, not the best seen at the end of a pass");

  cmd->add_option("--batch", opt.insertion.batch, "insertion: fraction of the inner nodes updated per pass")
      ->check(finite_number())
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  const std::vector<std::string> measures = names_of(insertion_measures(), measure_name);
  cmd->add_option("--measure", opt.measure, "insertion: node selection measure (" + joined(measures) + ")")
      ->check(CLI::IsMember(measures))
      ->capture_default_str();
  cmd->add_option("--form", opt.form,
                  "insertion: sequential (the paper's) | parallel (deterministic) | hybrid (the first, then the second, then "
                  "rotation sweeps; regional from 1M nodes) | regional (the paper's passes on all threads, in disjoint "
                  "subtrees, batch after batch down the ranking, with rotation sweeps)")
      ->check(CLI::IsMember(names_of(insertion_forms(), form_name)))
      ->capture_default_str();
  cmd->add_flag("--no-rotations", opt.no_rotations,
                "insertion: leave out the rotation sweeps (Kensler's hill climbing) that the hybrid and regional forms "
                "run after their insertion stages");
  cmd->add_flag("--no-parallel-start", opt.no_parallel_start,
                "insertion: the regional form starts with its sequential passes, without the parallel first stage "
                "(more gain in short runs on very large trees, as bake --quality fast; a higher converged cost)");
  cmd->add_option("--random-after", opt.insertion.random_after,
                  "insertion: passes without improvement before random selection (p_R)")
      ->check(whole_number(0, UINT32_MAX))
      ->capture_default_str();
  cmd->add_option("--stop-after", opt.insertion.stop_after,
                  "insertion: passes without improvement before stopping (p_T)")
      ->check(whole_number(1, UINT32_MAX))
      ->capture_default_str();
}

// Runs the chosen method with the shared settings over its own.
OptimizeReport run_method(Bvh& bvh, OptimizerMethod method, const OptimizeOptions& opt, const OptimizerConfig& shared) {
  switch (method) {
    case OptimizerMethod::hill_climb: {
      HillClimbConfig cfg;
      static_cast<OptimizerConfig&>(cfg) = shared;
      return hill_climb(bvh, cfg);
    }
    case OptimizerMethod::anneal: {
      AnnealConfig cfg = opt.anneal;
      static_cast<OptimizerConfig&>(cfg) = shared;
      cfg.keep_best = !opt.no_keep_best;
      return anneal(bvh, cfg);
    }
    case OptimizerMethod::insertion: {
      InsertionConfig cfg = opt.insertion;
      const uint32_t default_cap = cfg.limits.max_passes;
      static_cast<OptimizerConfig&>(cfg) = shared;
      if (cfg.limits.max_passes == 0) cfg.limits.max_passes = default_cap;  // the cap stays as a safety net
      cfg.measure = parse_measure(opt.measure).value_or(cfg.measure);
      cfg.form = parse_form(opt.form).value_or(cfg.form);
      cfg.rotations = !opt.no_rotations;
      cfg.parallel_start = !opt.no_parallel_start;
      return optimize_insertion(bvh, cfg);
    }
  }
  throw Error("optimize: unknown method");
}

struct Loaded {
  Bvh bvh;
  PrimitiveRefs refs;
  // A scene built by the sweep over its mesh (no subdivision): the references are made from
  // it, the same, once the optimizer is done, for the file. The optimizers need only the
  // tree; the mesh costs about half what the references would while they run.
  std::optional<Mesh> mesh;
  BvhFileInfo info;
  double load_seconds = 0.0;
  double build_seconds = 0.0;  // 0 for a BVH file
};

// A path ending in .bvh is a BVH file; anything else is a scene, built with sweep SAH.
Loaded load_input(const SceneOption& scene, const EvhOption& evh, const SceneBuilderOption& builder,
                  const CostModel& cost, bool cost_given) {
  Loaded in;
  Stopwatch clock;
  if (std::filesystem::path(scene.spec).extension() == ".bvh") {
    if (!scene.rotate.empty()) throw Error(scene.spec + ": --rotate applies to scenes, not to BVH files");
    if (evh.enabled) throw Error(scene.spec + ": --evh applies to scenes, not to BVH files");
    BvhFile file = read_bvh_file(scene.spec);
    in.bvh = std::move(file.bvh);
    in.refs = std::move(file.refs);
    in.info = std::move(file.info);
    if (cost_given) in.info.cost = cost;
    in.load_seconds = clock.seconds();
    return in;
  }
  Mesh mesh = scene.load();
  in.load_seconds = clock.seconds();
  Stopwatch build_clock;
  if (builder.name == "sweep" && !evh.enabled) {
    // The same tree as from references, at 93 bytes a triangle instead of 133.
    BuildOptions options;
    options.cost = cost;
    in.bvh = build_sweep_sah(mesh, sweep_sah_config(options));
    in.build_seconds = build_clock.seconds();
    in.info = scene_info(mesh, cost, builder.name);
    in.mesh = std::move(mesh);
    return in;
  }
  BuiltTree built = builder.build(mesh, evh.make_refs(mesh), cost);
  in.bvh = std::move(built.bvh);
  in.refs = std::move(built.refs);
  in.build_seconds = build_clock.seconds();
  in.info = scene_info(mesh, cost, (evh.enabled ? "evh+" : "") + builder.name);
  return in;
}

std::string trace_csv(const OptimizeReport& report) {
  std::ostringstream f;
  f.precision(10);
  // Columns are only ever added at the end, so that readers of older traces keep working.
  f << "pass,cost,best_cost,temperature,moves,seconds,stage,stage_name\n";
  // Row 0 is the tree before the first pass: no stage has run yet.
  f << 0 << ',' << report.initial_cost << ',' << report.initial_cost << ",0,0,0,0,\n";
  for (const PassRecord& p : report.trace)
    f << p.pass << ',' << p.cost << ',' << p.best_cost << ',' << p.temperature << ',' << p.moves << ',' << p.seconds
      << ',' << p.stage << ',' << p.stage_name << '\n';
  return f.str();
}

void print_report_json(const OptimizeOptions& opt, const Loaded& in, const BvhFileInfo& info, const OptimizeReport& report,
                       double ocost) {
  nlohmann::json j = {{"input", opt.input.spec},
                  {"method", opt.method},
                  {"file_method", info.method},
                  {"triangles", info.scene_triangles},
                  {"threads", opt.threads.effective()},
                  {"seed", opt.shared.seed},
                  {"load_seconds", in.load_seconds},
                  {"build_seconds", in.build_seconds},
                  {"cost_before", report.initial_cost},
                  {"cost_after", report.final_cost},
                  {"ratio", report.initial_cost > 0 ? report.final_cost / report.initial_cost : 1.0},
                  {"ocost", ocost},
                  {"passes", report.passes},
                  {"moves", report.moves},
                  {"seconds", report.seconds},
                  {"stop_reason", std::string(stop_reason_name(report.stop_reason))},
                  {"cost_trace", opt.trace_path},
                  {"output", opt.output}};
  j.update(stages_json(report));
  // Which insertion form ran: hybrid takes another on large trees.
  if (parse_optimizer_method(opt.method) == OptimizerMethod::insertion) {
    const InsertionForm form =
        resolved_form(parse_form(opt.form).value_or(InsertionConfig{}.form), in.bvh.nodes.size());
    j["insertion_form"] = std::string(form_name(form));
    // Whether the form runs rotation sweeps after its insertion stages (the regional form
    // and hybrid's small-tree stages do, unless --no-rotations; a run that a limit stops
    // early may not reach them), and whether it starts with the regional form's parallel
    // stage.
    j["insertion_rotations"] = !opt.no_rotations && form != InsertionForm::sequential && form != InsertionForm::parallel;
    j["insertion_parallel_start"] = !opt.no_parallel_start && form == InsertionForm::regional;
  }
  print_json(j);
}

void print_summary(const OptimizeOptions& opt, const Loaded& in, const BvhFileInfo& info, const OptimizeReport& report,
                   double ocost) {
  const double ratio = report.initial_cost > 0 ? report.final_cost / report.initial_cost : 1.0;
  std::cout << "input      " << opt.input.spec << " (" << info.scene_triangles << " triangles"
            << (in.build_seconds > 0 ? ", built in " + format_double(in.build_seconds, 2) + " s" : "")
            << ")\n"
            << "method     " << opt.method << ", " << opt.threads.effective() << " threads, seed " << opt.shared.seed
            << "\n"
            << "cost       " << format_double(report.initial_cost, 4) << " -> " << format_double(report.final_cost, 4)
            << "  (" << format_double(100.0 * ratio, 2) << " %)\n"
            << "ocost      " << format_double(ocost, 4) << "\n"
            << "passes     " << report.passes << " (" << stop_reason_name(report.stop_reason) << "), " << report.moves
            << " moves\n"
            << "time       " << format_double(report.seconds, 3) << " s\n"
            << "stages     " << stages_text(report) << "\n"
            << "written    " << opt.output << " (" << info.method << ")\n";
  if (!opt.trace_path.empty()) std::cout << "cost trace " << opt.trace_path << "\n";
}

void run_optimize(const OptimizeOptions& opt) {
  // Before the work: a typo in an output path must not cost the optimization.
  check_output_path(opt.output, "-o");
  if (!opt.trace_path.empty()) check_output_path(opt.trace_path, "--cost-trace");
  auto threads = opt.threads.apply();
  Loaded in = load_input(opt.input, opt.evh, opt.builder, opt.cost.model(), opt.cost_given);
  const std::optional<OptimizerMethod> method = parse_optimizer_method(opt.method);
  if (!method) throw Error("optimize: unknown method '" + opt.method + "'");

  ProgressLine progress;
  OptimizerConfig shared = opt.shared;
  shared.cost = in.info.cost;
  if (!opt.time_budget.empty()) shared.limits.time_budget = parse_time_budget(opt.time_budget, in.build_seconds);
  GainEstimate gain(sah_cost(in.bvh, in.info.cost));
  const bool annealing = *method == OptimizerMethod::anneal;
  shared.limits.on_pass = [&progress, &gain, annealing](const PassRecord& p) {
    gain.add(p.best_cost);
    progress.update(progress_text(p, gain, annealing));
  };
  OptimizeReport report = run_method(in.bvh, *method, opt, shared);
  progress.finish();

  if (in.mesh) {
    in.refs = make_references(*in.mesh);
    in.mesh.reset();
  }
  BvhFileInfo info = in.info;
  info.method = (info.method.empty() ? std::string("unknown") : info.method) + "+" + opt.method;
  // Both outputs or neither.
  OutputGroup outputs;
  outputs.add(opt.output, [&](const std::filesystem::path& tmp) { write_bvh_file(tmp, in.bvh, in.refs, info); });
  if (!opt.trace_path.empty()) outputs.add_text(opt.trace_path, trace_csv(report));
  outputs.commit();
  const double ocost = optimal_collapse_cost(in.bvh, in.refs, info.cost);
  if (opt.json)
    print_report_json(opt, in, info, report, ocost);
  else
    print_summary(opt, in, info, report, ocost);
}

}  // namespace

void register_optimize_command(CLI::App& app) {
  auto opt = std::make_shared<OptimizeOptions>();
  CLI::App* cmd = app.add_subcommand(
      "optimize", "Improve a BVH (a .bvh file, or a scene built with sweep SAH, one reference per leaf) and save it");
  opt->input.add_to(cmd, "input");
  cmd->get_option("input")->description(
      "A BVH file (*.bvh, from bvhopt build or optimize), or a scene: a file assimp reads or "
      "builtin[:atrium][?triangles=N&seed=S], built with sweep SAH, one reference per leaf");
  std::vector<std::string> names;
  std::string help = "Optimizer:";
  for (OptimizerMethod m : optimizer_methods()) {
    names.emplace_back(optimizer_method_name(m));
    help += "\n  " + names.back() + ": " + method_help(m);
  }
  cmd->add_option("--method", opt->method, help)->check(CLI::IsMember(names))->capture_default_str();
  cmd->add_option("--passes", opt->shared.limits.max_passes, "Stop after this many passes (0: no limit)")
      ->check(whole_number(0, UINT32_MAX))
      ->capture_default_str();
  cmd->add_option("--time-limit", opt->shared.limits.time_limit,
                  "Stop after the pass that reaches this many seconds (0: none)")
      ->check(finite_number())
      ->check(non_negative_number())
      ->type_name("S");
  cmd->add_option("--time-budget", opt->time_budget,
                  "The seconds the optimizer may take, its work after the last pass included: a pass that would "
                  "end too late, judged by the one before, is not started (the best tree seen is kept); in seconds "
                  "or, for a scene, as a multiple of its build time: 5x")
      ->type_name("S|Nx")
      ->excludes("--time-limit");
  cmd->add_option("--seed", opt->shared.seed, "Seed of every random choice")->check(whole_number(0, UINT64_MAX))->capture_default_str();
  cmd->add_option("--cost-trace", opt->trace_path, "Write the cost after every pass as CSV (pass, cost, best_cost, temperature, moves, seconds, stage: the method's stage that ran the pass, from 0, stage_name: its name)")->type_name("FILE.csv");
  opt->builder.add_to(cmd);
  opt->evh.add_to(cmd);
  opt->cost.add_to(cmd);
  opt->threads.add_to(cmd);
  add_method_options(cmd, *opt);
  cmd->add_option("-o,--output", opt->output, "BVH file to write")->required();
  cmd->add_flag("--json", opt->json, "Print the summary as JSON");

  cmd->callback([opt, cmd] {
    opt->cost_given = cmd->count("--ct") > 0 || cmd->count("--ci") > 0;
    run_optimize(*opt);
  });
}

}  // namespace bvhopt::cli
