// bvhopt demo: the main job. Every builder and every optimizer on the built-in scene, each
// tree judged by the three numbers users care about (cost, time to get it, rays per second),
// plus heat maps of the unoptimized and the best tree, so a new user sees the whole library
// at work in one command.
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <optional>
#include <utility>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/finalize.h"
#include "bvhopt/font.h"
#include "bvhopt/image_legend.h"
#include "bvhopt/images.h"
#include "bvhopt/png_file.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/scene.h"
#include "bvhopt/stats.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/atomic_file.h"
#include "cli_common.h"
#include "trace_common.h"
#include "commands.h"

namespace bvhopt::cli {
namespace {

struct DemoRow {
  std::string method;
  double seconds = 0.0;  // build, or build + optimization for the optimized trees
  TreeStats stats;
  double primary_mrays = 0.0;
  double random_mrays = 0.0;
};

void print_table(const std::vector<DemoRow>& rows) {
  std::cout << std::left << std::setw(25) << "method" << std::right << std::setw(10) << "time ms" << std::setw(9)
            << "cost" << std::setw(9) << "ocost" << std::setw(9) << "nodes" << std::setw(7) << "depth"
            << std::setw(14) << "primary Mr/s" << std::setw(13) << "random Mr/s" << "\n";
  for (const DemoRow& r : rows)
    std::cout << std::left << std::setw(25) << r.method << std::right << std::setw(10)
              << format_double(r.seconds * 1e3, 1) << std::setw(9) << format_double(r.stats.cost, 2) << std::setw(9)
              << format_double(r.stats.ocost, 2) << std::setw(9) << r.stats.nodes << std::setw(7)
              << r.stats.max_depth << std::setw(14) << format_double(r.primary_mrays, 2) << std::setw(13)
              << format_double(r.random_mrays, 2) << "\n";
}

struct DemoOptions {
  uint64_t triangles = 250'000;
  uint64_t seed = 1;
  ThreadsOption threads;
  CostOption cost;
  std::string images = "bvhopt-demo";
  uint64_t rays = 0;
  bool quick = false;
  bool json = false;
  LayoutOption layout;
  WideCostOption wide_cost;
};

// The built-in scene, and every tree measured on it against the same ray sets (made once,
// against the first tree).
struct DemoRun {
  const DemoOptions& opt;
  CostModel model;
  ProgressLine& progress;
  Mesh mesh{};
  double scene_seconds = 0.0;
  PrimitiveRefs refs{};
  std::vector<Ray> primary_rays{}, random_rays{};
  uint32_t image_w = 0, image_h = 0;
  float heat_scale = 0.0f;  // top of the heat maps' shared scale
  std::vector<TraceCounters> unoptimized_steps{};
  struct Best {
    double cost = 1e300;
    std::string method;
    std::vector<TraceCounters> steps;
  } best{};
  std::vector<DemoRow> rows{};

