// bvhopt build: scene -> references -> top-down build -> BVH file (the default sweep build,
// leaves of one, reads the mesh itself and makes the references for the file).
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/stats.h"
#include "bvhopt/atomic_file.h"
#include "bvhopt/triangle_cost.h"
#include "cli_common.h"
#include "commands.h"

namespace bvhopt::cli {

namespace {

struct BuildCommandOptions {
  SceneOption scene;
  EvhOption evh;
  ThreadsOption threads;
  CostOption cost;
  BuildOptions build;  // --leaf-size and --bins write straight into it
  std::string builder{builder_name(BuildOptions{}.kind)};
  bool bins_given = false;
  std::string output;
  bool json = false;
};

void print_build_summary(const BuildCommandOptions& opt, const Mesh& mesh, const BuiltTree& built,
                         const TreeStats& st, double load_s, double build_s, const std::string& evh_report) {
  const uint32_t leaf_size = opt.build.leaf.max_leaf_size;
  const PrimitiveRefs& refs = built.refs;
  const double per_triangle = mesh.triangle_count() ? double(refs.size()) / double(mesh.triangle_count()) : 0.0;
  if (opt.json) {
    nlohmann::json out = {{"scene", mesh.name},
                          {"triangles", mesh.triangle_count()},
                          {"references", refs.size()},
                          {"references_per_triangle", per_triangle},
                          {"builder", opt.builder},
                          {"leaf_size", leaf_size},
                          {"threads", opt.threads.effective()},
                          {"load_seconds", load_s},
                          {"build_seconds", build_s},
                          {"cost", st.cost},
                          {"ocost", st.ocost},
                          {"nodes", st.nodes},
                          {"leaves", st.leaves},
                          {"max_depth", st.max_depth},
                          {"output", opt.output}};
    if (built.spatial_split) out["spatial_split"] = spatial_split_json(*built.spatial_split);
    print_json(out);
    return;
  }
  std::string references = std::to_string(refs.size()) + " (" + format_double(per_triangle, 3) + " per triangle";
  if (const auto& s = built.spatial_split)
    references += ", budget " + std::to_string(s->budget) + "; " + std::to_string(s->spatial_splits) +
                  " spatial and " + std::to_string(s->object_splits) + " object splits, " +
                  std::to_string(s->split_references) + " references cut, " +
                  std::to_string(s->unsplit_references) + " sent whole";
  references += ")";
  std::cout << "scene      " << mesh.name << " (" << mesh.triangle_count() << " triangles, loaded in "
            << format_double(load_s, 2) << " s)\n"
            << (opt.evh.enabled ? "evh        " + evh_report + "\n" : std::string())
            << "builder    " << opt.builder << ", leaf size " << leaf_size << ", " << opt.threads.effective()
            << " threads\n"
            << "build      " << format_double(build_s * 1e3, 1) << " ms\n"
            << "references " << references << "\n"
            << "cost       " << format_double(st.cost, 3) << "  (ocost " << format_double(st.ocost, 3) << ")\n"
            << "nodes      " << st.nodes << " (" << st.leaves << " leaves), depth " << st.max_depth << "\n"
            << "written    " << opt.output << "\n";
}

void run_build(const BuildCommandOptions& opt) {
  check_output_path(opt.output, "-o");
  auto threads = opt.threads.apply();
  ProgressLine progress;
  progress.update("loading " + opt.scene.spec, true);
  Stopwatch load_clock;
  Mesh mesh = opt.scene.load();
  double load_s = load_clock.seconds();

  BuildOptions options = opt.build;
  options.kind = *parse_builder(opt.builder);
  options.cost = opt.cost.model();
  // An explicit bin count holds at every node; the adaptive count is the default's.
  if (opt.bins_given) options.binned.refs_per_bin = 0;
  progress.update("building " + std::to_string(mesh.triangle_count()) + " triangles with " + opt.builder, true);
  Stopwatch build_clock;
  std::string evh_report;
  BuiltTree built;
  Bvh& bvh = built.bvh;
  const PrimitiveRefs& refs = built.refs;
  double build_s = 0.0;
  std::optional<TreeStats> stats;
  if (!opt.evh.enabled && options.kind == BuilderKind::sweep_sah && options.leaf.max_leaf_size == 1) {
    // The tree of the build over references, built over the mesh (build_sweep_sah(const
    // Mesh&)) in less memory. Its statistics, whose per-node arrays would otherwise sit
    // beside tree and references at the command's peak, come before the references exist:
    // with one per triangle they count the same. The references are made for the file.
    bvh = build_sweep_sah(mesh, sweep_sah_config(options));
    build_s = build_clock.seconds();
    stats = compute_stats(bvh, options.cost);
    built.refs = make_references(mesh);
  } else {
    built = build_tree(mesh, opt.evh.make_refs(mesh, &evh_report), options);
    // Over subdivided references a leaf keeps one reference per triangle (the sbvh builder's
    // leaves already do).
    if (opt.evh.enabled && options.kind != BuilderKind::spatial_split) dedup_leaf_references(bvh, built.refs);
    build_s = build_clock.seconds();
  }

  const BvhFileInfo info = scene_info(mesh, options.cost, opt.evh.enabled ? "evh+" + opt.builder : opt.builder);
  progress.update("writing " + opt.output, true);
  write_bvh_file(opt.output, bvh, refs, info);
  progress.finish();

  if (!stats) stats = compute_stats(bvh, refs, options.cost);
  print_build_summary(opt, mesh, built, *stats, load_s, build_s, evh_report);
}

}  // namespace

void register_build_command(CLI::App& app) {
  auto opt = std::make_shared<BuildCommandOptions>();
  CLI::App* cmd = app.add_subcommand("build", "Build a BVH over a scene with a top-down builder and save it");
  opt->scene.add_to(cmd);
  std::vector<std::string> names;
  std::string names_help;
  for (BuilderKind kind : all_mesh_builders()) {
    names.emplace_back(builder_name(kind));
    names_help += (names_help.empty() ? "" : " | ") + names.back();
  }
  cmd->add_option("--builder", opt->builder, names_help)->check(CLI::IsMember(names))->capture_default_str();
  cmd->add_option("--leaf-size", opt->build.leaf.max_leaf_size, "Largest number of references per leaf")
      ->check(CLI::Range(1u, kMaxTracedLeafSize))
      ->capture_default_str();
  CLI::Option* bins =
      cmd->add_option("--bins", opt->build.binned.bin_count,
                      "Bins per axis at every node for the binned builder. Without it, large nodes get more "
                      "bins (up to " + std::to_string(kMaxBinCount) + ") and small ones fewer")
          ->check(CLI::Range(kMinBinCount, kMaxBinCount))
          ->capture_default_str();
  add_budget_option(cmd, opt->build.sbvh);
  opt->evh.add_to(cmd);
  opt->cost.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_option("-o,--output", opt->output, "BVH file to write")->required();
  cmd->add_flag("--json", opt->json, "Print the summary as JSON");
  cmd->callback([opt, bins] {
    opt->bins_given = bins->count() > 0;
    run_build(*opt);
  });
}

}  // namespace bvhopt::cli
