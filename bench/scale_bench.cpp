// Optimization at scale (issue 13): the sweep SAH build, then insertion (the default form)
// to convergence, on the built-in hall at 1M and 4M triangles and on Conference, 2 threads.
//
//   scale_bench [--scene SPEC]... [--threads 2] [--json FILE] [--reference SPEC=COST]...
//               [--budget N] [--repeat R]
//
// --repeat R runs each scene's optimization to convergence R times in all (default 1), the
// scenes in turn (1M, 4M, Conference, then again), each run from a copy of the scene's sweep
// tree, and reports the median time and the growth of the medians: on a shared machine one
// run's time varies by 10 % or more, as much as the margin of the n log n target.
// --budget N stops each optimizer run at N build times (then "converged" is only where the
// run stopped, marked so); without it every run goes to convergence.
//
// Per scene: the build's time; the best cost reached within 1x and 5x the build time (read from the
// converged run's trace; and from runs of their own with that time budget, as --time-budget 1x and
// 5x run: those end their passes early enough to renumber the tree within the budget, so they can
// end higher, and close with rotation sweeps, so they can end lower; their seconds are printed
// beside them) and its share of the converged gain (sweep
// cost -> converged cost, ours; with --reference, also of a given converged cost, e.g. the issue's
// 357.00 at 4M); the converged cost and time; the peak heap while building and while optimizing,
// less the mesh, per triangle. The optimizer runs as bake runs it: the references are dropped first
// (it needs only the tree), so its peak is tree + leaf slots + scratch. Heap figures count every
// operator new of the process (this program replaces it); the process's peak RSS is printed too.
//
// Where the time goes: per scene, each stage of the optimizer (its passes, seconds and
// seconds a pass; medians over the converged runs, which run the same passes), the setup
// before them and the final renumbering after; and for the smallest and largest built-in
// scenes, how much each stage grew from one to the other.
//
// Times are wall seconds of one run on a shared machine: the targets are ratios to the build
// time measured in the same run, and the growth from the smallest to the largest built-in
// scene is compared with n log n.
#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <new>
#include <string>
#include <vector>

#include "bench_support.h"

#include "bvhopt/cost.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/sweep_sah_builder.h"

// ---- heap accounting: every allocation of the process, live bytes and their peak ----
namespace {
std::atomic<int64_t> g_live{0};
std::atomic<int64_t> g_peak{0};

void note_alloc(void* p) {
  if (!p) return;
  const int64_t now = g_live.fetch_add(static_cast<int64_t>(malloc_usable_size(p))) + static_cast<int64_t>(malloc_usable_size(p));
  int64_t peak = g_peak.load(std::memory_order_relaxed);
  while (now > peak && !g_peak.compare_exchange_weak(peak, now)) {
  }
}
void note_free(void* p) {
  if (p) g_live.fetch_sub(static_cast<int64_t>(malloc_usable_size(p)));
}
void* counted_alloc(size_t n) {
  void* p = std::malloc(n ? n : 1);
  if (!p) throw std::bad_alloc();
  note_alloc(p);
  return p;
}
void* counted_aligned(size_t n, std::align_val_t a) {
  void* p = nullptr;
  if (posix_memalign(&p, std::max(sizeof(void*), static_cast<size_t>(a)), n ? n : 1) != 0) throw std::bad_alloc();
  note_alloc(p);
  return p;
}
void counted_free(void* p) {
  note_free(p);
  std::free(p);
}
}  // namespace