  // `tree_refs`: the references the tree names when its builder made its own (sbvh).
  void measure(const std::string& method, double seconds, const Bvh& bvh, const PrimitiveRefs* tree_refs = nullptr);
};

void DemoRun::measure(const std::string& method, double seconds, const Bvh& bvh, const PrimitiveRefs* tree_refs) {
  DemoRow row;
  row.method = method;
  row.seconds = seconds;
  row.stats = compute_stats(bvh, model);
  progress.update("tracing: " + row.method, true);
  const FlatBvh flat = finalize(bvh, tree_refs ? *tree_refs : refs);
  Tracer tracer(flat, mesh);
  const std::unique_ptr<WideTracer> wide = make_wide_tracer(flat, mesh, opt.layout.layout(), opt.wide_cost.model());
  const AnyTracer traced = wide ? AnyTracer(*wide) : AnyTracer(tracer);
  if (primary_rays.empty()) {
    RaySetConfig config;
    config.kind = RayKind::primary;
    config.count = opt.rays;
    RaySet set = make_ray_set(mesh, tracer, config);
    image_w = set.width;
    image_h = set.height;
    primary_rays = std::move(set.rays);
    config.kind = RayKind::random;
    config.seed = opt.seed;
    config.count = opt.rays != 0 ? opt.rays : 500'000;
    random_rays = make_ray_set(mesh, tracer, config).rays;
  }
  MeasureOptions mo;
  mo.repeats = 3;
  row.primary_mrays = measure_rays(traced, primary_rays, RayQuery::closest, mo).rays_per_second * 1e-6;
  row.random_mrays = measure_rays(traced, random_rays, RayQuery::closest, mo).rays_per_second * 1e-6;
  if (row.method == "sweep" || row.stats.cost < best.cost) {
    std::vector<Hit> hits;
    std::vector<TraceCounters> counters;
    trace_rays(traced, primary_rays, RayQuery::closest, hits, &counters);
    if (row.method == "sweep") unoptimized_steps = counters;
    if (row.stats.cost < best.cost) best = {row.stats.cost, row.method, std::move(counters)};
  }
  rows.push_back(std::move(row));
}

// Every builder; returns the sweep SAH tree, which the optimizers start from, and its build time.
std::pair<Bvh, double> run_builders(DemoRun& run) {
  ProgressLine& progress = run.progress;
  Bvh sweep;
  double sweep_s = 0.0;
  for (BuilderKind kind : all_mesh_builders()) {
    progress.update("building: " + std::string(builder_name(kind)), true);
    BuildOptions options;
    options.kind = kind;
    options.cost = run.model;
    Stopwatch clock;
    BuiltTree built = build_tree(run.mesh, run.refs, options);
    double s = clock.seconds();
    if (kind == BuilderKind::sweep_sah) {
      sweep = built.bvh;
      sweep_s = s;
    }
    run.measure(std::string(builder_name(kind)), s, built.bvh, &built.refs);
  }
  return {sweep, sweep_s};
}

// The optimizers all start from the sweep SAH tree with one reference per leaf; their time
// column is the build plus the optimization.
void run_optimizers(DemoRun& run, const Bvh& sweep, double sweep_s) {
  const CostModel& model = run.model;
  const DemoOptions& opt = run.opt;
  ProgressLine& progress = run.progress;
  auto on_pass = [&](const std::string& name) {
    return [&progress, name](const PassRecord& p) {
      progress.update(name + ": pass " + std::to_string(p.pass) + ", cost " + format_double(p.cost, 3) +
                      ", best " + format_double(p.best_cost, 3) + ", " + format_double(p.seconds, 1) + " s");
    };
  };
  {
    Bvh bvh = sweep;
    HillClimbConfig config;
    config.cost = model;
    config.limits.on_pass = on_pass("sweep+hill-climb");
    OptimizeReport r = hill_climb(bvh, config);
    run.measure("sweep+hill-climb", sweep_s + r.seconds, bvh);
  }
  {
    Bvh bvh = sweep;
    AnnealConfig config;
    config.cost = model;
    config.seed = opt.seed;
    if (opt.quick) config.schedule_passes = 250;
    config.limits.on_pass = on_pass("sweep+anneal");
    OptimizeReport r = anneal(bvh, config);
    run.measure("sweep+anneal", sweep_s + r.seconds, bvh);
  }
  {
    Bvh bvh = sweep;
    InsertionConfig config;
    config.cost = model;
    config.seed = opt.seed;
    config.limits.on_pass = on_pass("sweep+insertion");
    OptimizeReport r = optimize_insertion(bvh, config);
    run.measure("sweep+insertion", sweep_s + r.seconds, bvh);
    Stopwatch clock;
    CollapseConfig cc;
    cc.cost = model;
    collapse_leaves(bvh, cc);
    run.measure("sweep+insertion+compact", sweep_s + r.seconds + clock.seconds(), bvh);
  }
}

void print_demo(const DemoRun& run, const std::filesystem::path& unopt_png, const std::filesystem::path& best_png) {
  const DemoOptions& opt = run.opt;
  const Mesh& mesh = run.mesh;
  const CostModel& model = run.model;
  if (opt.json) {
    nlohmann::json j = {{"scene", mesh.name},
                        {"triangles", mesh.triangle_count()},
                        {"threads", opt.threads.effective()},
                        {"c_t", model.traversal},
                        {"c_i", model.intersection},
                        {"layout", opt.layout.name},
                        {"heatmaps", {unopt_png.string(), best_png.string()}},
                        {"wide_block_cost", opt.wide_cost.block}};
    for (const DemoRow& r : run.rows)
      j["rows"].push_back({{"method", r.method},
                           {"seconds", r.seconds},
                           {"cost", r.stats.cost},
                           {"ocost", r.stats.ocost},
                           {"nodes", r.stats.nodes},
                           {"max_depth", r.stats.max_depth},
                           {"primary_mrays_per_s", r.primary_mrays},
                           {"random_mrays_per_s", r.random_mrays}});
    print_json(j);
    return;
  }
  std::cout << "bvhopt demo: built-in scene " << mesh.name << ", " << mesh.triangle_count() << " triangles (made in "
            << format_double(run.scene_seconds, 2) << " s), " << opt.threads.effective() << " threads, c_T "
            << model.traversal << ", c_I " << model.intersection << "\n"
            << "optimizers start from the sweep SAH tree (one triangle per leaf); their time includes the build\n"
            << "rays: " << run.primary_rays.size() << " primary (" << run.image_w << "x" << run.image_h << "), "
            << run.random_rays.size() << " random; Mrays/s on " << opt.threads.effective() << " threads\n\n";
  print_table(run.rows);
  std::cout << "\nheat maps (traversal steps per pixel, 0.." << run.heat_scale << "): " << unopt_png.string() << " (sweep), "
            << best_png.string() << " (" << run.best.method << ")\n";
}

void run_demo(const DemoOptions& opt) {
  check_output_folder(opt.images, "--images");
  auto threads = opt.threads.apply();
  ProgressLine progress;
  DemoRun run{opt, opt.cost.model(), progress};
  progress.update("generating the built-in scene", true);
  Stopwatch scene_clock;
  run.mesh = load_builtin_scene("builtin:atrium?triangles=" + std::to_string(opt.triangles) +
                                "&seed=" + std::to_string(opt.seed));
  run.scene_seconds = scene_clock.seconds();
  run.refs = make_references(run.mesh);

  const auto [sweep, sweep_s] = run_builders(run);
  run_optimizers(run, sweep, sweep_s);
  progress.finish();

  std::filesystem::path folder = opt.images;
  std::filesystem::create_directories(folder);
  const std::filesystem::path unopt_png = folder / "heatmap-sweep.png";
  const std::filesystem::path best_png = folder / "heatmap-best.png";
  std::string font_problem;
  const std::optional<Font> font = Font::load_default(font_problem);
  if (!font) std::cerr << "warning: " << font_problem << ": heat maps without captions\n";
  const std::string scene = "  \u00b7  " + run.mesh.name;
  run.heat_scale = write_heatmaps({{&run.unoptimized_steps, "sweep" + scene, unopt_png},
                                   {&run.best.steps, run.best.method + scene, best_png}},
                                  run.image_w, run.image_h, font ? &*font : nullptr);
  print_demo(run, unopt_png, best_png);
}

}  // namespace

void register_demo_command(CLI::App& app) {
  auto opt = std::make_shared<DemoOptions>();
  CLI::App* cmd = app.add_subcommand(
      "demo", "Every builder and optimizer on the built-in scene: cost, time and rays per second, plus heat maps");
  cmd->add_option("--triangles", opt->triangles, "Size of the built-in scene (at least its architecture, 3,512 triangles)")
      ->check(CLI::Range(uint64_t{100}, uint64_t{100'000'000}))
      ->capture_default_str();
  cmd->add_option("--seed", opt->seed, "Seed of the built-in scene and of the optimizers")->check(whole_number(0, UINT64_MAX))->capture_default_str();
  cmd->add_option("--images", opt->images, "Folder for the heat maps of the unoptimized and the best tree")
      ->capture_default_str();
  cmd->add_option("--rays", opt->rays, "Rays per set (default: 1024x768 primary rays and 500,000 random rays)")
      ->check(whole_number(1, kMaxRayCount));
  cmd->add_flag("--quick", opt->quick, "Shorter annealing schedule (250 passes instead of 1250)");
  opt->cost.add_to(cmd);
  opt->layout.add_to(cmd);
  opt->wide_cost.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_flag("--json", opt->json, "Print JSON");
  cmd->callback([opt] { run_demo(*opt); });
}

}  // namespace bvhopt::cli
