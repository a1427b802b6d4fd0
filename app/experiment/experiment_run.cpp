// The experiment runner: the protocols of the three papers over a grid of scenes x tasks.
#include <tbb/version.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <thread>

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/error.h"
#include "experiment/experiment.h"
#include "bvhopt/finalize.h"
#include "bvhopt/font.h"
#include "bvhopt/image_legend.h"
#include "bvhopt/images.h"
#include "bvhopt/png_file.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/stats.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/wide_tracer.h"
#include "experiment/experiment_internal.h"

namespace bvhopt {
namespace {

using experiment_detail::json;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr const char* kBvhoptVersion = "0.1.0";
constexpr int kResultsFormat = 2;  // 2: the insertion_hybrid tree beside the paper's insertion
// A renderer traces leaves of several triangles: every traced tree is first compacted
// (Bittner's section 2.6) with this leaf limit, the same for every method, so the ray
// times compare trees and not leaf sizes.
constexpr uint32_t kTracedLeafSize = 8;
// Leaves of the Dammertz-Keller trees (binned SAH, as their builder): pieces of one triangle
// in one leaf are then deduplicated as the paper does.
constexpr uint32_t kEvhLeafSize = 4;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// A short name for tables and file names: the file stem, or "builtin".
std::string scene_short_name(const std::string& spec) {
  if (spec.rfind("builtin", 0) == 0) return "builtin";
  std::string stem = fs::path(spec).stem().string();
  std::string out;
  for (char c : stem) out += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return out.empty() ? "scene" : out;
}

struct Task {
  uint32_t index = 0;
  std::string kind;  // "optimizers", "evh", "rotation"
  uint32_t scene = 0;
};

// The fixed grid: per scene the optimizer protocol (Kensler + Bittner) and the EVH protocol
// (DK Figure 4 + Table 1), then Figure 5 once. Task k belongs to shard k mod N.
std::vector<Task> make_grid(const ExperimentConfig& config, int rotation_scene) {
  std::vector<Task> grid;
  for (uint32_t s = 0; s < config.scenes.size(); ++s) {
    grid.push_back({static_cast<uint32_t>(grid.size()), "optimizers", s});
    grid.push_back({static_cast<uint32_t>(grid.size()), "evh", s});
  }
  if (rotation_scene >= 0 && config.rotation_frames > 0)
    grid.push_back({static_cast<uint32_t>(grid.size()), "rotation", static_cast<uint32_t>(rotation_scene)});
  return grid;
}

int pick_rotation_scene(const ExperimentConfig& config) {
  if (config.rotation_scene.empty() || config.scenes.empty()) return -1;
  const std::string key = lower(config.rotation_scene);
  for (size_t i = 0; i < config.scenes.size(); ++i)
    if (lower(config.scenes[i]).find(key) != std::string::npos) return static_cast<int>(i);
  return 0;
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      auto colon = line.find(':');
      if (colon != std::string::npos) {
        std::string m = line.substr(colon + 1);
        m.erase(0, m.find_first_not_of(' '));
        return m;
      }
    }
  }
  return "unknown";
}

std::string utc_now() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// Settings that decide the results; merge checks that every part used the same.
json settings_json(const ExperimentConfig& c) {
  return json{{"scenes", c.scenes},
              {"seed", c.seed},
              {"time_budget", c.time_budget},
              {"anneal_budget_fraction", c.anneal_budget_fraction},
              {"anneal_seconds_per_node_pass", c.anneal_seconds_per_node_pass},
              {"rays", c.rays},
              {"evh_rays", c.evh_rays},
              {"repeats", c.repeats},
              {"evh_t_values", c.evh_t_values},
              {"rotation_frames", c.rotation_frames},
              {"rotation_t", c.rotation_t},
              {"rotation_scene", c.rotation_scene},
              {"heatmap_width", c.heatmap_width},
              {"heatmap_height", c.heatmap_height},
              {"traced_leaf_size", kTracedLeafSize},
              {"layout", std::string(trace_layout_name(c.layout))},
              {"wide_block_cost", c.wide_cost.block},
              {"evh_leaf_size", kEvhLeafSize},
              {"cost_model", {{"c_T", CostModel{}.traversal}, {"c_I", CostModel{}.intersection}}}};
}

json machine_json(const ExperimentConfig& c) {
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  return json{{"cpu", cpu_model()},
              {"cores", cores},
              {"threads", c.threads > 0 ? c.threads : static_cast<int>(cores)},
              {"bvhopt", kBvhoptVersion},
              {"compiler", __VERSION__},
              {"tbb", std::to_string(TBB_VERSION_MAJOR) + "." + std::to_string(TBB_VERSION_MINOR)},
              {"date", utc_now()}};
}

