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
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/references.h"
#include "bvhopt/scene.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/triangle.h"
#include "bvhopt/tree_rotations.h"

namespace bvhopt {
namespace {

struct Options {
  std::filesystem::path scenes_dir;
  std::vector<std::string> scenes;
  bool builtin = true;
  std::string builtin_spec = "builtin";
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

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

Options parse(int argc, char** argv) {
  Options o;
  if (const char* env = std::getenv("BVHOPT_SCENES"); env && *env)
    o.scenes_dir = env;
  else
    o.scenes_dir = "../shared/scenes";
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw Error("rotations_bench: option " + a + " needs a value");
      return argv[++i];
    };
    if (a == "--scenes") o.scenes_dir = value();
    else if (a == "--scene") o.scenes.push_back(value());
    else if (a == "--no-builtin") o.builtin = false;
    else if (a == "--builtin") o.builtin_spec = value();
    else if (a == "--runs") o.runs = std::max(1, std::stoi(value()));
    else if (a == "--schedule-passes") o.schedule_passes = std::stoul(value());
    else if (a == "--no-anneal") o.anneal = false;
    else if (a == "--no-nonzero-variant") o.nonzero_variant = false;
    else if (a == "--json") o.json_path = value();
    else if (a == "--h") {
      o.hs.clear();
      for (auto& h : split_list(value())) o.hs.push_back(std::stod(h));
    } else if (a == "--anneal-threads") {
      o.anneal_threads.clear();
      for (auto& t : split_list(value())) o.anneal_threads.push_back(std::max(1, std::stoi(t)));
    } else if (a == "--help" || a == "-h") {
      std::cout << "rotations_bench [--scenes DIR] [--scene SPEC]... [--no-builtin] [--builtin SPEC] [--runs 3]\n"
                   "                [--h 1.0[,1.5,...]] [--schedule-passes 1250] [--anneal-threads 1,2]\n"
                   "                [--no-anneal] [--no-nonzero-variant] [--json FILE]\n";
      std::exit(0);
    } else {
      throw Error("rotations_bench: unknown option '" + a + "' (try --help)");
    }
  }
  return o;
}

std::vector<std::string> scene_list(const Options& o) {
  std::vector<std::string> specs = o.scenes;
  if (specs.empty()) {
    if (!std::filesystem::is_directory(o.scenes_dir))
      throw Error(o.scenes_dir.string() + ": scenes folder not found (set BVHOPT_SCENES or pass --scenes DIR)");
    for (const auto& e : std::filesystem::directory_iterator(o.scenes_dir)) {
      std::string ext = e.path().extension().string();
      if (e.is_regular_file() && (ext == ".obj" || ext == ".ply" || ext == ".glb" || ext == ".gltf"))
        specs.push_back(e.path().string());
    }
    std::sort(specs.begin(), specs.end());
  }
  if (o.builtin) specs.push_back(o.builtin_spec);
  return specs;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
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
  auto t0 = std::chrono::steady_clock::now();
  SweepSahConfig sweep;
  sweep.leaf.max_leaf_size = 1;
  const Bvh start = build_sweep_sah(refs, sweep);
  r.build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.cost0 = sah_cost(start);

  for (int threads : {2, 1}) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
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
        tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
        Bvh bvh = start;
        AnnealConfig cfg;
        cfg.h = h;
        cfg.schedule_passes = o.schedule_passes;
        const std::clock_t c0 = std::clock();
        OptimizeReport rep = anneal(bvh, cfg);
        const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
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
  try {
    Options o = parse(argc, argv);
    std::vector<SceneResult> results;
    for (const std::string& spec : scene_list(o)) {
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
    if (!o.json_path.empty()) {
      std::ofstream f(o.json_path);
      if (!f) throw Error(o.json_path + ": cannot write");
      f << to_json(results).dump(2) << "\n";
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rotations_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
