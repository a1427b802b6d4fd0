// Insertion-based optimization (Bittner et al. 2013) on every shared scene and the built-in
// scene, from the exact sweep SAH tree with one reference per leaf, c_T = 3, c_I = 2,
// against the peer figures of issue 4 (madmann91/bvh reinsertion, tinybvh Optimize).
//
//   insertion_bench [--scenes DIR] [--scene SPEC]... [--no-builtin] [--builtin SPEC]
//                   [--runs 3] [--max-passes N] [--time-limit S] [--json FILE]
//                   [--stop-after P_T] [--no-sequential] [--no-median] [--measures] [--quick]
//
// "ours" is the default form (hybrid); "seq" the paper's sequential form alone (1 thread),
// "par" the deterministic parallel form alone (2 threads), "reg" the regional form (2 threads;
// the default's form from 1M nodes, kRegionalFrom, above every shared scene); --no-sequential
// skips these three.
//
// Times are the median of --runs runs (the same tree every run: the optimizer is
// deterministic). "to peer" is the time at which our trace first reaches madmann91's cost.
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

#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/sweep_sah_builder.h"

namespace {

using namespace bvhopt;
using namespace bvhopt::bench;

// The table: exact sweep SAH cost, madmann91 (cost, ms), tinybvh (cost, ms).
struct Peer {
  double sah, mm_cost, mm_ms, tiny_cost, tiny_ms;
};
const std::map<std::string, Peer>& peers() {
  static const std::map<std::string, Peer> table = {
      {"2CylinderEngine", {336.85, 312.19, 31, 281.08, 988}}, {"armadillo", {81.36, 81.07, 10, 80.76, 349}},
      {"beast", {61.72, 60.99, 11, 60.09, 392}},               {"bunny", {94.21, 94.11, 13, 95.35, 398}},
      {"classroom", {13.63, 10.54, 22, 13.39, 723}},           {"conference", {129.22, 103.73, 98, 96.96, 5626}},
      {"horse", {68.39, 68.31, 20, 68.09, 729}},               {"nefertiti", {104.87, 104.59, 18, 104.71, 673}},
      {"ogre", {82.70, 80.23, 25, 79.12, 828}},                {"sponza_dabrovic", {229.80, 192.59, 22, 176.40, 469}},
      {"staircase", {49.68, 43.55, 4, 41.98, 245}},
  };
  return table;
}
// The paper's reductions (Table 1) for the scenes we share with it.
const std::map<std::string, double>& paper() {
  static const std::map<std::string, double> table = {{"sponza_dabrovic", 0.8274}, {"conference", 0.7866}};
  return table;
}

struct Options {
  SceneOptions scenes;
  int runs = 3;
  uint32_t max_passes = 1000;
  double time_limit = 0.0;
  uint32_t stop_after = 10;
  std::string json_path;
  bool sequential = true;
  bool median_start = true;
  bool measures = false;
  bool quick = false;  // the default form on 2 threads only
};

struct OptRun {
  OptimizeReport report;
  double seconds = 0.0;  // median over runs
  Bvh tree;
};

OptRun run_optimizer(const Bvh& start, const PrimitiveRefs& refs, InsertionConfig cfg, int threads, int runs) {
  ThreadLimit limit(threads);
  OptRun out;
  std::vector<double> times;
  for (int r = 0; r < runs; ++r) {
    Bvh t = start;
    OptimizeReport rep = optimize_insertion(t, cfg);
    times.push_back(rep.seconds);
    if (r == 0) {
      out.report = rep;
      out.tree = std::move(t);
    }
  }
  out.seconds = upper_median(times);
  return out;
}


// Seconds into the run at which the trace first reaches `target`; negative if never.
double time_to_reach(const OptimizeReport& rep, double target) {
  if (rep.initial_cost <= target) return 0.0;
  for (const PassRecord& p : rep.trace)
    if (p.cost <= target) return p.seconds;
  return -1.0;
}

std::string stem_of(const std::string& spec) {
  if (spec.rfind("builtin", 0) == 0) return "builtin";
  return std::filesystem::path(spec).stem().string();
}

// Unlike the other benches, a bad command line exits with status 2 (an Error from here).
Options parse(int argc, char** argv) {
  Options opt;
  Args args(argc, argv, "insertion_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (read_scene_option(args, opt.scenes)) continue;
    if (a == "--runs") opt.runs = std::max(1, args.int_value());
    else if (a == "--max-passes") opt.max_passes = args.u32_value();
    else if (a == "--time-limit") opt.time_limit = args.double_value();
    else if (a == "--stop-after") opt.stop_after = args.u32_value();
    else if (a == "--json") opt.json_path = args.value();
    else if (a == "--no-sequential") opt.sequential = false;
    else if (a == "--no-median") opt.median_start = false;
    else if (a == "--measures") opt.measures = true;
    else if (a == "--quick") opt.quick = true;
    else throw Error("insertion_bench: unknown option " + a);
  }
  if (opt.quick) opt.sequential = opt.median_start = false;
  return opt;
}

int run(const Options& opt) {
  // A missing scenes folder only warns: the built-in scene still runs.
  const std::vector<std::string> specs = scene_specs(opt.scenes, "insertion_bench");

  nlohmann::json all = nlohmann::json::array();
  std::printf(
      "%-16s %7s | %8s %7s | %8s %6s %8s %8s %7s %7s %7s | %7s %7s %7s | %8s %6s | %8s %6s | %8s %6s | %8s %6s %7s | %8s "
      "%8s\n",
      "scene", "tris", "SAH", "build", "ours", "%", "opt 1t", "opt 2t", "2t/bld", "to mm", "to best", "mm %", "mm ms", "tiny %",
      "seq", "seq s", "par", "par s", "reg", "reg s", "median", "% SAH", "med s", "cost", "ocost");
  for (const std::string& spec : specs) {
    const std::string name = stem_of(spec);
    Mesh mesh;
    try {
      mesh = load_scene(spec);
    } catch (const Error& e) {
      std::cerr << "insertion_bench: skipping " << spec << ": " << e.what() << "\n";
      continue;
    }
    PrimitiveRefs refs = make_references(mesh);
    nlohmann::json row;
    row["scene"] = name;
    row["triangles"] = refs.size();

    // The sweep build on 2 threads: the time the whole optimization must stay under.
    Bvh sweep;
    std::vector<double> build_times;
    {
      ThreadLimit limit(2);
      for (int r = 0; r < opt.runs; ++r) build_times.push_back(seconds_of([&] { sweep = build_sweep_sah(refs); }));
    }
    const double build_s = upper_median(build_times);
    const double sah = sah_cost(sweep);

    InsertionConfig cfg;
    cfg.limits.max_passes = opt.max_passes;
    cfg.limits.time_limit = opt.time_limit;
    cfg.stop_after = opt.stop_after;
    OptRun p1 = opt.quick ? OptRun{} : run_optimizer(sweep, refs, cfg, 1, opt.runs);
    OptRun p2 = run_optimizer(sweep, refs, cfg, 2, opt.runs);
    const double ours = p2.report.final_cost;

    auto peer_it = peers().find(name);
    const bool has_peer = peer_it != peers().end();
    const Peer peer = has_peer ? peer_it->second : Peer{0, 0, 0, 0, 0};
    // The peers' percentages are relative to their own SAH figure; ours to our sweep tree.
    const double mm_pct = has_peer ? peer.mm_cost / peer.sah : 0.0;
    const double tiny_pct = has_peer ? peer.tiny_cost / peer.sah : 0.0;
    const double to_peer = has_peer ? time_to_reach(p2.report, peer.mm_cost) : -1.0;
    const double to_best_peer = has_peer ? time_to_reach(p2.report, std::min(peer.mm_cost, peer.tiny_cost)) : -1.0;

    OptRun seq;
    if (opt.sequential && !opt.quick) {
      InsertionConfig c = cfg;
      c.form = InsertionForm::sequential;
      seq = run_optimizer(sweep, refs, c, 1, opt.runs);
    }
    OptRun par;
    if (opt.sequential && !opt.quick) {
      InsertionConfig c = cfg;
      c.form = InsertionForm::parallel;
      par = run_optimizer(sweep, refs, c, 2, opt.runs);
    }
    OptRun reg;
    if (opt.sequential && !opt.quick) {
      InsertionConfig c = cfg;
      c.form = InsertionForm::regional;
      reg = run_optimizer(sweep, refs, c, 2, opt.runs);
    }
    OptRun med;
    double med_start = 0.0;
    if (opt.median_start && !opt.quick) {
      Bvh m;
      {
        ThreadLimit limit(2);
        m = build_spatial_median(refs);
      }
      med_start = sah_cost(m);
      med = run_optimizer(m, refs, cfg, 2, 1);
    }
    Bvh compacted = p2.tree;
    CollapseResult comp = collapse_leaves(compacted);
    const double sah_ocost = optimal_collapse_cost(sweep);

    std::printf(
        "%-16s %7zu | %8.2f %7.3f | %8.2f %5.1f%% %8.3f %8.3f %7.2f %7.3f %7.3f | %6.1f%% %7.0f %6.1f%% | %8.2f %6.3f | %8.2f "
        "%6.3f | %8.2f %6.3f | %8.2f %5.1f%% %7.3f | %8.2f %8.2f\n",
        name.c_str(), refs.size(), sah, build_s, ours, 100 * ours / sah, p1.seconds, p2.seconds, p2.seconds / build_s,
        to_peer, to_best_peer, 100 * mm_pct, peer.mm_ms, 100 * tiny_pct, opt.sequential ? seq.report.final_cost : 0.0,
        opt.sequential ? seq.seconds : 0.0, opt.sequential ? par.report.final_cost : 0.0,
        opt.sequential ? par.seconds : 0.0, opt.sequential ? reg.report.final_cost : 0.0,
        opt.sequential ? reg.seconds : 0.0, opt.median_start ? med.report.final_cost : 0.0,
        opt.median_start ? 100 * med.report.final_cost / sah : 0.0, opt.median_start ? med.seconds : 0.0,
        comp.cost_before, comp.cost_after);
    std::printf("%-16s within the sweep build's %.3f s: %.2f (%.1f%% of SAH)\n", "", build_s,
                cost_within(p2.report, build_s), 100 * cost_within(p2.report, build_s) / sah);
    std::fflush(stdout);

    row["sah_cost"] = sah;
    row["sah_ocost"] = sah_ocost;
    row["sweep_build_seconds_2t"] = build_s;
    row["final_cost"] = ours;
    row["final_ratio"] = ours / sah;
    row["passes"] = p2.report.passes;
    row["moves"] = p2.report.moves;
    row["stop_reason"] = std::string(stop_reason_name(p2.report.stop_reason));
    row["optimize_seconds_2t"] = p2.seconds;
    row["optimize_over_build_2t"] = p2.seconds / build_s;
    // What the optimizer reaches within the time of the sweep build that precedes it.
    row["cost_within_build_time_2t"] = cost_within(p2.report, build_s);
    if (!opt.quick) {
      row["optimize_seconds_1t"] = p1.seconds;
      row["same_tree_1t_2t"] = p1.report.final_cost == p2.report.final_cost;
    }
    if (has_peer) {
      row["peer_mm_cost"] = peer.mm_cost;
      row["peer_mm_ratio"] = mm_pct;
      row["peer_mm_ms"] = peer.mm_ms;
      row["peer_tiny_cost"] = peer.tiny_cost;
      row["peer_tiny_ratio"] = tiny_pct;
      row["peer_tiny_ms"] = peer.tiny_ms;
      row["seconds_to_mm_cost_2t"] = to_peer;
      row["seconds_to_best_peer_cost_2t"] = to_best_peer;
      row["beats_every_peer_ratio"] = ours / sah < std::min(mm_pct, tiny_pct);
    }
    if (auto pp = paper().find(name); pp != paper().end()) {
      row["paper_ratio"] = pp->second;
      row["meets_paper"] = ours / sah <= pp->second;
    }
    if (opt.sequential) {
      row["sequential_cost"] = seq.report.final_cost;
      row["sequential_seconds_1t"] = seq.seconds;
      row["sequential_passes"] = seq.report.passes;
      row["parallel_cost"] = par.report.final_cost;
      row["parallel_seconds_2t"] = par.seconds;
      row["parallel_passes"] = par.report.passes;
      row["regional_cost"] = reg.report.final_cost;
      row["regional_seconds_2t"] = reg.seconds;
      row["regional_passes"] = reg.report.passes;
    }
    if (opt.median_start) {
      row["median_start_cost"] = med_start;
      row["median_final_cost"] = med.report.final_cost;
      row["median_seconds_2t"] = med.seconds;
      row["median_passes"] = med.report.passes;
    }
    row["compacted_cost"] = comp.cost_after;
    row["compacted_leaves"] = comp.leaves_after;
    if (opt.measures) {
      nlohmann::json ms = nlohmann::json::object();
      for (InsertionMeasure m : {InsertionMeasure::sum, InsertionMeasure::min, InsertionMeasure::comb}) {
        InsertionConfig c = cfg;
        c.measure = m;
        OptRun r = run_optimizer(sweep, refs, c, 2, 1);
        ms[std::string(measure_name(m))] = {{"cost", r.report.final_cost}, {"seconds_2t", r.seconds},
                                            {"passes", r.report.passes}};
        std::printf("    measure %-5s: %8.2f (%5.1f%%) in %.3f s, %u passes\n", std::string(measure_name(m)).c_str(),
                    r.report.final_cost, 100 * r.report.final_cost / sah, r.seconds, r.report.passes);
      }
      row["measures"] = ms;
    }
    all.push_back(row);
  }
  if (!opt.json_path.empty()) write_json(opt.json_path, all);
  return 0;
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
  return guarded_main("insertion_bench", [&] { return run(opt); });
}