// The running state of one run: progress bookkeeping across tasks.
class Runner {
 public:
  Runner(const ExperimentConfig& config, size_t my_tasks) : config_(config), task_count_(my_tasks) {}

  void begin_task(uint32_t ordinal, const std::string& scene, double weight) {
    task_ordinal_ = ordinal;
    scene_ = scene;
    task_weight_ = weight;
    task_start_ = Clock::now();
  }
  void end_task() { done_weight_ += task_weight_; }
  void set_total_weight(double w) { total_weight_ = w; }

  // `fraction`: how far the current task has come, for the estimate of what remains.
  void step(const std::string& what, double fraction, uint32_t pass = 0) {
    if (!config_.on_progress) return;
    ExperimentProgress p;
    p.scene = scene_;
    p.step = what;
    p.pass = pass;
    p.elapsed = seconds_since(start_);
    const double done = done_weight_ + task_weight_ * std::clamp(fraction, 0.0, 1.0);
    // Too early an estimate only says 0:00; wait for a few seconds of work.
    p.remaining = done > 0.0 && p.elapsed > 2.0 ? p.elapsed * (total_weight_ - done) / done : -1.0;
    p.task = task_ordinal_;
    p.task_count = static_cast<uint32_t>(task_count_);
    config_.on_progress(p);
  }

  const ExperimentConfig& config() const { return config_; }

 private:
  const ExperimentConfig& config_;
  size_t task_count_;
  Clock::time_point start_ = Clock::now();
  Clock::time_point task_start_ = Clock::now();
  std::string scene_;
  uint32_t task_ordinal_ = 0;
  double task_weight_ = 0.0, done_weight_ = 0.0, total_weight_ = 1.0;
};

struct RaySets {
  std::vector<RaySet> sets;  // primary, random, ao, path
};

const RayKind kTableRayKinds[] = {RayKind::primary, RayKind::random, RayKind::ao, RayKind::path};

// A tree made ready for tracing: compacted to leaves of up to kTracedLeafSize references.
FlatBvh traced_flat(const Bvh& bvh, const PrimitiveRefs& refs) {
  Bvh copy = bvh;
  CollapseConfig cc;
  cc.max_leaf_size = kTracedLeafSize;
  collapse_leaves(copy, cc);
  return finalize(copy, refs);
}
Tracer make_tracer(const Bvh& bvh, const PrimitiveRefs& refs, const Mesh& mesh) {
  return Tracer(traced_flat(bvh, refs), mesh);
}

// The wide tracer of the configured layout and collapse cost (none for bvh2).
std::unique_ptr<WideTracer> make_wide(const FlatBvh& flat, const Mesh& mesh, const ExperimentConfig& c) {
  return make_wide_tracer(flat, mesh, c.layout, c.wide_cost);
}

// Every tree of a scene traced on the same ray sets. Deterministic figures (traversal steps,
// hit rates) go to `det`, clock figures to `timing`. The timed passes are interleaved, round
// by round over all trees, so that a burst of load from other processes on a shared machine
// slows every tree alike instead of spoiling one tree's figure; each figure is the median of
// `repeats` passes (the first taken by measure_rays right after its untimed pass).
struct TracedTree {
  std::string key;
  Tracer tracer;                     // binary: heat maps
  std::unique_ptr<WideTracer> wide;  // the configured wide layout: ray measurements

