// bvhopt demo: the main job. Every builder (and, as they land, every optimizer) on the
// built-in scene, in one table, so a new user sees what the library does in one command.
#include <iomanip>
#include <iostream>
#include <sstream>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/scene.h"
#include "bvhopt/stats.h"
#include "cli_common.h"
#include "commands.h"

namespace bvhopt::cli {
namespace {

struct DemoRow {
  std::string method;
  double seconds = 0.0;
  TreeStats stats;
};

void print_table(const std::vector<DemoRow>& rows) {
  std::cout << std::left << std::setw(26) << "method" << std::right << std::setw(11) << "time ms" << std::setw(10)
            << "cost" << std::setw(10) << "ocost" << std::setw(10) << "nodes" << std::setw(7) << "depth" << "\n";
  for (const DemoRow& r : rows)
    std::cout << std::left << std::setw(26) << r.method << std::right << std::setw(11) << format_double(r.seconds * 1e3, 1)
              << std::setw(10) << format_double(r.stats.cost, 2) << std::setw(10) << format_double(r.stats.ocost, 2)
              << std::setw(10) << r.stats.nodes << std::setw(7) << r.stats.max_depth << "\n";
}

}  // namespace

void register_demo_command(CLI::App& app) {
  struct Options {
    uint64_t triangles = 250'000;
    uint64_t seed = 1;
    ThreadsOption threads;
    CostOption cost;
    bool json = false;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("demo", "Build the built-in scene with every builder and print a table");
  cmd->add_option("--triangles", opt->triangles, "Size of the built-in scene")
      ->check(CLI::Range(uint64_t{100}, uint64_t{100'000'000}))
      ->capture_default_str();
  cmd->add_option("--seed", opt->seed, "Seed of the built-in scene")->capture_default_str();
  opt->cost.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_flag("--json", opt->json, "Print JSON");
  cmd->callback([opt] {
    auto threads = opt->threads.apply();
    ProgressLine progress;
    progress.update("generating the built-in scene", true);
    Stopwatch scene_clock;
    Mesh mesh = load_scene("builtin:atrium?triangles=" + std::to_string(opt->triangles) +
                           "&seed=" + std::to_string(opt->seed));
    double scene_s = scene_clock.seconds();
    PrimitiveRefs refs = make_references(mesh);

    std::vector<DemoRow> rows;
    for (BuilderKind kind : all_builders()) {
      progress.update("building: " + std::string(builder_name(kind)), true);
      BuildOptions options;
      options.kind = kind;
      options.cost = opt->cost.model();
      Stopwatch clock;
      Bvh bvh = build_bvh(refs, options);
      double s = clock.seconds();
      rows.push_back({std::string(builder_name(kind)), s, compute_stats(bvh, options.cost)});
    }
    progress.finish();

    if (opt->json) {
      nlohmann::json j = {{"scene", mesh.name}, {"triangles", mesh.triangle_count()}, {"threads", opt->threads.effective()}};
      for (const DemoRow& r : rows)
        j["rows"].push_back({{"method", r.method},
                             {"seconds", r.seconds},
                             {"cost", r.stats.cost},
                             {"ocost", r.stats.ocost},
                             {"nodes", r.stats.nodes},
                             {"max_depth", r.stats.max_depth}});
      print_json(j);
      return;
    }
    std::cout << "bvhopt demo: built-in scene " << mesh.name << ", " << mesh.triangle_count() << " triangles (made in "
              << format_double(scene_s, 2) << " s), " << opt->threads.effective() << " threads, c_T "
              << opt->cost.traversal << ", c_I " << opt->cost.intersection << ", leaf size 1\n\n";
    print_table(rows);
  });
}

}  // namespace bvhopt::cli
