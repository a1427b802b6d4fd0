// Collapse + wide layout time against the sweep SAH build time (issue 11's target: at most
// 10 %), measured in one run on the same tree, on 1 and 2 threads.
//
//   layout_bench [--scenes DIR] [--scene FILE]... [--repeats R] [--threads 1,2] [--width 8|4]
//                [--leaf N] [--wide-block C,...] [--json FILE]
//
// Per scene and thread count: R rounds, each timing the sweep SAH build of the scene (leaf
// size 1, the build a user starts from) and then the collapse and the layout of the tree
// `--leaf` (default 8: the sweep tree compacted into leaves of up to 8, as traced) into
// `--width`-wide nodes, once for each c_blk of `--wide-block` (default: the library's; several
// are timed in the same rounds, in turn, their order reversed every other round, for a
// same-run ratio). Each figure is the median of its R samples, wall time (the layout
// runs on several threads); the process CPU time ratio is printed beside it, since on a
// shared machine wall times also count other processes. Then the wide layout's bytes and
// triangle slots (4 per leaf block) per triangle. The rounds run on warm caches, and reuse
// memory freed by the rounds before where the allocator hands it back: not always the wide
// arena, which on the AMD VM came fresh in every round for 2CylinderEngine and Conference
// (4 and 10 huge-page faults a round in /proc/vmstat, each page cleared by the kernel) and
// from the round before for the other scenes. trace_bench prints each tree's layout done
// once, cold.
#include <tbb/global_control.h>

#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "bench_support.h"

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/finalize.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {
namespace {

using namespace bench;

struct Options {
  SceneOptions scene_options = SceneOptions::files_only();
  std::vector<std::string> scenes;
  int repeats = 7;
  std::vector<int> threads{1, 2};
  uint32_t width = 8;
  uint32_t leaf = 8;
  std::vector<double> block_costs{WideCostModel{}.block};
  std::string json_path;
};

Options parse(int argc, char** argv) {
  Options o;
  Args args(argc, argv, "layout_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (read_scene_option(args, o.scene_options)) continue;
    if (a == "--repeats") o.repeats = std::max(1, args.int_value());
    else if (a == "--width") o.width = args.u32_value();
    else if (a == "--leaf") o.leaf = args.u32_value();
    else if (a == "--json") o.json_path = args.value();
    else if (a == "--wide-block") o.block_costs = parse_positive_list(args.value(), a);
    else if (a == "--threads") {
      o.threads.clear();
      for (const std::string& t : split_list(args.value())) o.threads.push_back(std::max(1, parse_int(t, a)));
    } else if (a == "--help" || a == "-h") {
      std::cout << "layout_bench [--scenes DIR] [--scene FILE]... [--repeats R] [--threads 1,2] [--width 8|4]\n"
                   "             [--leaf N] [--wide-block C,...] [--json FILE]\n";
      std::exit(0);
    } else {
      throw Error("unknown option '" + a + "'");
    }
  }
  o.scenes = scene_specs(o.scene_options);
  return o;
}

// One c_blk's rounds.
struct Samples {
  std::vector<double> collapse, layout, wide_cpu;
  WideLayoutStats wide;  // the same in every round (the layout is deterministic)
};

int run(const Options& opt) {
  nlohmann::json rows = nlohmann::json::array();
  std::printf("# layout_bench: wall-clock medians of %d rounds; collapse + layout of the sweep tree compacted into "
              "leaves of up to %u, %u-wide\n",
              opt.repeats, opt.leaf, opt.width);
  std::printf("%-22s %3s %9s %5s | %10s %10s %10s | %7s %7s | %7s %7s\n", "scene", "thr", "triangles", "c_blk",
              "build ms", "collapse", "layout", "ratio", "cpu", "B/tri", "slots");
  for (const std::string& spec : opt.scenes) {
    const Mesh mesh = load_mesh_file(spec);
    const PrimitiveRefs refs = make_references(mesh);
    const std::string name = std::filesystem::path(spec).filename().string();
    for (int threads : opt.threads) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
      std::vector<double> builds, build_cpu;
      std::vector<Samples> per_cost(opt.block_costs.size());
      for (int r = 0; r < opt.repeats; ++r) {
        Bvh bvh;
        double cpu0 = process_cpu_seconds();
        builds.push_back(seconds_of([&] { bvh = build_bvh(refs, BuildOptions{}); }));
        build_cpu.push_back(process_cpu_seconds() - cpu0);
        CollapseConfig cc;
        cc.max_leaf_size = opt.leaf;
        collapse_leaves(bvh, cc);
        const FlatBvh flat = finalize(bvh, refs);
        for (size_t i = 0; i < per_cost.size(); ++i) {
          // In turn, the order reversed every other round: the first layout after the build
          // meets other caches and allocator state than the next.
          const size_t k = r % 2 == 0 ? i : per_cost.size() - 1 - i;
          Samples& s = per_cost[k];
          WideLayoutOptions wo;
          wo.collapse.width = opt.width;
          wo.collapse.cost.block = opt.block_costs[k];
          cpu0 = process_cpu_seconds();
          const WideBvh wide(flat, mesh, wo);
          s.wide_cpu.push_back(process_cpu_seconds() - cpu0);
          s.collapse.push_back(wide.stats().collapse_seconds);
          s.layout.push_back(wide.stats().layout_seconds);
          s.wide = wide.stats();
        }
      }
      const double build = median(builds);
      for (size_t k = 0; k < per_cost.size(); ++k) {
        const Samples& s = per_cost[k];
        const double collapse = median(s.collapse), layout = median(s.layout);
        const double ratio = (collapse + layout) / build, cpu_ratio = median(s.wide_cpu) / median(build_cpu);
        // Bytes of the wide layout per triangle, and triangle slots per triangle (padding of
        // leaf blocks): what the layout writes, beside how long it takes.
        const double bytes_per_triangle = double(s.wide.bytes) / double(mesh.triangle_count());
        const double slots_per_triangle = double(s.wide.triangle_slots) / double(mesh.triangle_count());
        std::printf("%-22s %3d %9zu %5.2f | %10.1f %10.1f %10.1f | %6.1f%% %6.1f%% | %7.1f %7.2f\n", name.c_str(),
                    threads, mesh.triangle_count(), opt.block_costs[k], 1e3 * build, 1e3 * collapse, 1e3 * layout,
                    100.0 * ratio, 100.0 * cpu_ratio, bytes_per_triangle, slots_per_triangle);
        std::fflush(stdout);
        rows.push_back({{"scene", name}, {"threads", threads}, {"triangles", mesh.triangle_count()},
                        {"build_seconds", build}, {"collapse_seconds", collapse}, {"layout_seconds", layout},
                        {"ratio", ratio}, {"cpu_ratio", cpu_ratio},
                        {"wide_bytes", s.wide.bytes}, {"wide_nodes", s.wide.nodes}, {"wide_blocks", s.wide.blocks},
                        {"bytes_per_triangle", bytes_per_triangle}, {"wide_block_cost", opt.block_costs[k]}});
      }
    }
  }
  if (!opt.json_path.empty()) write_json(opt.json_path, {{"bench", "layout_bench"}, {"rows", rows}});
  return 0;
}

}  // namespace
}  // namespace bvhopt

int main(int argc, char** argv) {
  return bvhopt::bench::guarded_main("layout_bench", [&] { return bvhopt::run(bvhopt::parse(argc, argv)); });
}