  TracedTree(std::string k, const FlatBvh& flat, const Mesh& mesh, const ExperimentConfig& c)
      : key(std::move(k)), tracer(flat, mesh), wide(make_wide(flat, mesh, c)) {}
  AnyTracer traced() const { return wide ? AnyTracer(*wide) : AnyTracer(tracer); }
};
void measure_trees(Runner& run, const std::vector<TracedTree>& trees, const RaySets& rays, json& det_trees,
                   json& timing_trees) {
  const int repeats = std::max(1, run.config().repeats);
  const size_t sets = rays.sets.size();
  std::vector<std::vector<double>> samples(trees.size() * sets);
  MeasureOptions mo;
  mo.repeats = 1;
  for (size_t t = 0; t < trees.size(); ++t) {
    for (size_t k = 0; k < sets; ++k) {
      const RaySet& set = rays.sets[k];
      const std::string kind(ray_kind_name(set.kind));
      run.step(trees[t].key + ": rays " + kind, 0.85);
      RayMeasurement m = measure_rays(trees[t].traced(), set.rays, set.query, mo);
      json& d = det_trees[trees[t].key];
      d["steps"][kind] = m.steps.mean;
      d["triangle_tests"][kind] = m.triangle_tests.mean;
      d["hit_rate"][kind] = m.hit_rate;
      samples[t * sets + k].push_back(m.seconds);
    }
  }
  std::vector<Hit> hits;
  for (int round = 1; round < repeats; ++round) {
    run.step("timing round " + std::to_string(round + 1) + " of " + std::to_string(repeats), 0.9);
    for (size_t t = 0; t < trees.size(); ++t) {
      for (size_t k = 0; k < sets; ++k) {
        const RaySet& set = rays.sets[k];
        const auto t0 = Clock::now();
        trace_rays(trees[t].traced(), set.rays, set.query, hits);
        samples[t * sets + k].push_back(seconds_since(t0));
      }
    }
  }
  for (size_t t = 0; t < trees.size(); ++t) {
    for (size_t k = 0; k < sets; ++k) {
      std::vector<double>& v = samples[t * sets + k];
      std::sort(v.begin(), v.end());
      const double median = v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
      const std::string kind(ray_kind_name(rays.sets[k].kind));
      json& tm = timing_trees[trees[t].key];
      tm["ray_seconds"][kind] = median;
      tm["mrays_per_second"][kind] = median > 0.0 ? 1e-6 * double(rays.sets[k].rays.size()) / median : 0.0;
    }
  }
}

json trace_costs(const OptimizeReport& r) {
  json costs = json::array();
  for (const PassRecord& p : r.trace) costs.push_back(p.cost);
  return costs;
}
json trace_seconds(const OptimizeReport& r) {
  json s = json::array();
  for (const PassRecord& p : r.trace) s.push_back(p.seconds);
  return s;
}

json tree_det(const Bvh& bvh) {
  TreeStats st = compute_stats(bvh);
  return json{{"cost", st.cost},
              {"ocost", st.ocost},
              {"inner_nodes", st.inner_nodes},
              {"max_depth", st.max_depth},
              {"inner_area_by_depth", st.inner_area_by_depth},
              {"leaf_area_by_depth", st.leaf_area_by_depth},
              {"root_area", st.root_area}};
}

std::vector<TraceCounters> heatmap_steps(const Tracer& tracer, const RaySet& camera_rays) {
  std::vector<Hit> hits;
  std::vector<TraceCounters> counters;
  trace_rays(tracer, camera_rays.rays, RayQuery::closest, hits, &counters);
  return counters;
}

// The heat maps of the SAH tree and the best one, on one scale, with legends.
void write_heatmap_pair(const Tracer& sah, const Tracer& best, const std::string& best_key, const RaySet& camera_rays,
                        const std::string& scene, const fs::path& sah_file, const fs::path& best_file) {
  std::string font_problem;
  const std::optional<Font> font = Font::load_default(font_problem);
  if (!font) std::cerr << "warning: " << font_problem << ": heat maps without captions\n";
  const std::vector<TraceCounters> a = heatmap_steps(sah, camera_rays), b = heatmap_steps(best, camera_rays);
  write_heatmaps({{&a, "sah  \u00b7  " + scene, sah_file}, {&b, best_key + " (best)  \u00b7  " + scene, best_file}},
                 camera_rays.width, camera_rays.height, font ? &*font : nullptr);
}

// Kensler's Table 1 and Figures 3-4, Bittner's Table 1 and Figure 7, on one scene.
// The ray sets of the optimizer tables, and the camera rays of the heat maps, made from the
// SAH tree: the rays depend on the mesh and seed only.
struct TableRays {
  RaySets tables;
  RaySet heat;
};

TableRays make_table_rays(const ExperimentConfig& cfg, const Mesh& mesh, const Tracer& sah_tracer) {
  TableRays rays;
  for (RayKind kind : kTableRayKinds) {
    RaySetConfig rc;
    rc.kind = kind;
    rc.seed = cfg.seed;
    rc.count = cfg.rays;
    rays.tables.sets.push_back(make_ray_set(mesh, sah_tracer, rc));
  }
  RaySetConfig hc;
  hc.kind = RayKind::primary;
  hc.seed = cfg.seed;
  hc.width = cfg.heatmap_width;
  hc.height = cfg.heatmap_height;
  hc.count = static_cast<uint64_t>(cfg.heatmap_width) * cfg.heatmap_height;
  rays.heat = make_ray_set(mesh, sah_tracer, hc);
  return rays;
}

// The optimized trees of one scene, kept for tracing, and their entries in results.json.
struct OptimizedTrees {
  json& det;
  json& timing;
  std::vector<std::pair<std::string, Bvh>> trees;

