// `bvhopt experiment`: the papers' tables and figures on a set of scenes, as a report;
// `bvhopt experiment merge`: joins the parts of a sharded run.
#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "bvhopt/error.h"
#include "experiment/experiment.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/atomic_file.h"
#include "cli_common.h"
#include "commands.h"
#include "trace_common.h"

namespace bvhopt::cli {
namespace {

namespace fs = std::filesystem;

struct ExperimentOptions {
  std::string scenes_dir;
  std::vector<std::string> scenes;
  std::string out;
  double time_budget = ExperimentConfig{}.time_budget;
  uint64_t seed = 1;
  uint64_t rays = ExperimentConfig{}.rays;
  std::string shard;
  bool quick = false;
  std::string plot_script;
  ThreadsOption threads;
  LayoutOption layout;
  WideCostOption wide_cost;
  std::vector<std::string> merge_dirs;
  std::string merge_out;
};

// Mesh files in a scenes folder, by name, so the grid (and so the shards) are the same on
// every machine. READMEs, checksums and licence folders are skipped.
std::vector<std::string> scenes_in(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error("--scenes " + dir + ": not a folder");
  static const char* const kExtensions[] = {".obj", ".ply", ".glb", ".gltf", ".fbx", ".dae", ".3ds", ".stl", ".off"};
  std::vector<std::string> out;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file()) continue;
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (std::find(std::begin(kExtensions), std::end(kExtensions), ext) != std::end(kExtensions))
      out.push_back(entry.path().string());
  }
  if (ec) throw Error("--scenes " + dir + ": cannot list: " + ec.message());
  std::sort(out.begin(), out.end());
  if (out.empty()) throw Error("--scenes " + dir + ": no scene files (.obj, .ply, .glb, ...) in it");
  return out;
}

// "I/N" with 1 <= I <= N, as people count shards (a Slurm array index from 1).
void parse_shard(const std::string& text, uint32_t& index, uint32_t& count) {
  const auto slash = text.find('/');
  try {
    if (slash == std::string::npos) throw std::invalid_argument("no slash");
    size_t used = 0;
    const unsigned long i = std::stoul(text.substr(0, slash), &used);
    if (used != slash) throw std::invalid_argument("index");
    const std::string rest = text.substr(slash + 1);
    const unsigned long n = std::stoul(rest, &used);
    if (used != rest.size()) throw std::invalid_argument("count");
    if (n == 0 || i == 0 || i > n || n > 100000) throw std::out_of_range("range");
    index = static_cast<uint32_t>(i - 1);
    count = static_cast<uint32_t>(n);
  } catch (const std::exception&) {
    throw Error("--shard '" + text + "': expected I/N with 1 <= I <= N (e.g. 2/8)");
  }
}

// The plotting script: --plot-script, $BVHOPT_PLOT_SCRIPT, then beside the program as it is
// built (build/<dir>/bvhopt) or installed (bin/ and share/bvhopt/), then ./scripts.
fs::path find_plot_script(const std::string& given) {
  if (!given.empty()) return given;
  if (const char* env = std::getenv("BVHOPT_PLOT_SCRIPT"); env && *env) return env;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  std::vector<fs::path> candidates;
  if (!ec) {
    const fs::path dir = exe.parent_path();
    candidates = {dir / "../../scripts/plot_experiment.py", dir / "../scripts/plot_experiment.py",
                  dir / "../share/bvhopt/plot_experiment.py"};
  }
  candidates.push_back(fs::path("scripts") / "plot_experiment.py");
  for (const fs::path& c : candidates)
    if (fs::exists(c, ec)) return fs::weakly_canonical(c, ec);
  return {};
}

std::string clock_text(double seconds) {
  if (seconds < 0) return "?";
  const long s = static_cast<long>(seconds + 0.5);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%ld:%02ld", s / 60, s % 60);
  return buf;
}

// The run's settings from the options; an explicit --time-budget or --rays wins over --quick's.
ExperimentConfig experiment_config(const ExperimentOptions& opt, bool budget_given, bool rays_given) {
  if (opt.out.empty()) throw Error("experiment: --out DIR is required");
  ExperimentConfig config;
  if (!opt.scenes_dir.empty()) config.scenes = scenes_in(opt.scenes_dir);
  for (const std::string& s : opt.scenes) config.scenes.push_back(s);
  if (config.scenes.empty()) throw Error("experiment: give --scenes DIR or --scene FILE");
  config.seed = opt.seed;
  config.layout = opt.layout.layout();
  config.wide_cost = opt.wide_cost.model();
  config.rays = opt.rays;
  if (opt.quick) config = quick_experiment_config(config);
  if (budget_given || !opt.quick) config.time_budget = opt.time_budget;
  if (rays_given) config.rays = opt.rays;
  if (!opt.shard.empty()) parse_shard(opt.shard, config.shard_index, config.shard_count);
  config.plot_script = find_plot_script(opt.plot_script);
  return config;
}

