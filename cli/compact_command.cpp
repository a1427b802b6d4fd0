// bvhopt compact: collapse subtrees into leaves wherever a leaf costs no more (Bittner et
// al. 2013, section 2.6), after optimizing a tree with one reference per leaf.
#include <iostream>

#include "bvhopt/bvh_file.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/atomic_file.h"
#include "cli_common.h"
#include "commands.h"

namespace bvhopt::cli {

namespace {

// Everything `bvhopt compact` takes; the defaults are the command's.
struct CompactOptions {
  std::string input;
  uint32_t max_leaf_size = 0;
  std::string output;
  bool json = false;
};

// Collapses the tree of the input file, removes repeated triangles from its leaves, writes
// the output file, and prints the costs before and after.
void run_compact(const CompactOptions& opt) {
  check_output_path(opt.output, "-o");
  Stopwatch load_clock;
  BvhFile file = read_bvh_file(opt.input);
  const double load_s = load_clock.seconds();
  const CostModel cost = file.info.cost;
  const double ocost_before = optimal_collapse_cost(file.bvh, file.refs, cost, opt.max_leaf_size);

  Stopwatch clock;
  CollapseConfig cfg;
  cfg.cost = cost;
  cfg.max_leaf_size = opt.max_leaf_size;
  // Each triangle once per leaf: a collapsed leaf keeps one reference per triangle.
  CollapseResult r = collapse_leaves(file.bvh, file.refs, cfg);
  // A tree over subdivided references (--evh) may now hold one triangle twice in a
  // leaf; keep one. Without subdivision this changes nothing.
  dedup_leaf_references(file.bvh, file.refs);
  const double compact_s = clock.seconds();
  const double ocost_after = optimal_collapse_cost(file.bvh, file.refs, cost, opt.max_leaf_size);

  BvhFileInfo info = file.info;
  info.method = (info.method.empty() ? std::string("unknown") : info.method) + "+compact";
  write_bvh_file(opt.output, file.bvh, file.refs, info);

  if (opt.json) {
    print_json({{"input", opt.input},
                {"max_leaf_size", opt.max_leaf_size},
                {"c_t", cost.traversal},
                {"c_i", cost.intersection},
                {"load_seconds", load_s},
                {"compact_seconds", compact_s},
                {"cost_before", r.cost_before},
                {"ocost_before", ocost_before},
                {"cost_after", r.cost_after},
                {"ocost_after", ocost_after},
                {"leaves_before", r.leaves_before},
                {"leaves_after", r.leaves_after},
                {"nodes_before", r.nodes_before},
                {"nodes_after", r.nodes_after},
                {"file_method", info.method},
                {"output", opt.output}});
    return;
  }
  std::cout << "input      " << opt.input << " (" << info.scene_triangles << " triangles, " << r.leaves_before
            << " leaves)\n"
            << "max leaf   " << (opt.max_leaf_size == 0 ? std::string("no limit") : std::to_string(opt.max_leaf_size))
            << "\n"
            << "before     cost " << format_double(r.cost_before, 4) << "  ocost " << format_double(ocost_before, 4)
            << "\n"
            << "after      cost " << format_double(r.cost_after, 4) << "  ocost " << format_double(ocost_after, 4)
            << "  (" << format_double(100.0 * r.cost_after / r.cost_before, 2) << " % of before)\n"
            << "leaves     " << r.leaves_before << " -> " << r.leaves_after << ", nodes " << r.nodes_before << " -> "
            << r.nodes_after << ", " << format_double(compact_s * 1e3, 1) << " ms\n"
            << "written    " << opt.output << " (" << info.method << ")\n";
}

}  // namespace

void register_compact_command(CLI::App& app) {
  auto opt = std::make_shared<CompactOptions>();
  CLI::App* cmd = app.add_subcommand(
      "compact", "Collapse every subtree whose references cost less as one leaf (the paper's ocost), and save");
  cmd->add_option("input", opt->input, "BVH file to compact")->required()->type_name("IN.bvh");
  cmd->add_option("--max-leaf-size", opt->max_leaf_size,
                  "Never make a leaf of more references than this (0: no limit, the paper's ocost)")
      ->check(whole_number(0, UINT32_MAX))
      ->capture_default_str();
  cmd->add_option("-o,--output", opt->output, "BVH file to write")->required()->type_name("OUT.bvh");
  cmd->add_flag("--json", opt->json, "Print the summary as JSON");
  cmd->callback([opt] { run_compact(*opt); });
}

}  // namespace bvhopt::cli