  void record(const std::string& key, Bvh tree, const OptimizeReport& rep, double secs) {
    det["trees"][key] = tree_det(tree);
    det["trees"][key]["passes"] = rep.passes;
    det["trees"][key]["moves"] = rep.moves;
    det["trees"][key]["stop_reason"] = std::string(stop_reason_name(rep.stop_reason));
    det["traces"][key] = trace_costs(rep);
    timing["traces"][key] = trace_seconds(rep);
    timing["trees"][key]["optimize_seconds"] = secs;
    trees.emplace_back(key, std::move(tree));
  }
};

// Hill climbing: until no pass improves.
void run_hill_climb(Runner& run, const Bvh& sah, OptimizedTrees& out) {
  Bvh tree = sah;
  HillClimbConfig hc_cfg;
  hc_cfg.limits.on_pass = [&](const PassRecord& p) { run.step("hill climbing", 0.15, p.pass); };
  const auto t0 = Clock::now();
  OptimizeReport rep = hill_climb(tree, hc_cfg);
  out.record("hill", std::move(tree), rep, seconds_since(t0));
}

// Kensler's schedule scaled down to the budget (see ExperimentConfig::time_budget), described
// in `schedule` for the report.
AnnealConfig budgeted_anneal_config(const ExperimentConfig& cfg, size_t inner_count, json& schedule) {
  AnnealConfig ac;
  ac.seed = cfg.seed;
  const double inner = static_cast<double>(std::max<size_t>(1, inner_count));
  const double full_estimate = ac.schedule_passes * inner * cfg.anneal_seconds_per_node_pass;
  const double allotted = cfg.time_budget * cfg.anneal_budget_fraction;
  bool scaled = false;
  if (cfg.time_budget > 0.0 && full_estimate > allotted) {
    const double passes = std::floor(allotted / (inner * cfg.anneal_seconds_per_node_pass));
    const uint32_t n = static_cast<uint32_t>(std::clamp(passes, 8.0, static_cast<double>(ac.schedule_passes)));
    ac.period = std::max<uint32_t>(2, static_cast<uint32_t>(std::lround(50.0 * n / ac.schedule_passes)));
    ac.schedule_passes = n;
    scaled = true;
  }
  // A safety net only: a machine many times slower than the calibration stops here, and
  // the report shows the stop reason (then the costs are no longer machine-independent).
  if (cfg.time_budget > 0.0) ac.limits.time_limit = 4.0 * std::max(allotted, 1.0);
  schedule = {{"passes", ac.schedule_passes}, {"period", ac.period}, {"h", ac.h},
              {"scaled_by_budget", scaled}, {"paper_passes", 1250}, {"paper_period", 50},
              {"estimated_full_seconds", full_estimate}};
  return ac;
}

void run_anneal(Runner& run, const Bvh& sah, OptimizedTrees& out) {
  AnnealConfig ac = budgeted_anneal_config(run.config(), sah.inner_count(), out.det["anneal_schedule"]);
  const uint32_t total = ac.schedule_passes;
  ac.limits.on_pass = [&](const PassRecord& p) {
    run.step("annealing", 0.2 + 0.5 * std::min(1.0, double(p.pass) / total), p.pass);
  };
  Bvh tree = sah;
  const auto t0 = Clock::now();
  OptimizeReport rep = anneal(tree, ac);
  out.record("anneal", std::move(tree), rep, seconds_since(t0));
  json temps = json::array();
  for (const PassRecord& p : rep.trace) temps.push_back(p.temperature);
  out.det["traces"]["anneal_temperature"] = temps;
}

// Insertion as the paper publishes it from the SAH tree and from the spatial-median tree,
// and our hybrid form from the SAH tree.
void run_insertion(Runner& run, const Bvh& sah, const Bvh& median, OptimizedTrees& out) {
  const uint64_t seed = run.config().seed;
  for (const auto& [key, start, label, ic_made] :
       {std::tuple<const char*, const Bvh*, const char*, InsertionConfig>{"insertion_sah", &sah, "insertion (SAH)",
                                                                          bittner_paper_insertion_config(seed)},
        std::tuple<const char*, const Bvh*, const char*, InsertionConfig>{
            "insertion_median", &median, "insertion (median)", bittner_paper_insertion_config(seed)},
        std::tuple<const char*, const Bvh*, const char*, InsertionConfig>{
            "insertion_hybrid", &sah, "insertion, hybrid form (SAH)", hybrid_insertion_config(seed)}}) {
    Bvh tree = *start;
    InsertionConfig ic = ic_made;
    const std::string step_label = label;
    ic.limits.on_pass = [&](const PassRecord& p) { run.step(step_label, 0.75, p.pass); };
    const auto t0 = Clock::now();
    OptimizeReport rep = optimize_insertion(tree, ic);
    out.record(key, std::move(tree), rep, seconds_since(t0));
  }
}

