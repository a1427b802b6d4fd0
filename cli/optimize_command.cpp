// bvhopt optimize: improves an existing tree (a BVH file, or a scene built with sweep SAH and
// one reference per leaf) with one of the optimizers, and saves it.
//
// The methods are a table: each entry names itself, registers its own options and runs on
// the shared settings (cost model, pass and time limits, seed, per-pass callback). Loading,
// the progress line, the cost trace, the summary and writing the file know nothing of the
// method. To add one (e.g. insertion-based optimization with --batch and --measure), append
// an entry to method_table() with its options struct held by a shared_ptr.
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <sstream>
#include <vector>

#include "bvhopt/atomic_file.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/references.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/tree_rotations.h"
#include "cli_common.h"
#include "commands.h"

namespace bvhopt::cli {
namespace {

// What every method gets from the shared options.
struct RunSettings {
  CostModel cost;
  uint32_t max_passes = 0;   // 0: the method's own stopping rule only
  double time_limit = 0.0;   // seconds, 0: none
  uint64_t seed = 1;
  PassCallback on_pass;
};

struct Method {
  std::string name;  // the --method value, also appended to the file's method string
  std::string help;
  std::function<void(CLI::App*)> add_options;  // method-specific options (may be empty)
  std::function<OptimizeReport(Bvh&, const RunSettings&)> run;
};

std::vector<Method> method_table() {
  std::vector<Method> table;

  table.push_back({"hill-climb", "Kensler's tree rotations, hill climbing until no move improves", nullptr,
                   [](Bvh& bvh, const RunSettings& s) {
                     HillClimbConfig cfg;
                     cfg.cost = s.cost;
                     cfg.limits = {s.max_passes, s.time_limit};
                     cfg.on_pass = s.on_pass;
                     return hill_climb(bvh, cfg);
                   }});

  auto anneal_opt = std::make_shared<AnnealConfig>();
  auto no_keep_best = std::make_shared<bool>(false);
  table.push_back({"anneal", "Kensler's tree rotations with simulated annealing",
                   [anneal_opt, no_keep_best](CLI::App* cmd) {
                     cmd->add_option("--schedule-passes", anneal_opt->schedule_passes,
                                     "anneal: schedule length N in passes (then the quench)")
                         ->capture_default_str();
                     cmd->add_option("--period", anneal_opt->period, "anneal: period f of the sine schedule, in passes")
                         ->check(CLI::PositiveNumber)
                         ->capture_default_str();
                     cmd->add_option("--h", anneal_opt->h, "anneal: hottest temperature, in Kensler's units (0.8-2.2)")
                         ->check(CLI::NonNegativeNumber)
                         ->capture_default_str();
                     cmd->add_flag("--no-keep-best", *no_keep_best,
                                   "anneal: return the last tree, not the best seen at the end of a pass");
                   },
                   [anneal_opt, no_keep_best](Bvh& bvh, const RunSettings& s) {
                     AnnealConfig cfg = *anneal_opt;
                     cfg.cost = s.cost;
                     cfg.seed = s.seed;
                     cfg.keep_best = !*no_keep_best;
                     cfg.limits = {s.max_passes, s.time_limit};
                     cfg.on_pass = s.on_pass;
                     return anneal(bvh, cfg);
                   }});

  // Insertion-based optimization (issue 4).
  auto insertion_opt = std::make_shared<InsertionConfig>();
  auto insertion_measure = std::make_shared<std::string>("area");
  auto insertion_form = std::make_shared<std::string>("hybrid");
  table.push_back(
      {"insertion", "Bittner et al.'s insertion-based optimization: remove nodes, reinsert their children at the best place",
       [insertion_opt, insertion_measure, insertion_form](CLI::App* cmd) {
         cmd->add_option("--batch", insertion_opt->batch, "insertion: fraction of the inner nodes updated per pass")
             ->check(CLI::Range(0.0, 1.0))
             ->capture_default_str();
         cmd->add_option("--measure", *insertion_measure, "insertion: node selection measure (area | sum | min | comb)")
             ->check(CLI::IsMember({"area", "sum", "min", "comb"}))
             ->capture_default_str();
         cmd->add_option("--form", *insertion_form,
                         "insertion: sequential (the paper's) | parallel (deterministic) | hybrid (the first, then the second)")
             ->check(CLI::IsMember({"sequential", "parallel", "hybrid"}))
             ->capture_default_str();
         cmd->add_option("--random-after", insertion_opt->random_after,
                         "insertion: passes without improvement before random selection (p_R)")
             ->capture_default_str();
         cmd->add_option("--stop-after", insertion_opt->stop_after,
                         "insertion: passes without improvement before stopping (p_T)")
             ->check(CLI::PositiveNumber)
             ->capture_default_str();
       },
       [insertion_opt, insertion_measure, insertion_form](Bvh& bvh, const RunSettings& s) {
         InsertionConfig cfg = *insertion_opt;
         cfg.cost = s.cost;
         cfg.seed = s.seed;
         cfg.measure = parse_measure(*insertion_measure).value_or(InsertionMeasure::area);
         cfg.form = parse_form(*insertion_form).value_or(InsertionForm::hybrid);
         if (s.max_passes > 0) cfg.max_passes = s.max_passes;  // else the default cap stays as a safety net
         cfg.time_limit_seconds = s.time_limit;
         return optimize_insertion(bvh, cfg, s.on_pass);
       }});
  return table;
}

struct Loaded {
  Bvh bvh;
  PrimitiveRefs refs;
  BvhFileInfo info;
  double load_seconds = 0.0;
  double build_seconds = 0.0;  // 0 for a BVH file
};

// A path ending in .bvh is a BVH file; anything else is a scene, built with sweep SAH.
Loaded load_input(const SceneOption& scene, const EvhOption& evh, const CostModel& cost, bool cost_given) {
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
  in.refs = evh.make_refs(mesh);
  SweepSahConfig sweep;
  sweep.cost = cost;
  sweep.leaf.max_leaf_size = 1;
  in.bvh = build_sweep_sah(in.refs, sweep);
  in.build_seconds = build_clock.seconds();
  in.info.cost = cost;
  in.info.scene_name = mesh.name;
  in.info.scene_triangles = mesh.triangle_count();
  in.info.method = evh.enabled ? "evh+sweep" : "sweep";
  return in;
}

void write_trace_csv(const std::string& path, const OptimizeReport& report) {
  std::ostringstream f;
  f.precision(10);
  f << "pass,cost,best_cost,temperature,moves,seconds\n";
  f << 0 << ',' << report.initial_cost << ',' << report.initial_cost << ",0,0,0\n";
  for (const PassRecord& p : report.trace)
    f << p.pass << ',' << p.cost << ',' << p.best_cost << ',' << p.temperature << ',' << p.moves << ',' << p.seconds
      << '\n';
  write_text_atomically(path, f.str());
}

}  // namespace

void register_optimize_command(CLI::App& app) {
  struct Options {
    SceneOption input;
    EvhOption evh;
    ThreadsOption threads;
    CostOption cost;
    std::string method = "anneal";
    uint32_t passes = 0;
    double time_limit = 0.0;
    uint64_t seed = 1;
    std::string trace_path;
    std::string output;
    bool json = false;
  };
  auto opt = std::make_shared<Options>();
  auto methods = std::make_shared<std::vector<Method>>(method_table());

  CLI::App* cmd = app.add_subcommand(
      "optimize", "Improve a BVH (a .bvh file, or a scene built with sweep SAH, one reference per leaf) and save it");
  opt->input.add_to(cmd, "input");
  cmd->get_option("input")->description(
      "A BVH file (*.bvh, from bvhopt build or optimize), or a scene: a file assimp reads or "
      "builtin[:atrium][?triangles=N&seed=S], built with sweep SAH, one reference per leaf");
  std::vector<std::string> names;
  std::string method_help = "Optimizer:";
  for (const Method& m : *methods) {
    names.push_back(m.name);
    method_help += "\n  " + m.name + ": " + m.help;
  }
  cmd->add_option("--method", opt->method, method_help)->check(CLI::IsMember(names))->capture_default_str();
  cmd->add_option("--passes", opt->passes, "Stop after this many passes (0: no limit)")->capture_default_str();
  cmd->add_option("--time-limit", opt->time_limit, "Stop after the pass that reaches this many seconds (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->type_name("S");
  cmd->add_option("--seed", opt->seed, "Seed of every random choice")->capture_default_str();
  cmd->add_option("--cost-trace", opt->trace_path, "Write the cost after every pass as CSV")->type_name("FILE.csv");
  opt->evh.add_to(cmd);
  opt->cost.add_to(cmd);
  opt->threads.add_to(cmd);
  for (const Method& m : *methods)
    if (m.add_options) m.add_options(cmd);
  cmd->add_option("-o,--output", opt->output, "BVH file to write")->required();
  cmd->add_flag("--json", opt->json, "Print the summary as JSON");

  cmd->callback([opt, methods, cmd] {
    auto threads = opt->threads.apply();
    const bool cost_given = cmd->count("--ct") > 0 || cmd->count("--ci") > 0;
    Loaded in = load_input(opt->input, opt->evh, opt->cost.model(), cost_given);
    const Method* method = nullptr;
    for (const Method& m : *methods)
      if (m.name == opt->method) method = &m;
    if (!method) throw Error("optimize: unknown method '" + opt->method + "'");

    ProgressLine progress;
    RunSettings settings;
    settings.cost = in.info.cost;
    settings.max_passes = opt->passes;
    settings.time_limit = opt->time_limit;
    settings.seed = opt->seed;
    settings.on_pass = [&progress](const PassRecord& p) {
      std::ostringstream line;
      line << "pass " << p.pass << "  T " << format_double(p.temperature, 3) << "  cost " << format_double(p.cost, 4)
           << "  best " << format_double(p.best_cost, 4) << "  " << format_double(p.seconds, 1) << " s";
      progress.update(line.str());
    };
    OptimizeReport report = method->run(in.bvh, settings);
    progress.finish();

    if (!opt->trace_path.empty()) write_trace_csv(opt->trace_path, report);
    BvhFileInfo info = in.info;
    info.method = (info.method.empty() ? std::string("unknown") : info.method) + "+" + method->name;
    write_bvh_file(opt->output, in.bvh, in.refs, info);
    const double ocost = optimal_collapse_cost(in.bvh, info.cost);

    if (opt->json) {
      print_json({{"input", opt->input.spec},
                  {"method", method->name},
                  {"file_method", info.method},
                  {"triangles", info.scene_triangles},
                  {"threads", opt->threads.effective()},
                  {"seed", opt->seed},
                  {"load_seconds", in.load_seconds},
                  {"build_seconds", in.build_seconds},
                  {"cost_before", report.initial_cost},
                  {"cost_after", report.final_cost},
                  {"ratio", report.initial_cost > 0 ? report.final_cost / report.initial_cost : 1.0},
                  {"ocost", ocost},
                  {"passes", report.passes},
                  {"moves", report.moves},
                  {"seconds", report.seconds},
                  {"stop_reason", report.stop_reason},
                  {"cost_trace", opt->trace_path},
                  {"output", opt->output}});
      return;
    }
    const double ratio = report.initial_cost > 0 ? report.final_cost / report.initial_cost : 1.0;
    std::cout << "input      " << opt->input.spec << " (" << info.scene_triangles << " triangles"
              << (in.build_seconds > 0 ? ", sweep SAH built in " + format_double(in.build_seconds, 2) + " s" : "")
              << ")\n"
              << "method     " << method->name << ", " << opt->threads.effective() << " threads, seed " << opt->seed
              << "\n"
              << "cost       " << format_double(report.initial_cost, 4) << " -> " << format_double(report.final_cost, 4)
              << "  (" << format_double(100.0 * ratio, 2) << " %)\n"
              << "ocost      " << format_double(ocost, 4) << "\n"
              << "passes     " << report.passes << " (" << report.stop_reason << "), " << report.moves << " moves\n"
              << "time       " << format_double(report.seconds, 3) << " s\n"
              << "written    " << opt->output << " (" << info.method << ")\n";
    if (!opt->trace_path.empty()) std::cout << "cost trace " << opt->trace_path << "\n";
  });
}

}  // namespace bvhopt::cli