void* operator new(size_t n) { return counted_alloc(n); }
void* operator new[](size_t n) { return counted_alloc(n); }
void* operator new(size_t n, std::align_val_t a) { return counted_aligned(n, a); }
void* operator new[](size_t n, std::align_val_t a) { return counted_aligned(n, a); }
void operator delete(void* p) noexcept { counted_free(p); }
void operator delete[](void* p) noexcept { counted_free(p); }
void operator delete(void* p, size_t) noexcept { counted_free(p); }
void operator delete[](void* p, size_t) noexcept { counted_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { counted_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { counted_free(p); }
void operator delete(void* p, size_t, std::align_val_t) noexcept { counted_free(p); }
void operator delete[](void* p, size_t, std::align_val_t) noexcept { counted_free(p); }

namespace {

using namespace bvhopt;
using namespace bvhopt::bench;

// Peak RSS of the process (VmHWM), bytes.
int64_t peak_rss() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::atoll(line.c_str() + 6) * 1024;
  return 0;
}

// The peak of live heap bytes from now on, starting at what is live now.
void reset_heap_peak() { g_peak.store(g_live.load()); }

struct Options {
  std::vector<std::string> scenes;
  int threads = 2;
  std::string json_path;
  std::map<std::string, double> references;  // scene spec -> a given converged cost
  double budget = 0.0;                          // in build times; 0: to convergence
  int repeat = 1;                               // converged runs per scene, the scenes in turn
};

Options parse(int argc, char** argv) {
  Options opt;
  Args args(argc, argv, "scale_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (a == "--scene") {
      opt.scenes.push_back(args.value());
    } else if (a == "--threads") {
      opt.threads = std::max(1, args.int_value());
    } else if (a == "--budget") {
      opt.budget = args.double_value();
    } else if (a == "--repeat") {
      opt.repeat = std::max(1, args.int_value());
    } else if (a == "--json") {
      opt.json_path = args.value();
    } else if (a == "--reference") {
      const std::string v = args.value();
      const size_t eq = v.rfind('=');
      if (eq == std::string::npos) throw Error("scale_bench: --reference wants SPEC=COST");
      opt.references[v.substr(0, eq)] = parse_double(v.substr(eq + 1), a);
    } else {
      throw Error("scale_bench: unknown option " + a);
    }
  }
  if (opt.scenes.empty())
    opt.scenes = {"builtin:atrium?triangles=1000000", "builtin:atrium?triangles=4000000",
                  (default_scenes_dir() / "conference.obj").string()};
  return opt;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// One converged run's time, stage by stage (OptimizeReport::stages), and around them.
struct Profile {
  std::vector<double> stage_seconds;
  double setup = 0, finish = 0;
};

double share_of_gain(double start, double reached, double converged) {
  return start > converged ? 100.0 * (start - reached) / (start - converged) : 100.0;
}

struct Row {
  std::string spec;
  uint64_t triangles = 0;
  double build_s = 0, sweep_cost = 0, cost_1x = 0, cost_5x = 0, converged = 0, converged_s = 0;
  double run_1x = 0, run_5x = 0;  // the best cost of a run with a budget of 1x and 5x the build time
  double run_1x_s = 0, run_5x_s = 0;  // and the seconds each took, its final renumbering included
  uint32_t passes = 0;
  double build_bytes_per_tri = 0, optimize_bytes_per_tri = 0, rss_bytes_per_tri = 0;
  double reference = 0;  // 0: none given
  bool converged_run = true;
  std::vector<double> converged_runs_s;  // every converged run's seconds, the first included
  std::vector<StageReport> stages;       // the first converged run's stages
  std::vector<Profile> profiles;         // every converged run's, the first included
  Bvh sweep_tree;                        // kept for the repeated runs (--repeat)

  double median_converged_s() const { return median(converged_runs_s); }
  // The median over the converged runs of one figure of their profiles.
  template <class Field>
  double median_of(const Field& field) const {
    std::vector<double> v;
    for (const Profile& p : profiles) v.push_back(field(p));
    return median(v);
  }
  double median_stage_s(size_t k) const { return median_of([k](const Profile& p) { return p.stage_seconds[k]; }); }
  double median_setup_s() const { return median_of([](const Profile& p) { return p.setup; }); }
  double median_finish_s() const { return median_of([](const Profile& p) { return p.finish; }); }
  void add_profile(const OptimizeReport& rep) {
    Profile p;
    for (const StageReport& st : rep.stages) p.stage_seconds.push_back(st.seconds);
    p.setup = rep.setup_seconds;
    p.finish = rep.finish_seconds;
    profiles.push_back(std::move(p));
  }
};

// One more run of a scene, from its sweep tree: its seconds. A converged run must end where
// the first did (the optimizer is deterministic: the same tree, the same cost); a run stopped
// by --budget ends wherever its time ran out.
double repeat_run(Row& row, const Options& opt) {
  Bvh copy = row.sweep_tree;
  InsertionConfig cfg;
  cfg.limits.time_limit = opt.budget * row.build_s;
  const OptimizeReport rep = optimize_insertion(copy, cfg);
  if (opt.budget == 0.0 && rep.final_cost != row.converged)
    throw Error("a repeated run of " + row.spec + " ended at " + std::to_string(rep.final_cost) +
                ", the first at " + std::to_string(row.converged));
  // The same passes, so the same stages: their times line up with the first run's.
  if (rep.stages.size() == row.stages.size()) row.add_profile(rep);
  return rep.seconds;
}

Row run_scene(const std::string& spec, const Options& opt) {
  Row row;
  row.spec = spec;
  Mesh mesh = load_scene(spec);
  row.triangles = mesh.triangle_count();
  const double tris = static_cast<double>(row.triangles);
  const int64_t mesh_bytes = g_live.load();

  reset_heap_peak();
  SweepSahConfig sweep;
  sweep.leaf.max_leaf_size = 1;
  Bvh bvh;
  // As bake builds with the sweep builder: over the mesh itself, the triangles' boxes kept
  // inside the node array, with no array of references beside the tree.
  row.build_s = seconds_of([&] { bvh = build_sweep_sah(mesh, sweep); });
  row.build_bytes_per_tri = static_cast<double>(g_peak.load() - mesh_bytes) / tris;
  row.sweep_cost = sah_cost(bvh, CostModel{});

  // The copy kept for --repeat is not the optimizer's: its bytes are left out of the peak.
  const int64_t before_copy = g_live.load();
  if (opt.repeat > 1) row.sweep_tree = bvh;
  const int64_t kept_bytes = g_live.load() - before_copy;
  // The budget runs, each on a copy, before the converged run's heap is measured.
  for (double times : {1.0, 5.0}) {
    if (opt.budget > 0 && times > opt.budget) continue;
    Bvh copy = bvh;
    InsertionConfig cfg;
    cfg.limits.time_budget = times * row.build_s;
    const OptimizeReport r = optimize_insertion(copy, cfg);
    (times == 1.0 ? row.run_1x : row.run_5x) = r.final_cost;
    (times == 1.0 ? row.run_1x_s : row.run_5x_s) = r.seconds;
  }

  reset_heap_peak();
  InsertionConfig cfg;
  cfg.limits.time_limit = opt.budget * row.build_s;
  // A progress line rewritten in place on a terminal; into a file (a logged run) one line
  // every 10 passes, so the log reads without carriage returns.
  const bool terminal = ::isatty(2) == 1;
  cfg.limits.on_pass = [&](const PassRecord& p) {
    if (terminal)
      std::fprintf(stderr, "\r%s: pass %u, %.1f s, best %.4f   ", spec.c_str(), p.pass, p.seconds, p.best_cost);
    else if (p.pass % 10 == 0)
      std::fprintf(stderr, "%s: pass %u, %.1f s, best %.4f\n", spec.c_str(), p.pass, p.seconds, p.best_cost);
  };
  const OptimizeReport rep = optimize_insertion(bvh, cfg);
  if (terminal) std::fprintf(stderr, "\n");
  row.optimize_bytes_per_tri = static_cast<double>(g_peak.load() - mesh_bytes - kept_bytes) / tris;
  row.rss_bytes_per_tri = static_cast<double>(peak_rss()) / tris;
  row.cost_1x = cost_within(rep, row.build_s, true);
  row.cost_5x = cost_within(rep, 5.0 * row.build_s, true);
  row.converged = rep.final_cost;
  row.converged_s = rep.seconds;
  row.converged_runs_s.push_back(rep.seconds);
  row.stages = rep.stages;
  row.add_profile(rep);
  row.passes = rep.passes;
  row.converged_run = rep.stop_reason == StopReason::converged;
  if (auto it = opt.references.find(spec); it != opt.references.end()) row.reference = it->second;
  return row;
}

// Where each run's time went, and (for the smallest and largest built-in scenes, when they
// ran the same stages) how much each part grew from one to the other.
void print_stages(const std::vector<Row>& rows, const Row* small, const Row* large) {
  for (const Row& r : rows) {
    const double total = r.median_converged_s();
    std::printf("\n%s: where the time goes (%s; medians of %zu run%s)\n\n", r.spec.c_str(),
                r.converged_run ? "converged" : "stopped at the budget", r.profiles.size(),
                r.profiles.size() == 1 ? "" : "s");
    std::printf("| stage | passes | s | ms a pass | share |\n|---|---|---|---|---|\n");
    std::printf("| setup | | %.3f | | %.1f %% |\n", r.median_setup_s(), 100.0 * r.median_setup_s() / total);
    for (size_t k = 0; k < r.stages.size(); ++k) {
      const double sec = r.median_stage_s(k);
      std::printf("| %zu %.*s | %u | %.3f | %.2f | %.1f %% |\n", k, static_cast<int>(r.stages[k].name.size()),
                  r.stages[k].name.data(), r.stages[k].passes, sec,
                  r.stages[k].passes ? 1e3 * sec / r.stages[k].passes : 0.0, 100.0 * sec / total);
    }
    std::printf("| finish (renumbering) | | %.3f | | %.1f %% |\n", r.median_finish_s(), 100.0 * r.median_finish_s() / total);
  }
  if (!small || !large || small == large || small->stages.size() != large->stages.size()) return;
  for (size_t k = 0; k < small->stages.size(); ++k)
    if (small->stages[k].name != large->stages[k].name) return;
  const double n = static_cast<double>(large->triangles) / static_cast<double>(small->triangles);
  const double nlogn = n * std::log(static_cast<double>(large->triangles)) / std::log(static_cast<double>(small->triangles));
  std::printf("\ngrowth of each part, %llu -> %llu triangles (n log n x%.2f; medians)\n\n",
              static_cast<unsigned long long>(small->triangles), static_cast<unsigned long long>(large->triangles), nlogn);
  std::printf("| part | s | passes | s a pass | seconds beyond n log n at the larger size |\n|---|---|---|---|---|\n");
  // What the part took at the larger size beyond the smaller's times n log n's growth: where
  // the growth above n log n comes from (negative: below it).
  const auto ratio = [](double from, double to) {
    char text[32] = "";
    if (from > 0) std::snprintf(text, sizeof text, "x%.2f", to / from);
    return std::string(text);
  };
  const auto row = [&](const std::string& name, double a, double b, uint32_t pa, uint32_t pb) {
    std::printf("| %s | %s | %s | %s | %+.3f |\n", name.c_str(), ratio(a, b).c_str(), ratio(pa, pb).c_str(),
                pa && pb ? ratio(a / pa, b / pb).c_str() : "", b - nlogn * a);
  };
  row("setup", small->median_setup_s(), large->median_setup_s(), 0, 0);
  for (size_t k = 0; k < small->stages.size(); ++k)
    row(std::to_string(k) + " " + std::string(small->stages[k].name), small->median_stage_s(k), large->median_stage_s(k),
        small->stages[k].passes, large->stages[k].passes);
  row("finish (renumbering)", small->median_finish_s(), large->median_finish_s(), 0, 0);
  row("whole run", small->median_converged_s(), large->median_converged_s(), small->passes, large->passes);
}

void print(const std::vector<Row>& rows, int threads) {
  std::printf("\n%d threads; wall seconds of one run; bytes per triangle less the mesh (heap peak), RSS of the whole process\n\n",
              threads);
  std::printf("| scene | triangles | build s | sweep cost | 1x: cost (%% gain) | 5x: cost (%% gain, %% above converged) | "
              "converged cost | converged s (x build) | passes | heap B/tri build / optimize | RSS B/tri |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  // The 1x and 5x columns from the converged run's trace, then (second line) from runs limited to that time.
  for (const Row& r : rows) {
    std::printf("| %s | %llu | %.2f | %.2f | %.2f (%.1f) | %.2f (%.1f, %.2f) | %.2f%s | %.1f (%.1f) | %u | %.1f / %.1f | %.0f |\n",
                r.spec.c_str(), static_cast<unsigned long long>(r.triangles), r.build_s, r.sweep_cost, r.cost_1x,
                share_of_gain(r.sweep_cost, r.cost_1x, r.converged), r.cost_5x,
                share_of_gain(r.sweep_cost, r.cost_5x, r.converged), 100.0 * (r.cost_5x / r.converged - 1.0), r.converged,
                r.converged_run ? "" : " (stopped at the budget)", r.converged_s, r.converged_s / r.build_s, r.passes, r.build_bytes_per_tri, r.optimize_bytes_per_tri,
                r.rss_bytes_per_tri);
    if (r.run_1x > 0) {
      char five[64] = "-";
      if (r.run_5x > 0)
        std::snprintf(five, sizeof five, "%.2f (%.1f, %.2f) in %.2f s", r.run_5x,
                      share_of_gain(r.sweep_cost, r.run_5x, r.converged), 100.0 * (r.run_5x / r.converged - 1.0),
                      r.run_5x_s);
      std::printf("|   runs with a budget of 1x / 5x | | | | %.2f (%.1f) in %.2f s | %s | | | | | |\n", r.run_1x,
                  share_of_gain(r.sweep_cost, r.run_1x, r.converged), r.run_1x_s, five);
    }
    if (r.reference > 0)
      std::printf("|   vs given converged %.2f (trace; budget runs) | | | | %.1f %%; %.1f %% | %.1f %%; %.1f %% | | | | | |\n",
                  r.reference, share_of_gain(r.sweep_cost, r.cost_1x, r.reference),
                  share_of_gain(r.sweep_cost, r.run_1x, r.reference), share_of_gain(r.sweep_cost, r.cost_5x, r.reference),
                  share_of_gain(r.sweep_cost, r.run_5x, r.reference));
  }
  // Growth of the time to convergence between the smallest and largest built-in scenes.
  const Row* small = nullptr;
  const Row* large = nullptr;
  for (const Row& r : rows) {
    if (r.spec.rfind("builtin", 0) != 0) continue;
    if (!small || r.triangles < small->triangles) small = &r;
    if (!large || r.triangles > large->triangles) large = &r;
  }
  if (small && large && large->triangles > small->triangles) {
    const double n = static_cast<double>(large->triangles) / static_cast<double>(small->triangles);
    const double nlogn = n * std::log(static_cast<double>(large->triangles)) / std::log(static_cast<double>(small->triangles));
    std::printf("\ntime to convergence %llu -> %llu triangles: x%.2f (build x%.2f; n log n x%.2f; in build times x%.2f)\n",
                static_cast<unsigned long long>(small->triangles), static_cast<unsigned long long>(large->triangles),
                large->converged_s / small->converged_s, large->build_s / small->build_s, nlogn,
                (large->converged_s / large->build_s) / (small->converged_s / small->build_s));
    const size_t runs = std::min(small->converged_runs_s.size(), large->converged_runs_s.size());
    if (runs > 1) {
      std::printf("over %zu runs of each: medians %.2f s and %.2f s, x%.2f (n log n x%.2f); run by run:", runs,
                  small->median_converged_s(), large->median_converged_s(),
                  large->median_converged_s() / small->median_converged_s(), nlogn);
      for (size_t i = 0; i < runs; ++i)
        std::printf(" x%.2f", large->converged_runs_s[i] / small->converged_runs_s[i]);
      std::printf("\n");
    }
  }
  for (const Row& r : rows)
    if (r.converged_runs_s.size() > 1) {
      std::printf("%s: converged in", r.spec.c_str());
      for (double t : r.converged_runs_s) std::printf(" %.2f", t);
      std::printf(" s (median %.2f)\n", r.median_converged_s());
    }
  print_stages(rows, small, large);
}

nlohmann::json stages_json(const Row& r) {
  nlohmann::json stages = nlohmann::json::array();
  for (size_t k = 0; k < r.stages.size(); ++k)
    stages.push_back({{"name", std::string(r.stages[k].name)},
                      {"passes", r.stages[k].passes},
                      {"seconds_median", r.median_stage_s(k)},
                      {"cost", r.stages[k].cost}});
  return stages;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  try {
    opt = parse(argc, argv);
  } catch (const Error& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  return guarded_main("scale_bench", [&] {
    require_scene_files(opt.scenes);
    ThreadLimit limit(opt.threads);
    std::vector<Row> rows;
    for (const std::string& spec : opt.scenes) {
      rows.push_back(run_scene(spec, opt));
      // Each scene's figures as soon as they are known: the large runs take long.
      const Row& r = rows.back();
      std::fprintf(stderr, "%s: build %.2f s, sweep %.4f, 1x %.4f, 5x %.4f, end %.4f after %.1f s (%s), heap %.1f B/tri\n",
                   r.spec.c_str(), r.build_s, r.sweep_cost, r.cost_1x, r.cost_5x, r.converged, r.converged_s,
                   r.converged_run ? "converged" : "budget", r.optimize_bytes_per_tri);
    }
    // The repeated runs, the scenes in turn, so that a slow phase of the machine falls on all.
    for (int k = 1; k < opt.repeat; ++k)
      for (Row& r : rows) {
        r.converged_runs_s.push_back(repeat_run(r, opt));
        std::fprintf(stderr, "%s: run %d converged after %.2f s\n", r.spec.c_str(), k + 1, r.converged_runs_s.back());
      }
    print(rows, opt.threads);
    if (!opt.json_path.empty()) {
      nlohmann::json j = nlohmann::json::array();
      for (const Row& r : rows)
        j.push_back({{"scene", r.spec},
                     {"triangles", r.triangles},
                     {"threads", opt.threads},
                     {"build_seconds", r.build_s},
                     {"sweep_cost", r.sweep_cost},
                     {"cost_at_1x_build", r.cost_1x},
                     {"cost_at_5x_build", r.cost_5x},
                     {"cost_of_1x_run", r.run_1x},
                     {"cost_of_5x_run", r.run_5x},
                     {"seconds_of_1x_run", r.run_1x_s},
                     {"seconds_of_5x_run", r.run_5x_s},
                     {"converged_cost", r.converged},
                     {"converged_seconds", r.converged_s},
                     {"converged_seconds_runs", r.converged_runs_s},
                     {"converged_seconds_median", r.median_converged_s()},
                     {"passes", r.passes},
                     {"stages", stages_json(r)},
                     {"setup_seconds_median", r.median_setup_s()},
                     {"finish_seconds_median", r.median_finish_s()},
                     {"heap_bytes_per_triangle_build", r.build_bytes_per_tri},
                     {"heap_bytes_per_triangle_optimize", r.optimize_bytes_per_tri},
                     {"peak_rss_bytes_per_triangle", r.rss_bytes_per_tri}});
      write_json(opt.json_path, j);
    }
    return 0;
  });
}