json run_optimizers(Runner& run, const Mesh& mesh, const std::string& name, const fs::path& out) {
  json det, timing;
  det["triangles"] = mesh.triangle_count();
  const PrimitiveRefs refs = make_references(mesh);

  run.step("sweep SAH build", 0.02);
  BuildOptions sah_opts;
  auto t0 = Clock::now();
  const Bvh sah = build_bvh(refs, sah_opts);
  timing["build_seconds"]["sah"] = seconds_since(t0);

  run.step("spatial median build", 0.04);
  BuildOptions med_opts;
  med_opts.kind = BuilderKind::spatial_median;
  t0 = Clock::now();
  const Bvh median = build_bvh(refs, med_opts);
  timing["build_seconds"]["median"] = seconds_since(t0);

  run.step("ray sets", 0.06);
  const TableRays rays = make_table_rays(run.config(), mesh, make_tracer(sah, refs, mesh));
  for (const RaySet& s : rays.tables.sets) det["ray_counts"][std::string(ray_kind_name(s.kind))] = s.rays.size();

  json& trees = det["trees"];
  json& ttimes = timing["trees"];
  trees["sah"] = tree_det(sah);
  ttimes["sah"]["optimize_seconds"] = 0.0;
  trees["median"] = tree_det(median);
  ttimes["median"]["optimize_seconds"] = 0.0;

  OptimizedTrees optimized{det, timing, {}};
  run_hill_climb(run, sah, optimized);
  run_anneal(run, sah, optimized);
  run_insertion(run, sah, median, optimized);

  // Ray measurements of all seven trees together; heat maps of the SAH tree and the best one.
  std::string best_key = "sah";
  double best_cost = trees["sah"]["cost"].get<double>();
  std::vector<TracedTree> traced;
  const ExperimentConfig& config = run.config();
  traced.emplace_back("sah", traced_flat(sah, refs), mesh, config);
  traced.emplace_back("median", traced_flat(median, refs), mesh, config);
  for (auto& [key, tree] : optimized.trees) {
    traced.emplace_back(key, traced_flat(tree, refs), mesh, config);
    const double c = trees[key]["cost"].get<double>();
    if (c < best_cost) {
      best_cost = c;
      best_key = key;
    }
  }
  measure_trees(run, traced, rays.tables, trees, ttimes);
  run.step("heat maps", 0.98);
  det["best_tree"] = best_key;
  const std::string heat_sah = "heat_" + name + "_sah.png";
  const std::string heat_best = "heat_" + name + "_best.png";
  const Tracer* sah_tracer = nullptr;
  const Tracer* best_tracer = nullptr;
  for (const TracedTree& t : traced) {
    if (t.key == "sah") sah_tracer = &t.tracer;
    if (t.key == best_key) best_tracer = &t.tracer;
  }
  write_heatmap_pair(*sah_tracer, *best_tracer, best_key, rays.heat, mesh.name, out / heat_sah, out / heat_best);
  return json{{"det", det}, {"timing", timing}, {"images", {heat_sah, heat_best}}};
}

struct EvhTrace {
  double steps = 0.0;
  double seconds = 0.0;
  size_t references = 0;
  int effective_t = 0;
};

// Builds over `refs` (binned SAH), dedups the pieces of one triangle per leaf, traces `rays`.
EvhTrace trace_evh_tree(const Mesh& mesh, const PrimitiveRefs& refs, const RaySet& rays, const ExperimentConfig& cfg) {
  BuildOptions bo;
  bo.kind = BuilderKind::binned_sah;
  bo.leaf.max_leaf_size = kEvhLeafSize;
  Bvh bvh = build_bvh(refs, bo);
  dedup_leaf_references(bvh, refs);
  const FlatBvh flat = finalize(bvh, refs);
  const Tracer tracer(flat, mesh);
  const std::unique_ptr<WideTracer> wide = make_wide(flat, mesh, cfg);
  MeasureOptions mo;
  mo.repeats = std::max(1, cfg.repeats);
  RayMeasurement m = measure_rays(wide ? AnyTracer(*wide) : AnyTracer(tracer), rays.rays, rays.query, mo);
  EvhTrace r;
  r.steps = m.steps.mean;
  r.seconds = m.seconds;
  r.references = refs.size();
  return r;
}

// With a camera given, primary rays do not depend on the tracer (it only places default
// cameras), so the rotation frames reuse one.
RaySet evh_primary_rays(const Mesh& mesh, const ExperimentConfig& cfg, const Camera& camera, const Tracer& tracer) {
  RaySetConfig rc;
  rc.kind = RayKind::primary;
  rc.seed = cfg.seed;
  rc.count = cfg.evh_rays;
  rc.camera = camera;
  return make_ray_set(mesh, tracer, rc);
}

