// bvhopt trace: trace a ray set through a BVH file and report speed and work per ray.
#include <tbb/info.h>

#include <cstdio>
#include <iostream>
#include <optional>

#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/ray_file.h"
#include "bvhopt/atomic_file.h"
#include "cli_common.h"
#include "commands.h"
#include "trace_common.h"

namespace bvhopt::cli {

namespace {

// How the text report names an any-hit order (the JSON field keeps the option's word).
std::string any_hit_order_text(const std::string& order) {
  if (order == "auto") return "far end first, slot order while the batch mostly misses";
  return order + " end first";
}

nlohmann::json distribution_json(const CountDistribution& d) {
  return {{"mean", d.mean}, {"p50", d.p50}, {"p90", d.p90}, {"p99", d.p99}, {"max", d.max},
          {"histogram_bin_width", 10}, {"histogram", d.histogram}};
}

std::string histogram_line(const CountDistribution& d) {
  // Percent of rays per 10-wide bin, the last bin open-ended.
  uint64_t total = 0;
  for (uint64_t h : d.histogram) total += h;
  std::string s;
  for (size_t i = 0; i < d.histogram.size(); ++i) {
    if (d.histogram[i] == 0) continue;
    s += "  " + std::to_string(10 * i) + (i + 1 == d.histogram.size() ? "+" : "") + ":" +
         format_double(100.0 * double(d.histogram[i]) / double(total), 1) + "%";
  }
  return s;
}

// Everything `bvhopt trace` takes; the defaults are the command's.
struct TraceOptions {
  std::string bvh_file;
  SceneOption scene;
  ThreadsOption threads;
  std::string rays = "primary";
  uint64_t count = 0;
  uint64_t seed = 1;
  bool json = false;
  std::string save_rays, load_rays, save_hits;
  std::string order = "axis";
  uint64_t check = 1000;
  int repeats = 3;
  uint32_t rays_per_call = 0;  // 0: a block of 256 rays a call
  std::string any_hit_order = "auto";
  std::string closest_hit_order = "auto";
  std::string light;  // shadow rays' point light, X,Y,Z (empty: default_light)
  std::string query;  // "closest" | "any"; empty: the ray set's own
  uint32_t width = 1024, height = 768;
  CameraOptions camera;
  LayoutOption layout;
  WideCostOption wide_cost;
};

// What one run measured, for the report.
struct TraceResults {
  RaySet set;
  std::optional<Vec3> light;  // the light of generated shadow rays
  RayMeasurement one_thread, all_threads;
  std::optional<BruteForceCheck> check;
};

// --light, checked before anything loads: the point, for generated shadow rays only.
std::optional<Vec3> asked_light(const TraceOptions& opt) {
  if (opt.light.empty()) return std::nullopt;
  if (!opt.load_rays.empty())
    throw Error("--light: the rays of --load-rays " + opt.load_rays + " are traced as saved; --light places the "
                "light of generated shadow rays (--rays shadow)");
  if (opt.rays != "shadow")
    throw Error("--light: only shadow rays have a light; " + opt.rays + " rays do not (use --rays shadow)");
  return CameraOptions::parse(opt.light, "--light");
}

// The rays of a ray file, or a generated set (saved when asked) with `asked` (asked_light)
// as its light; `light` gets the light of generated shadow rays.
RaySet trace_ray_set(const TraceOptions& opt, const Mesh& mesh, const Tracer& tracer, const std::optional<Vec3>& asked,
                     std::optional<Vec3>& light) {
  RaySet set;
  if (!opt.load_rays.empty()) {
    set = read_ray_file(opt.load_rays);
  } else {
    RaySetConfig cfg;
    cfg.kind = *parse_ray_kind(opt.rays);
    cfg.light = asked;
    cfg.seed = opt.seed;
    cfg.count = opt.count;
    cfg.width = opt.width;
    cfg.height = opt.height;
    cfg.up_axis = opt.camera.up_axis();
    cfg.camera = opt.camera.resolve(mesh, tracer, opt.width, opt.height);
    set = make_ray_set(mesh, tracer, cfg);
    if (cfg.kind == RayKind::shadow) light = cfg.light ? *cfg.light : default_light(mesh, cfg.up_axis);
  }
  // After loading too: a saved AO set can be traced as occlusion queries.
  if (!opt.query.empty()) set.query = opt.query == "any" ? RayQuery::any : RayQuery::closest;
  // Saved with the query traced, so that a peer traces the same queries from the file.
  if (!opt.save_rays.empty()) write_ray_file(opt.save_rays, set);
  if (set.rays.empty()) throw Error("trace: the ray set is empty");
  return set;
}

void print_trace_json(const TraceOptions& opt, const Mesh& mesh, const LoadedTree& tree, const TraceResults& r) {
  const RayMeasurement& m1 = r.one_thread;
  const RayMeasurement& mn = r.all_threads;
  nlohmann::json j = {{"bvh", opt.bvh_file},
                      {"scene", mesh.name},
                      {"triangles", mesh.triangle_count()},
                      {"method", tree.info.method},
                      {"rays", std::string(ray_kind_name(r.set.kind))},
                      {"query", r.set.query == RayQuery::any ? "any" : "closest"},
                      {"count", r.set.rays.size()},
                      {"seed", r.set.seed},
                      {"order", opt.order},
                      {"layout", opt.layout.name},
                      {"isa", std::string(tree.traced(parse_child_order(opt.order)).isa())},
                      {"layout_seconds", tree.layout_seconds},
                      {"wide_block_cost", opt.wide_cost.block},
                      {"hit_rate", m1.hit_rate},
                      {"rays_per_call", opt.rays_per_call},
                      {"any_hit_order", opt.any_hit_order},
                      {"closest_hit_order", opt.closest_hit_order},
                      {"threads_1", {{"seconds", m1.seconds}, {"rays_per_second", m1.rays_per_second}}},
                      {"threads_n", {{"threads", mn.threads}, {"seconds", mn.seconds},
                                     {"rays_per_second", mn.rays_per_second}}},
                      {"steps", distribution_json(m1.steps)},
                      {"triangle_tests", distribution_json(m1.triangle_tests)}};
  if (r.light) j["light"] = {r.light->x, r.light->y, r.light->z};
  if (r.check) j["brute_force"] = {{"checked", r.check->checked}, {"mismatches", r.check->mismatches},
                                   {"first_mismatch", r.check->first_mismatch}};
  print_json(j);
}

void print_trace_text(const TraceOptions& opt, const Mesh& mesh, const LoadedTree& tree, const TraceResults& r) {
  const RayMeasurement& m1 = r.one_thread;
  const RayMeasurement& mn = r.all_threads;
  std::cout << "tree       " << opt.bvh_file << " (" << tree.info.method << ")\n"
            << "layout     " << opt.layout.name << ", " << tree.traced(parse_child_order(opt.order)).isa() << " kernel"
            << (tree.wide ? ", built in " + format_double(1e3 * tree.layout_seconds, 1) + " ms (c_blk " +
                                format_double(opt.wide_cost.block, 2) + ")"
                          : std::string())
            << "\n"
            << "scene      " << mesh.name << " (" << mesh.triangle_count() << " triangles)\n"
            << "rays       " << r.set.rays.size() << " " << ray_kind_name(r.set.kind)
            << (r.set.query == RayQuery::any ? " (any hit" + std::string(tree.wide ? ", " + any_hit_order_text(opt.any_hit_order) : "") + ")"
                                             : " (closest hit)")
            << ", seed " << r.set.seed
            << (r.light ? ", light at (" + format_double(r.light->x, 4) + ", " + format_double(r.light->y, 4) + ", " +
                              format_double(r.light->z, 4) + ")"
                        : std::string())
            << "\n"
            << "hit rate   " << format_double(100.0 * m1.hit_rate, 2) << " %\n"
            << "speed      " << format_double(m1.rays_per_second / 1e6, 3) << " Mrays/s on 1 thread, "
            << format_double(mn.rays_per_second / 1e6, 3) << " on " << mn.threads << " (x"
            << format_double(mn.rays_per_second / m1.rays_per_second, 2) << "), order " << opt.order
            << (opt.rays_per_call ? ", calls of " + std::to_string(opt.rays_per_call) + " ray" +
                                        (opt.rays_per_call == 1 ? "" : "s")
                                  : std::string())
            << "\n"
            << "steps/ray  mean " << format_double(m1.steps.mean, 2) << ", p50 " << m1.steps.p50 << ", p90 "
            << m1.steps.p90 << ", p99 " << m1.steps.p99 << ", max " << m1.steps.max << "\n"
            << "           " << histogram_line(m1.steps) << "\n"
            << "tests/ray  mean " << format_double(m1.triangle_tests.mean, 2) << ", p50 "
            << m1.triangle_tests.p50 << ", p90 " << m1.triangle_tests.p90 << ", p99 " << m1.triangle_tests.p99
            << ", max " << m1.triangle_tests.max << "\n";
  if (r.check)
    std::cout << "check      " << r.check->checked << " rays against brute force: "
              << (r.check->mismatches == 0 ? std::string("all agree")
                                           : std::to_string(r.check->mismatches) + " differ; " + r.check->first_mismatch)
              << "\n";
}

// One line per ray (docs/wide-export-format.md, "Hit files"): for closest-hit rays the
// triangle id and t, u, v as hexadecimal floats (exact), or "miss"; for any-hit rays "hit" or
// "miss". Readers of exported trees write the same lines, so equal files mean equal hits.
void save_hits(const std::string& path, const AnyTracer& traced, const RaySet& set) {
  std::vector<Hit> hits(set.query == RayQuery::closest ? set.rays.size() : 0);
  std::vector<uint8_t> any(set.query == RayQuery::any ? set.rays.size() : 0);
  TraceCounters counters;
  if (set.query == RayQuery::closest)
    traced.closest(set.rays.data(), set.rays.size(), hits.data(), counters);
  else
    traced.any(set.rays.data(), set.rays.size(), any.data(), counters);
  std::string text;
  char line[128];
  for (size_t i = 0; i < set.rays.size(); ++i) {
    if (set.query == RayQuery::any) {
      text += any[i] ? "hit\n" : "miss\n";
    } else if (!hits[i].hit()) {
      text += "miss\n";
    } else {
      std::snprintf(line, sizeof line, "%u %a %a %a\n", hits[i].triangle_id, double(hits[i].t), double(hits[i].u),
                    double(hits[i].v));
      text += line;
    }
  }
  write_text_atomically(path, text);
}

// Loads the tree and the rays, times them on one thread and on all, checks a sample against
// brute force, and reports; throws Error when traversal and brute force disagree.
void run_trace(const TraceOptions& opt) {
  if (!opt.save_rays.empty()) check_output_path(opt.save_rays, "--save-rays");
  const std::optional<Vec3> light = asked_light(opt);
  auto threads = opt.threads.apply();
  ProgressLine progress;
  const SceneAndTree loaded = load_scene_and_tree(opt.scene, opt.bvh_file, progress, opt.layout.layout(),
                                                 opt.wide_cost.model(), *parse_any_hit_order(opt.any_hit_order),
                                                 *parse_closest_hit_order(opt.closest_hit_order));
  const Mesh& mesh = loaded.mesh;
  const LoadedTree& tree = loaded.tree;
  const ChildOrder order = parse_child_order(opt.order);
  const AnyTracer traced = tree.traced(order);

  progress.update("making " + opt.rays + " rays", true);
  TraceResults r;
  r.set = trace_ray_set(opt, mesh, *tree.tracer, light, r.light);
  const RaySet& set = r.set;
  if (!opt.save_hits.empty()) {
    progress.update("saving the hits of " + std::to_string(set.rays.size()) + " rays", true);
    save_hits(opt.save_hits, traced, set);
  }

  progress.update("tracing " + std::to_string(set.rays.size()) + " rays on 1 thread", true);
  MeasureOptions one;
  one.order = order;
  one.threads = 1;
  one.repeats = opt.repeats;
  one.rays_per_call = opt.rays_per_call;
  r.one_thread = measure_rays(traced, set.rays, set.query, one);
  MeasureOptions all = one;
  all.threads = opt.threads.effective();
  progress.update("tracing " + std::to_string(set.rays.size()) + " rays on " + std::to_string(all.threads) + " threads",
                  true);
  r.all_threads = measure_rays(traced, set.rays, set.query, all);
  if (opt.check > 0) {
    progress.update("checking " + std::to_string(opt.check) + " rays against brute force", true);
    r.check = check_against_brute_force(traced, mesh, set.rays, set.query, opt.check, opt.seed);
  }
  progress.finish();

  if (opt.json)
    print_trace_json(opt, mesh, tree, r);
  else
    print_trace_text(opt, mesh, tree, r);
  if (r.check && r.check->mismatches != 0)
    throw Error(opt.bvh_file + ": traversal disagrees with brute force on " + std::to_string(r.check->mismatches) +
                " of " + std::to_string(r.check->checked) + " rays (" + r.check->first_mismatch + ")");
}

}  // namespace

void register_trace_command(CLI::App& app) {
  auto opt = std::make_shared<TraceOptions>();
  CLI::App* cmd = app.add_subcommand("trace", "Trace a ray set through a BVH file: rays per second, steps, hit rate");
  cmd->add_option("bvh", opt->bvh_file, "BVH file (from bvhopt build or optimize)")->required()->type_name("FILE.bvh");
  opt->scene.add_to(cmd, "--scene", true);
  cmd->add_option("--rays", opt->rays, "Ray set: primary | random | ao | path | shadow")
      ->check(CLI::IsMember({"primary", "random", "ao", "path", "shadow"}))
      ->capture_default_str();
  cmd->add_option("--count", opt->count, "Rays (default: 1024x768 primary, 1,000,000 otherwise)")
      ->check(whole_number(1, kMaxRayCount))
      ->type_name("N");
  cmd->add_option("--seed", opt->seed, "Seed of the ray set")
      ->check(whole_number(0, UINT64_MAX))
      ->capture_default_str();
  cmd->add_option("--width", opt->width, "Camera image width")->check(CLI::Range(1u, 16384u))->capture_default_str();
  cmd->add_option("--height", opt->height, "Camera image height")->check(CLI::Range(1u, 16384u))->capture_default_str();
  cmd->add_option("--order", opt->order, "Near child first by: axis (split axis and ray sign) | distance")
      ->check(CLI::IsMember({"axis", "distance"}))
      ->capture_default_str();
  cmd->add_option("--check", opt->check, "Rays checked against brute force (0: none)")
      ->check(whole_number(0, kMaxRayCount))
      ->capture_default_str();
  cmd->add_option("--repeats", opt->repeats, "Timed passes (median reported)")->check(CLI::Range(1, 100))->capture_default_str();
  cmd->add_option("--rays-per-call", opt->rays_per_call,
                  "Time the rays traced in calls of this many (1: one ray a call, as a renderer tracing a ray at a "
                  "time; 0: blocks of 256 rays)")
      ->check(CLI::Range(size_t(0), kMaxRaysPerCall))
      ->type_name("N")
      ->capture_default_str();
  cmd->add_option("--any-hit-order", opt->any_hit_order,
                  "bvh4 / bvh8: any-hit (shadow) rays search from the ray's far end ('far'), or its near end, nearest "
                  "first as closest-hit rays ('near'), or ('auto') from the far end but in slot order while the "
                  "batch's rays mostly hit nothing (docs/wide-bvh.md, \"Any-hit rays from the far end\" and \"Rays "
                  "that mostly hit nothing\")")
      ->check(CLI::IsMember({"auto", "far", "near"}))
      ->capture_default_str();
  cmd->add_option("--closest-hit-order", opt->closest_hit_order,
                  "bvh4 / bvh8: closest-hit rays in batches enter children nearest first ('near'), or ('auto') in slot "
                  "order while the batch's rays mostly hit nothing (rays that hit nothing visit the same boxes in any "
                  "order) "
                  "(docs/wide-bvh.md, \"Rays that mostly hit nothing\")")
      ->check(CLI::IsMember({"auto", "near"}))
      ->capture_default_str();
  cmd->add_option("--light", opt->light,
                  "Shadow rays: the point light they go to (default: above the centre of the scene's box by 0.4 of its "
                  "height)")
      ->type_name("X,Y,Z");
  cmd->add_option("--query", opt->query,
                  "Trace the rays as closest-hit or any-hit (occlusion) queries (default: any for shadow rays, closest "
                  "for the others and as a ray file says; any for AO rays is what a renderer traces)")
      ->check(CLI::IsMember({"closest", "any"}));
  cmd->add_option("--save-rays", opt->save_rays, "Write the ray set to this ray file")->type_name("FILE");
  cmd->add_option("--save-hits", opt->save_hits,
                  "Write each ray's hit (triangle id and t, u, v as hex floats, or miss) to this text file")
      ->type_name("FILE");
  cmd->add_option("--load-rays", opt->load_rays, "Trace the rays of this ray file instead of generating them")
      ->type_name("FILE");
  opt->camera.add_to(cmd);
  opt->layout.add_to(cmd);
  opt->wide_cost.add_to(cmd);
  opt->threads.add_to(cmd);
  cmd->add_flag("--json", opt->json, "Print the results as JSON");
  cmd->callback([opt] { run_trace(*opt); });
}

}  // namespace bvhopt::cli