void run_experiment_command(const ExperimentOptions& opt, bool budget_given, bool rays_given) {
  ExperimentConfig config = experiment_config(opt, budget_given, rays_given);
  check_output_folder(opt.out, "--out");
  auto limit = opt.threads.apply();
  config.threads = opt.threads.effective();

  ProgressLine progress;
  std::string last_step;
  config.on_progress = [&](const ExperimentProgress& p) {
    std::string text = "[" + std::to_string(p.task) + "/" + std::to_string(p.task_count) + "] " + p.scene + ": " + p.step;
    if (p.pass > 0) text += ", pass " + std::to_string(p.pass);
    text += "  elapsed " + clock_text(p.elapsed) + ", remaining ~" + clock_text(p.remaining);
    progress.update(text, p.step != last_step);
    last_step = p.step;
  };
  Stopwatch watch;
  run_experiment(config, opt.out);
  progress.finish();
  std::cout << "experiment: " << config.scenes.size() << " scenes";
  if (config.shard_count > 1) std::cout << " (shard " << config.shard_index + 1 << "/" << config.shard_count << ")";
  std::cout << " in " << format_double(watch.seconds(), 1) << " s; report: "
            << (fs::path(opt.out) / "report.md").string() << "\n";
}

void run_merge_command(const ExperimentOptions& opt) {
  check_output_folder(opt.merge_out, "--out");
  std::vector<fs::path> parts(opt.merge_dirs.begin(), opt.merge_dirs.end());
  merge_experiments(parts, opt.merge_out, find_plot_script(opt.plot_script));
  std::cout << "merged " << parts.size() << " parts into " << (fs::path(opt.merge_out) / "report.md").string() << "\n";
}

}  // namespace

void register_experiment_command(CLI::App& app) {
  auto opt = std::make_shared<ExperimentOptions>();
  CLI::App* cmd = app.add_subcommand(
      "experiment", "Regenerate the papers' tables and figures on a set of scenes: report.md, results.json, CSVs, plots");
  cmd->add_option("--scenes", opt->scenes_dir, "Folder of scenes: every mesh file in it, by name")->type_name("DIR");
  cmd->add_option("--scene", opt->scenes, "A scene (file or builtin?triangles=N); repeatable, after --scenes' ones")
      ->type_name("FILE");
  cmd->add_option("--out", opt->out, "Output folder")->type_name("DIR");
  cmd->add_option("--time-budget", opt->time_budget,
                  "Seconds per scene for the optimizers; annealing's schedule is scaled to fit (0: the paper's full schedule)")
      ->capture_default_str();
  cmd->add_option("--seed", opt->seed, "Seed of every random choice")->check(whole_number(0, UINT64_MAX))->capture_default_str();
  cmd->add_option("--rays", opt->rays, "Rays per set (primary, random, ao, path)")
      ->check(whole_number(1, kMaxRayCount))
      ->capture_default_str();
  cmd->add_option("--shard", opt->shard, "Run only part I of N of the scene x protocol grid (join with `merge`)")
      ->type_name("I/N");
  cmd->add_flag("--quick", opt->quick, "Small settings for a trial run: 20k rays, 4 frames, t in {10, 14}, 10 s budget");
  cmd->add_option("--plot-script", opt->plot_script, "The plotting script (default: scripts/plot_experiment.py found beside the program)");
  opt->layout.add_to(cmd);
  opt->wide_cost.add_to(cmd);
  opt->threads.add_to(cmd);

  CLI::App* merge = cmd->add_subcommand("merge", "Join the output folders of the shards of one run into one report");
  merge->add_option("dirs", opt->merge_dirs, "Shard output folders")->required()->check(CLI::ExistingDirectory);
  merge->add_option("--out", opt->merge_out, "Output folder")->required()->type_name("DIR");
  merge->add_option("--plot-script", opt->plot_script, "The plotting script");
  merge->callback([opt] { run_merge_command(*opt); });
  cmd->callback([opt, cmd, merge] {
    if (merge->parsed()) return;
    run_experiment_command(*opt, cmd->count("--time-budget") > 0, cmd->count("--rays") > 0);
  });
}

}  // namespace bvhopt::cli