RaySet evh_primary_rays(const Mesh& mesh, const ExperimentConfig& cfg) {
  PrimitiveRefs refs = make_references(mesh);
  BuildOptions bo;
  bo.kind = BuilderKind::binned_sah;
  bo.leaf.max_leaf_size = kEvhLeafSize;
  Tracer tracer(finalize(build_bvh(refs, bo), refs), mesh);
  RaySetConfig rc;
  rc.kind = RayKind::primary;
  rc.seed = cfg.seed;
  rc.count = cfg.evh_rays;
  return make_ray_set(mesh, tracer, rc);
}

// DK's pose of frame 16 of 64 (half-way through the first 32 steps).
constexpr float kFrame16[3] = {45.0f, 10.0f, 15.0f};

// Dammertz-Keller Figure 4 (t against references and time) and Table 1 on one scene.
json run_evh(Runner& run, const Mesh& mesh) {
  const ExperimentConfig& cfg = run.config();
  json det, timing;
  det["triangles"] = mesh.triangle_count();
  run.step("EVH rays", 0.05);
  const RaySet rays = evh_primary_rays(mesh, cfg);
  det["rays"] = rays.rays.size();
  EvhTrace off = trace_evh_tree(mesh, make_references(mesh), rays, cfg);
  det["off"] = {{"references", off.references}, {"steps", off.steps}};
  timing["off_seconds"] = off.seconds;
  det["sweep"] = json::array();
  timing["sweep_seconds"] = json::array();
  for (size_t i = 0; i < cfg.evh_t_values.size(); ++i) {
    const int t = cfg.evh_t_values[i];
    run.step("EVH t = " + std::to_string(t), 0.1 + 0.7 * double(i) / cfg.evh_t_values.size());
    EdgeVolumeConfig ec;
    ec.t = t;
    EdgeVolumeResult sub = subdivide_edge_volume(mesh, ec);
    EvhTrace r = trace_evh_tree(mesh, sub.refs, rays, cfg);
    det["sweep"].push_back({{"t", t},
                            {"effective_t", sub.stats.effective_t},
                            {"references", r.references},
                            {"ratio", double(r.references) / double(std::max<size_t>(1, mesh.triangle_count()))},
                            {"budget_hit", sub.stats.budget_hit},
                            {"steps", r.steps}});
    timing["sweep_seconds"].push_back(r.seconds);
  }
  // Table 1 in the pose of the paper's Sponza row (frame 16): unrotated architecture has
  // axis-aligned triangles that are never split.
  run.step("EVH area reduction", 0.9);
  Mesh posed = mesh;
  rotate_mesh(posed, Vec3{kFrame16[0], kFrame16[1], kFrame16[2]});
  for (const auto& [label, m] : {std::pair<const char*, const Mesh*>{"as_loaded", &mesh},
                                 std::pair<const char*, const Mesh*>{"frame16", &posed}}) {
    EdgeVolumeConfig ec;
    AreaReduction ar = area_reduction_factors(*m, ec);
    det["area_reduction"][label] = {{"splits", ar.splits}, {"best", ar.best}, {"average", ar.average},
                                    {"worst", ar.worst}, {"references", ar.stats.references}};
  }
  return json{{"det", det}, {"timing", timing}};
}

// Dammertz-Keller Figure 5: the scene rotated in two legs of frames/2 steps each.
json run_rotation(Runner& run, const Mesh& mesh) {
  const ExperimentConfig& cfg = run.config();
  json det, timing;
  det["triangles"] = mesh.triangle_count();
  det["t"] = cfg.rotation_t;
  // One camera for all frames, the unrotated scene's default view: only the geometry moves.
  PrimitiveRefs refs0 = make_references(mesh);
  BuildOptions bo;
  bo.kind = BuilderKind::binned_sah;
  Tracer tracer0(finalize(build_bvh(refs0, bo), refs0), mesh);
  const Camera camera = default_camera(mesh, tracer0);
  det["frames"] = json::array();
  timing["frames"] = json::array();
  const uint32_t frames = cfg.rotation_frames;
  const uint32_t half = std::max<uint32_t>(1, frames / 2);
  const float a[3] = {90.0f, 20.0f, 30.0f}, b[3] = {-180.0f, 0.0f, 90.0f};
  for (uint32_t f = 1; f <= frames; ++f) {
    run.step("rotation frame " + std::to_string(f), double(f - 1) / frames);
    float angle[3];
    for (int k = 0; k < 3; ++k) {
      angle[k] = f <= half ? a[k] * float(f) / float(half)
                           : a[k] + (b[k] - a[k]) * float(f - half) / float(std::max<uint32_t>(1, frames - half));
    }
    Mesh m = mesh;
    rotate_mesh(m, Vec3{angle[0], angle[1], angle[2]});
    const RaySet rays = evh_primary_rays(m, cfg, camera, tracer0);
    EvhTrace base = trace_evh_tree(m, make_references(m), rays, cfg);
    EdgeVolumeConfig ec;
    ec.t = cfg.rotation_t;
    EdgeVolumeResult sub = subdivide_edge_volume(m, ec);
    EvhTrace evh = trace_evh_tree(m, sub.refs, rays, cfg);
    det["frames"].push_back({{"frame", f},
                             {"angles", {angle[0], angle[1], angle[2]}},
                             {"base_references", base.references},
                             {"evh_references", evh.references},
                             {"base_steps", base.steps},
                             {"evh_steps", evh.steps}});
    timing["frames"].push_back({{"base_seconds", base.seconds}, {"evh_seconds", evh.seconds}});
  }
  return json{{"det", det}, {"timing", timing}};
}

