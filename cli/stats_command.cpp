// bvhopt stats: cost, ocost, counts, depth and per-depth area sums of a BVH file.
#include <iostream>

#include "bvhopt/bvh_file.h"
#include "bvhopt/finalize.h"
#include "bvhopt/stats.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/wide_bvh.h"
#include "cli_common.h"
#include "trace_common.h"
#include "commands.h"

namespace bvhopt::cli {

namespace {

// Everything `bvhopt stats` takes; the defaults are the command's.
struct StatsOptions {
  std::string input;
  CostOption cost;
  bool ct_given = false, ci_given = false;  // set from the command line, not options
  bool json = false;
  bool per_depth = false;
  WideCostOption wide_cost;
};

// Prints the statistics of the file's tree, with its own cost constants unless --ct or
// --ci was given.
void run_stats(const StatsOptions& opt) {
  BvhFile file = read_bvh_file(opt.input);
  CostModel model = file.info.cost;
  if (opt.ct_given) model.traversal = opt.cost.traversal;
  if (opt.ci_given) model.intersection = opt.cost.intersection;
  // Each triangle once per leaf, however many of its references the leaf holds.
  TreeStats st = compute_stats(file.bvh, file.refs, model);
  const size_t triangles = count_distinct_triangles(file.bvh, file.refs);
  // The wide SAH cost (wide_bvh.h) of the SAH-optimal collapses the wide layouts trace.
  double wide_sah[2] = {0.0, 0.0};
  if (!file.bvh.empty()) {
    const FlatBvh flat = finalize(file.bvh, file.refs);
    for (int i = 0; i < 2; ++i) {
      CollapseOptions o;
      o.width = i == 0 ? 4 : 8;
      o.cost = opt.wide_cost.model();
      wide_sah[i] = collapse_to_wide(flat, o).sah_cost;
    }
  }
  if (opt.json) {
    print_json({{"file", opt.input},
                {"scene", file.info.scene_name},
                {"scene_triangles", file.info.scene_triangles},
                {"method", file.info.method},
                {"c_t", model.traversal},
                {"c_i", model.intersection},
                {"cost", st.cost},
                {"ocost", st.ocost},
                {"nodes", st.nodes},
                {"inner_nodes", st.inner_nodes},
                {"leaves", st.leaves},
                {"references", st.references},
                {"triangles", triangles},
                {"references_per_triangle", triangles ? double(st.references) / double(triangles) : 0.0},
                {"max_depth", st.max_depth},
                {"mean_leaf_depth", st.mean_leaf_depth},
                {"refs_per_leaf", {{"min", st.min_refs_per_leaf}, {"max", st.max_refs_per_leaf}, {"mean", st.mean_refs_per_leaf}}},
                {"inner_area_sum", st.inner_area_sum},
                {"leaf_area_sum", st.leaf_area_sum},
                {"inner_area_by_depth", st.inner_area_by_depth},
                {"leaf_area_by_depth", st.leaf_area_by_depth},
                {"wide_sah_bvh4", wide_sah[0]},
                {"wide_sah_bvh8", wide_sah[1]},
                {"wide_block_cost", opt.wide_cost.block}});
    return;
  }
  std::cout << "file        " << opt.input << "\n"
            << "scene       " << file.info.scene_name << " (" << file.info.scene_triangles << " triangles)\n"
            << "method      " << file.info.method << "\n"
            << "cost        " << format_double(st.cost, 3) << "   (c_T " << model.traversal << ", c_I "
            << model.intersection << ")\n"
            << "ocost       " << format_double(st.ocost, 3) << "\n"
            << "nodes       " << st.nodes << " (" << st.inner_nodes << " inner, " << st.leaves << " leaves)\n"
            << "references  " << st.references << " (per leaf " << st.min_refs_per_leaf << ".."
            << st.max_refs_per_leaf << ", mean " << format_double(st.mean_refs_per_leaf, 2) << ")\n"
            << "triangles   " << triangles << " (" << format_double(triangles ? double(st.references) / triangles : 0.0, 4)
            << " references per triangle)\n"
            << "depth       max " << st.max_depth << ", mean leaf depth " << format_double(st.mean_leaf_depth, 2)
            << "\n"
            << "area sums   inner " << format_double(st.inner_area_sum / st.root_area, 2) << ", leaves "
            << format_double(st.leaf_area_sum / st.root_area, 2) << " (relative to the root)\n"
            << "wide SAH    bvh4 " << format_double(wide_sah[0], 3) << ", bvh8 " << format_double(wide_sah[1], 3)
            << "   (SAH-optimal collapse, c_node " << opt.wide_cost.model().node << ", c_blk " << opt.wide_cost.block
            << ")\n";
  if (opt.per_depth) {
    std::cout << "depth  inner_area/root  leaf_area/root\n";
    for (size_t d = 0; d < st.inner_area_by_depth.size(); ++d)
      std::cout << d << "  " << format_double(st.inner_area_by_depth[d] / st.root_area, 4) << "  "
                << format_double(d < st.leaf_area_by_depth.size() ? st.leaf_area_by_depth[d] / st.root_area : 0, 4)
                << "\n";
  }
}

}  // namespace

void register_stats_command(CLI::App& app) {
  auto opt = std::make_shared<StatsOptions>();
  CLI::App* cmd = app.add_subcommand("stats", "Print the cost and shape of a saved BVH");
  // Not CLI::ExistingFile: a missing file is bad input (exit 1), which read_bvh_file reports.
  cmd->add_option("file", opt->input, "BVH file")->required();
  opt->cost.add_to(cmd);
  opt->wide_cost.add_to(cmd);
  cmd->add_flag("--per-depth", opt->per_depth, "Also print the inner and leaf area sums per depth");
  cmd->add_flag("--json", opt->json, "Print JSON");
  cmd->callback([opt, cmd] {
    opt->ct_given = cmd->count("--ct") > 0;
    opt->ci_given = cmd->count("--ci") > 0;
    run_stats(*opt);
  });
}

}  // namespace bvhopt::cli
