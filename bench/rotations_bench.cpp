// Tree rotations benchmark (Kensler 2008): hill climbing and simulated annealing on every
// scene, from the exact sweep SAH tree with one reference per leaf, beside the paper's
// Table 1 (Sponza and Conference; no library ships Kensler's annealing, so the paper is
// the peer).
//
//   rotations_bench [--scenes DIR] [--scene SPEC]... [--no-builtin] [--builtin SPEC]
//                   [--runs 3] [--h 1.0[,1.5,...]] [--schedule-passes 1250]
//                   [--anneal-threads 1,2] [--no-anneal] [--no-nonzero-variant] [--json FILE]
//
// Scenes where more than 1 % of the triangles have zero area (Conference, Staircase) are
// also run without them ("-nonzero"), as Kensler's Conference (282,664 triangles) was.
//
// Hill-climbing times are the median of --runs runs on 2 threads (and on 1 for the
// speedup); annealing runs once per thread count and h (it takes seconds, and the tree is
// the same on every thread count, which the program checks).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench_support.h"

#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/triangle.h"
#include "bvhopt/tree_rotations.h"

namespace bvhopt {
namespace {

using namespace bench;

struct Options {
  SceneOptions scenes;
  int runs = 3;
  std::vector<double> hs{AnnealConfig{}.h};
  uint32_t schedule_passes = AnnealConfig{}.schedule_passes;
  std::vector<int> anneal_threads{1, 2};
  bool anneal = true;
  // Also run scenes with many zero-area triangles (Conference, Staircase) without them, as
  // the paper's Conference was.
  bool nonzero_variant = true;
  std::string json_path;
};

Options parse(int argc, char** argv) {
  Options o;
  Args args(argc, argv, "rotations_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (read_scene_option(args, o.scenes)) continue;
    if (a == "--runs") o.runs = std::max(1, args.int_value());
    else if (a == "--schedule-passes") o.schedule_passes = args.u64_value();
    else if (a == "--no-anneal") o.anneal = false;
    else if (a == "--no-nonzero-variant") o.nonzero_variant = false;
    else if (a == "--json") o.json_path = args.value();
    else if (a == "--h") {
      o.hs.clear();
      for (auto& h : split_list(args.value())) o.hs.push_back(parse_double(h, a));
    } else if (a == "--anneal-threads") {
      o.anneal_threads.clear();
      for (auto& t : split_list(args.value())) o.anneal_threads.push_back(std::max(1, parse_int(t, a)));
    } else if (a == "--help" || a == "-h") {
      std::cout << "rotations_bench [--scenes DIR] [--scene SPEC]... [--no-builtin] [--builtin SPEC] [--runs 3]\n"
                   "                [--h 1.0[,1.5,...]] [--schedule-passes 1250] [--anneal-threads 1,2]\n"
                   "                [--no-anneal] [--no-nonzero-variant] [--json FILE]\n";
      std::exit(0);
    } else {
      throw Error("unknown option '" + a + "' (try --help)");
    }
  }
  return o;
}

// Kensler's Table 1: cost ratios after hill climbing and annealing, and annealing seconds
// (2.8 GHz Core 2 Duo, one thread). His Sponza has 76,065 triangles and his Conference
// 282,664 (the zero-area triangles removed); ours have 66,454 and 331,179.
struct PaperRow {
  double hill_ratio, hill_s, anneal_ratio, anneal_s;
};
const std::map<std::string, PaperRow>& paper_rows() {
  static const std::map<std::string, PaperRow> rows{
      {"sponza_dabrovic", {0.908, 0.13, 0.842, 28.51}},
      {"conference", {0.895, 0.68, 0.845, 119.26}},
      {"conference-nonzero", {0.895, 0.68, 0.845, 119.26}},
  };
  return rows;
}

struct AnnealRun {
  double h = 0.0;
  int threads = 0;
  double cost = 0.0, seconds = 0.0;
  double cpu_seconds = 0.0;  // process CPU time: shows how much of the wall time was waiting on a busy machine
  uint32_t passes = 0;
  uint64_t moves = 0;
};

struct SceneResult {
  std::string scene;
  size_t triangles = 0;
  double build_s = 0.0;
  double cost0 = 0.0;
  double hill_cost = 0.0, hill_s2 = 0.0, hill_s1 = 0.0;
  uint32_t hill_passes = 0;
  std::vector<AnnealRun> anneal;
  bool same_tree_on_thread_counts = true;
};

std::string stem(const std::string& spec) {
  std::filesystem::path p(spec);
  return p.has_extension() ? p.stem().string() : spec;
}

// The scene without its zero-area triangles, as Kensler's Conference (282,664 triangles)
// was; empty if fewer than 1 % of the triangles have zero area.
Mesh without_zero_area(const Mesh& mesh) {
  Mesh out;
  out.name = mesh.name + " (no zero-area triangles)";
  out.positions = mesh.positions;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    const Triangle tri = mesh.triangle(t);
    if (length(cross(tri.v1 - tri.v0, tri.v2 - tri.v0)) > 0.0f)
      out.add_triangle(mesh.indices[3 * t], mesh.indices[3 * t + 1], mesh.indices[3 * t + 2]);
  }
  if (100 * (mesh.triangle_count() - out.triangle_count()) < mesh.triangle_count()) return Mesh{};
  return out;
}

SceneResult run_scene(const Mesh& mesh, const std::string& name, const Options& o) {
  SceneResult r;
  r.scene = name;
  r.triangles = mesh.triangle_count();
  PrimitiveRefs refs = make_references(mesh);
  Bvh start;
  r.build_s = seconds_of([&] {
    SweepSahConfig sweep;
    sweep.leaf.max_leaf_size = 1;
    start = build_sweep_sah(refs, sweep);
  });
  r.cost0 = sah_cost(start);

  for (int threads : {2, 1}) {
    ThreadLimit limit(threads);
    std::vector<double> times;
    for (int i = 0; i < o.runs; ++i) {
      Bvh bvh = start;
      OptimizeReport rep = hill_climb(bvh);
      times.push_back(rep.seconds);
      if (threads == 2) {
        r.hill_cost = rep.final_cost;
        r.hill_passes = rep.passes;
      } else if (rep.final_cost != r.hill_cost) {
        r.same_tree_on_thread_counts = false;
      }
    }
    (threads == 2 ? r.hill_s2 : r.hill_s1) = median(times);
  }

  if (o.anneal) {
    for (double h : o.hs) {
      double first_cost = -1.0;
      for (int threads : o.anneal_threads) {
        ThreadLimit limit(threads);
        Bvh bvh = start;
        AnnealConfig cfg;
        cfg.h = h;
        cfg.schedule_passes = o.schedule_passes;
        const double c0 = process_cpu_seconds();
        OptimizeReport rep = anneal(bvh, cfg);
        const double cpu = process_cpu_seconds() - c0;
        AnnealRun a{h, threads, rep.final_cost, rep.seconds, cpu, rep.passes, rep.moves};
        if (first_cost < 0) first_cost = rep.final_cost;
        else if (rep.final_cost != first_cost) r.same_tree_on_thread_counts = false;
        r.anneal.push_back(a);
        std::fprintf(stderr, "  %s anneal h=%.2f %dT: %.3f (%.1f%%) %.2f s (cpu %.2f s), %u passes\n", r.scene.c_str(), h,
                     threads, rep.final_cost, 100.0 * rep.final_cost / r.cost0, rep.seconds, cpu, rep.passes);
      }
    }
  }
  return r;
}

void print_table(const std::vector<SceneResult>& results, const Options& o) {
  std::printf("\n%-20s %9s %9s | %9s %7s %8s %8s | ", "scene", "tris", "sweep", "hill", "ratio", "2T s", "1T/2T");
  std::printf("%5s %9s %7s %8s %8s %7s\n", "h", "anneal", "ratio", "1T s", "2T s", "1T/2T");
  for (const SceneResult& r : results) {
    std::printf("%-20s %9zu %9.3f | %9.3f %6.1f%% %8.3f %8.2f | ", r.scene.c_str(), r.triangles, r.cost0, r.hill_cost,
                100.0 * r.hill_cost / r.cost0, r.hill_s2, r.hill_s1 / r.hill_s2);
    bool first = true;
    for (double h : o.hs) {
      const AnnealRun* t1 = nullptr;
      const AnnealRun* t2 = nullptr;
      for (const AnnealRun& a : r.anneal)
        if (a.h == h) (a.threads == 1 ? t1 : t2) = &a;
      const AnnealRun* any = t2 ? t2 : t1;
      if (!any) break;
      if (!first) std::printf("%-20s %9s %9s | %9s %7s %8s %8s | ", "", "", "", "", "", "", "");
      first = false;
      std::printf("%5.2f %9.3f %6.1f%% %8.2f %8.2f %7.2f\n", h, any->cost, 100.0 * any->cost / r.cost0,
                  t1 ? t1->seconds : 0.0, t2 ? t2->seconds : 0.0, t1 && t2 ? t1->seconds / t2->seconds : 0.0);
    }
    if (first) std::printf("\n");
    if (!r.same_tree_on_thread_counts) std::printf("  ** %s: different trees on different thread counts **\n", r.scene.c_str());
    auto it = paper_rows().find(r.scene);
    if (it != paper_rows().end())
      std::printf("%-20s %9s %9s | %9s %6.1f%% %8.2f %8s | %5s %9s %6.1f%% %8.2f %8s %7s\n", "  (Kensler 2008)", "", "",
                  "", 100.0 * it->second.hill_ratio, it->second.hill_s, "", "", "", 100.0 * it->second.anneal_ratio,
                  it->second.anneal_s, "", "");
  }
}

nlohmann::json to_json(const std::vector<SceneResult>& results) {
  nlohmann::json out = nlohmann::json::array();
  for (const SceneResult& r : results) {
    nlohmann::json j{{"scene", r.scene},
                     {"triangles", r.triangles},
                     {"sweep_cost", r.cost0},
                     {"sweep_build_seconds", r.build_s},
                     {"hill_cost", r.hill_cost},
                     {"hill_ratio", r.hill_cost / r.cost0},
                     {"hill_passes", r.hill_passes},
                     {"hill_seconds_2t", r.hill_s2},
                     {"hill_seconds_1t", r.hill_s1},
                     {"same_tree_on_thread_counts", r.same_tree_on_thread_counts}};
    nlohmann::json runs = nlohmann::json::array();
    for (const AnnealRun& a : r.anneal)
      runs.push_back({{"h", a.h}, {"threads", a.threads}, {"cost", a.cost}, {"ratio", a.cost / r.cost0},
                      {"seconds", a.seconds}, {"cpu_seconds", a.cpu_seconds}, {"passes", a.passes}, {"moves", a.moves}});
    j["anneal"] = runs;
    auto it = paper_rows().find(r.scene);
    if (it != paper_rows().end())
      j["paper"] = {{"hill_ratio", it->second.hill_ratio}, {"hill_seconds", it->second.hill_s},
                    {"anneal_ratio", it->second.anneal_ratio}, {"anneal_seconds", it->second.anneal_s}};
    out.push_back(j);
  }
  return out;
}

}  // namespace
}  // namespace bvhopt

int main(int argc, char** argv) {
  using namespace bvhopt;
  return guarded_main("rotations_bench", [&] {
    Options o = parse(argc, argv);
    std::vector<SceneResult> results;
    for (const std::string& spec : scene_specs(o.scenes)) {
      std::fprintf(stderr, "%s ...\n", spec.c_str());
      const Mesh mesh = load_scene(spec);
      std::vector<std::pair<const Mesh*, std::string>> variants{{&mesh, stem(spec)}};
      Mesh nonzero;
      if (o.nonzero_variant) {
        nonzero = without_zero_area(mesh);
        if (nonzero.triangle_count() > 0) variants.push_back({&nonzero, stem(spec) + "-nonzero"});
      }
      for (auto& [m, name] : variants) {
        results.push_back(run_scene(*m, name, o));
        const SceneResult& r = results.back();
        std::fprintf(stderr, "  %s: sweep %.3f, hill %.3f (%.1f%%) in %.3f s on 2T\n", name.c_str(), r.cost0,
                     r.hill_cost, 100.0 * r.hill_cost / r.cost0, r.hill_s2);
      }
    }
    print_table(results, o);
    if (!o.json_path.empty()) write_json(o.json_path, to_json(results));
    return 0;
  });
}