double task_weight(const Task& t, size_t triangles, const ExperimentConfig& cfg) {
  const double n = static_cast<double>(std::max<size_t>(1, triangles));
  if (t.kind == "optimizers") return 3.0 * n;
  if (t.kind == "evh") return 0.5 * n * std::max<size_t>(1, cfg.evh_t_values.size()) / 7.0;
  return 1.5 * n * cfg.rotation_frames / 64.0;
}

void check_config(const ExperimentConfig& c) {
  if (c.scenes.empty()) throw Error("experiment: no scenes (give --scenes DIR or --scene FILE)");
  if (c.shard_count == 0 || c.shard_index >= c.shard_count)
    throw Error("experiment: --shard " + std::to_string(c.shard_index + 1) + "/" + std::to_string(c.shard_count) +
                ": the shard must be I/N with 1 <= I <= N");
  if (c.rays == 0 || c.evh_rays == 0) throw Error("experiment: ray counts must be positive");
  if (c.time_budget < 0.0) throw Error("experiment: --time-budget must not be negative");
  if (c.anneal_seconds_per_node_pass <= 0.0) throw Error("experiment: anneal_seconds_per_node_pass must be positive");
  for (int t : c.evh_t_values)
    if (t < 0 || t > 40) throw Error("experiment: EVH t = " + std::to_string(t) + " out of range 0..40");
}

}  // namespace

ExperimentConfig quick_experiment_config(ExperimentConfig c) {
  c.time_budget = 10.0;
  c.rays = 20'000;
  c.evh_rays = 20'000;
  c.repeats = 1;
  c.evh_t_values = {10, 14};
  c.rotation_frames = 4;
  c.heatmap_width = 128;
  c.heatmap_height = 96;
  return c;
}

void run_experiment(const ExperimentConfig& config, const fs::path& out) {
  check_config(config);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) throw Error(out.string() + ": cannot create the output folder: " + ec.message());

  const int rotation_scene = pick_rotation_scene(config);
  const std::vector<Task> grid = make_grid(config, rotation_scene);
  std::vector<Task> mine;
  for (const Task& t : grid)
    if (t.index % config.shard_count == config.shard_index) mine.push_back(t);

  std::vector<std::string> names;
  for (const std::string& s : config.scenes) {
    std::string n = scene_short_name(s);
    std::string unique = n;
    for (int k = 2; std::find(names.begin(), names.end(), unique) != names.end(); ++k) unique = n + "_" + std::to_string(k);
    names.push_back(unique);
  }

  Runner run(config, mine.size());
  // Weights from a cheap guess (1 unit per scene until it is loaded); good enough for an ETA.
  std::vector<size_t> tri_guess(config.scenes.size(), 100'000);
  double total = 0.0;
  for (const Task& t : mine) total += task_weight(t, tri_guess[t.scene], config);
  run.set_total_weight(total);

  json results;
  results["format"] = kResultsFormat;
  results["settings"] = settings_json(config);
  results["machine"] = machine_json(config);
  results["grid"] = {{"tasks", grid.size()}, {"shard_index", config.shard_index}, {"shard_count", config.shard_count}};
  results["scene_names"] = names;
  results["plot_note"] = "";
  results["tasks"] = json::array();

  // Consecutive tasks of one scene share the loaded mesh.
  int loaded = -1;
  Mesh mesh;
  uint32_t ordinal = 0;
  for (const Task& t : mine) {
    if (static_cast<int>(t.scene) != loaded) {
      mesh = load_scene(config.scenes[t.scene]);
      loaded = static_cast<int>(t.scene);
    }
    run.begin_task(++ordinal, names[t.scene], task_weight(t, tri_guess[t.scene], config));
    auto t0 = Clock::now();
    json r;
    if (t.kind == "optimizers") r = run_optimizers(run, mesh, names[t.scene], out);
    else if (t.kind == "evh") r = run_evh(run, mesh);
    else r = run_rotation(run, mesh);
    r["index"] = t.index;
    r["kind"] = t.kind;
    r["scene"] = names[t.scene];
    r["spec"] = config.scenes[t.scene];
    r["timing"]["task_seconds"] = seconds_since(t0);
    if (!r.contains("images")) r["images"] = json::array();
    results["tasks"].push_back(std::move(r));
    run.end_task();
  }
  experiment_detail::write_text_file(out / "results.json", results.dump(1));
  experiment_detail::write_outputs(results, out, config.plot_script);
}

