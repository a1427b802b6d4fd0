// bvhopt export: a BVH file's tree as a wide layout for renderers, in the documented flat
// format (the wide tracer's nodes and leaf blocks) or the compressed 8-wide nodes (CWBVH) of
// GPU tracers (docs/wide-export-format.md).
#include <chrono>
#include <iostream>

#include "bvhopt/compressed_wide_bvh.h"
#include "bvhopt/wide_export_file.h"
#include "cli_common.h"
#include "commands.h"
#include "trace_common.h"

namespace bvhopt::cli {

namespace {

struct ExportOptions {
  std::string bvh_file;
  SceneOption scene;
  std::string layout = "bvh8";
  std::string format = "flat";
  WideCostOption wide_cost;
  std::string output;
  bool json = false;
};

struct ExportSummary {
  size_t nodes = 0, leaf_items = 0, bytes = 0;
  double seconds = 0.0, sah = 0.0;
};

ExportSummary export_flat(const ExportOptions& opt, const FlatBvh& flat, const Mesh& mesh) {
  WideLayoutOptions o;
  o.collapse.width = uint32_t(*parse_trace_layout(opt.layout));
  o.collapse.cost = opt.wide_cost.model();
  const WideBvh wide(flat, mesh, o);
  write_wide_export_file(opt.output, wide, flat.nodes[0].box);
  return {wide.stats().nodes, wide.stats().blocks, sizeof(WideExportHeader) + wide.stats().bytes, 0.0,
          wide.stats().sah_cost};
}

ExportSummary export_cwbvh(const ExportOptions& opt, const FlatBvh& flat, const Mesh& mesh) {
  if (opt.layout != "bvh8") throw Error("export: --format cwbvh is 8-wide; it needs --layout bvh8, not " + opt.layout);
  const CompressedWideBvh wide = build_compressed_wide_bvh(flat, mesh, opt.wide_cost.model());
  write_cwbvh_export_file(opt.output, wide, flat.nodes[0].box, mesh.triangle_count());
  const size_t bytes = sizeof(WideExportHeader) + (wide.nodes.size() * sizeof(CwbvhNode) + 63) / 64 * 64 +
                       wide.triangles.size() * sizeof(CwbvhTriangle);
  return {wide.nodes.size(), wide.triangles.size(), bytes, 0.0, wide.sah_cost};
}

void run_export(const ExportOptions& opt) {
  ProgressLine progress;
  progress.update("loading " + opt.scene.spec + " and " + opt.bvh_file, true);
  const Mesh mesh = opt.scene.load();
  const BvhFile file = read_tree_for_scene(opt.bvh_file, mesh);
  const FlatBvh flat = finalize(file.bvh, file.refs);
  progress.update("writing " + opt.output, true);
  const auto start = std::chrono::steady_clock::now();
  ExportSummary s = opt.format == "cwbvh" ? export_cwbvh(opt, flat, mesh) : export_flat(opt, flat, mesh);
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  progress.finish();
  const double per_triangle = double(s.bytes) / double(mesh.triangle_count());
  if (opt.json) {
    print_json({{"bvh", opt.bvh_file}, {"scene", mesh.name}, {"triangles", mesh.triangle_count()},
                {"layout", opt.layout}, {"format", opt.format}, {"output", opt.output}, {"nodes", s.nodes},
                {"leaf_items", s.leaf_items}, {"bytes", s.bytes}, {"bytes_per_triangle", per_triangle},
                {"wide_sah", s.sah}, {"wide_block_cost", opt.wide_cost.block}, {"seconds", s.seconds}});
    return;
  }
  std::cout << "wrote      " << opt.output << " (" << opt.format << ", " << opt.layout << ")\n"
            << "nodes      " << s.nodes << ", " << s.leaf_items
            << (opt.format == "cwbvh" ? " triangle entries" : " leaf blocks") << "\n"
            << "size       " << s.bytes << " bytes, " << format_double(per_triangle, 1) << " per triangle\n"
            << "wide SAH   " << format_double(s.sah, 2) << "\n"
            << "time       " << format_double(1e3 * s.seconds, 1) << " ms\n";
}

}  // namespace

void register_export_command(CLI::App& app) {
  auto opt = std::make_shared<ExportOptions>();
  CLI::App* cmd = app.add_subcommand(
      "export", "Write a BVH file's tree as a wide layout for renderers (docs/wide-export-format.md)");
  cmd->add_option("bvh", opt->bvh_file, "BVH file (from bvhopt build, optimize or bake)")->required()->type_name("FILE.bvh");
  opt->scene.add_to(cmd, "--scene", true);
  cmd->add_option("--layout", opt->layout, "Node width: bvh8 | bvh4")
      ->check(CLI::IsMember({"bvh4", "bvh8"}))
      ->capture_default_str();
  cmd->add_option("--format", opt->format,
                  "flat (the wide tracer's nodes and 4-triangle blocks) | cwbvh (80-byte compressed 8-wide nodes)")
      ->check(CLI::IsMember({"flat", "cwbvh"}))
      ->capture_default_str();
  opt->wide_cost.add_to(cmd);
  cmd->add_option("-o,--output", opt->output, "Output file (written atomically)")->required()->type_name("FILE");
  cmd->add_flag("--json", opt->json, "Print a summary as JSON");
  cmd->callback([opt] { run_export(*opt); });
}

}  // namespace bvhopt::cli