void merge_experiments(const std::vector<fs::path>& parts, const fs::path& out, const fs::path& plot_script) {
  if (parts.empty()) throw Error("experiment merge: no part folders given");
  json merged;
  std::vector<bool> have;
  for (const fs::path& dir : parts) {
    json part = experiment_detail::read_json_file(dir / "results.json");
    if (merged.is_null()) {
      merged = part;
      merged["tasks"] = json::array();
      have.assign(part["grid"]["tasks"].get<size_t>(), false);
    } else if (part["settings"] != merged["settings"] || part["grid"]["tasks"] != merged["grid"]["tasks"]) {
      throw Error((dir / "results.json").string() + ": settings differ from " + (parts[0] / "results.json").string() +
                  " (every part must come from the same command with a different --shard)");
    }
    for (const json& task : part["tasks"]) {
      const size_t index = task["index"].get<size_t>();
      if (index >= have.size() || have[index])
        throw Error((dir / "results.json").string() + ": task " + std::to_string(index) +
                    (index >= have.size() ? " out of range" : " already given by another part"));
      have[index] = true;
      merged["tasks"].push_back(task);
      for (const json& img : task["images"]) {
        std::error_code ec;
        fs::create_directories(out, ec);
        const fs::path from = dir / img.get<std::string>();
        const fs::path to = out / img.get<std::string>();
        if (fs::equivalent(dir, out, ec)) continue;
        fs::copy_file(from, to, fs::copy_options::overwrite_existing, ec);
        if (ec) throw Error(from.string() + ": cannot copy the heat map to " + to.string() + ": " + ec.message());
      }
    }
  }
  for (size_t i = 0; i < have.size(); ++i)
    if (!have[i])
      throw Error("experiment merge: task " + std::to_string(i) + " of " + std::to_string(have.size()) +
                  " is in none of the given folders (a shard is missing)");
  std::sort(merged["tasks"].begin(), merged["tasks"].end(),
            [](const json& a, const json& b) { return a["index"].get<size_t>() < b["index"].get<size_t>(); });
  merged["grid"]["shard_index"] = 0;
  merged["grid"]["shard_count"] = 1;
  merged["grid"]["merged_from"] = parts.size();
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec) throw Error(out.string() + ": cannot create the output folder: " + ec.message());
  experiment_detail::write_text_file(out / "results.json", merged.dump(1));
  experiment_detail::write_outputs(merged, out, plot_script);
}

std::string deterministic_results(const fs::path& results_json) {
  json r = experiment_detail::read_json_file(results_json);
  json d;
  d["settings"] = r["settings"];
  d["tasks"] = json::array();
  std::vector<json> tasks(r["tasks"].begin(), r["tasks"].end());
  std::sort(tasks.begin(), tasks.end(),
            [](const json& a, const json& b) { return a["index"].get<size_t>() < b["index"].get<size_t>(); });
  for (const json& t : tasks)
    d["tasks"].push_back({{"index", t["index"]}, {"kind", t["kind"]}, {"scene", t["scene"]}, {"det", t["det"]}});
  return d.dump(1);
}

InsertionConfig bittner_paper_insertion_config(uint64_t seed) {
  InsertionConfig ic;
  ic.seed = seed;
  ic.form = InsertionForm::sequential;
  ic.batch = 0.01;
  ic.measure = InsertionMeasure::area;
  ic.random_after = 5;
  ic.stop_after = 10;
  ic.min_improvement = 0.0;
  ic.limits.max_passes = 0;
  return ic;
}

InsertionConfig hybrid_insertion_config(uint64_t seed) {
  InsertionConfig ic;
  ic.seed = seed;
  return ic;
}

}  // namespace bvhopt
