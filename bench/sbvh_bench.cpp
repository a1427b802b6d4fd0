// Spatial-split benchmark (issue 12).
//
//   sbvh_bench [--scenes DIR] [--scene FILE]... [--runs 5] [--threads 2] [--budget 1.3]
//              [--embree-budget 1.5] [--opt-seconds S] [--no-embree] [--json FILE]
//   sbvh_bench --compare [--rotate 0,30] [--rays N] [--opt-seconds S] ...
//
// Default table, per shared scene: our SBVH build (build_spatial_split, budget --budget)
// and Embree HIGH (rtcBuildBVH with RTC_BUILD_QUALITY_HIGH, spatial splits through a
// splitPrimitive callback that cuts the triangle in float as Embree's own splitter does,
// room for --embree-budget times the references), both on --threads threads, timed
// interleaved in the same run (median of --runs, wall and process CPU time): references
// per second and per triangle, cost and ocost (counting each triangle once per leaf);
// then our tree after insertion optimization (to convergence, or --opt-seconds) and the
// ocost of bake --quality best (the lower of two starts: that tree collapsed, and the
// SBVH with SAH leaves of up to 8 optimized and collapsed), beside the best split
// peer figures (tinybvh BuildHQ + Optimize(50, extreme), or Embree HIGH; c_T = 3, c_I = 2).
//
// --compare: the edge volume heuristic beside spatial splits, per scene unrotated and
// rotated by (30, 30, 0): sweep, sweep + EVH, SBVH, SBVH + EVH, and the other starts of bake
// --quality best: SAH leaves of up to 8 from sweep and SBVH, and SBVH with spatial splits
// only in nodes of at most 256 references (their costs count those leaves), each built
// (median of --runs), optimized by insertion (--opt-seconds each, default 20) and collapsed
// into leaves as bake does (ocost); per scene, the split and the unsplit start of least
// ocost (what bake --quality best keeps, with sbvh and with sweep) side by side:
// references per triangle, cost, build time and rays per second of the collapsed tree in
// the bvh8 layout (primary and random rays made once per scene from the sweep tree, and as
// many isotropic random lines through the scene's box, the rays the SAH assumes; the same
// for all; --ray-threads threads, default 1; the trees traced in turn, pass after pass,
// median of --ray-passes passes, default 11, CPU time over the thread count, with the
// passes' interquartile range), and the work per ray that load does not change: traversal
// steps and triangle tests. --wide-block sets the bvh8 collapse's c_blk (default
// WideCostModel's), to see how the two kinds of tree fare under another cost model.
#ifdef BVHOPT_HAVE_EMBREE
#include <embree3/rtcore.h>

#include "embree_build.h"
#endif

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench_support.h"
#include "bvhopt/any_tracer.h"
#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/random_stream.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/spatial_split_builder.h"
#include "bvhopt/tracer.h"
#include "bvhopt/triangle_clipping.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/wide_bvh.h"
#include "bvhopt/wide_tracer.h"

namespace bvhopt::bench {
namespace {

// The best split peer per scene: cost with leaves of one reference, and ocost.
struct PeerFigures {
  const char* scene;  // start of the file name, lower case
  double cost, ocost;
};
constexpr PeerFigures kPeers[] = {
    {"2cylinderengine", 248.53, 219.57}, {"armadillo", 80.86, 76.82}, {"beast", 59.92, 56.53},
    {"bunny", 94.53, 89.94},             {"classroom", 13.39, 10.41}, {"conference", 92.34, 80.67},
    {"horse", 68.25, 64.93},             {"nefertiti", 104.04, 98.77}, {"ogre", 78.67, 74.48},
    {"sponza", 164.58, 142.72},          {"staircase", 42.25, 37.95},
};

const PeerFigures* peer_of(const std::string& scene) {
  std::string lower = scene;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const PeerFigures& p : kPeers)
    if (lower.rfind(p.scene, 0) == 0) return &p;
  return nullptr;
}

struct Options {
  SceneOptions scenes = SceneOptions::files_only();
  int runs = 5;
  int threads = 2;
  double budget = 1.3;
  double alpha = SpatialSplitParams{}.alpha;
  double node_alpha = SpatialSplitParams{}.node_alpha;
  uint32_t spatial_bins = SpatialSplitParams{}.spatial_bins;
  double embree_budget = 1.5;
  double opt_seconds = -1.0;  // < 0: the mode's default
  bool embree = true;
  bool compare = false;
  std::vector<float> rotations{0.0f, 30.0f};
  uint64_t rays = 200000;
  int ray_passes = 11;
  int ray_threads = 1;
  double wide_block = WideCostModel{}.block;  // the bvh8 collapse's c_blk (c_node = 1)
  std::string json_path;
  CostModel cost;
};

Options parse(int argc, char** argv) {
  Options o;
  Args args(argc, argv, "sbvh_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (read_scene_option(args, o.scenes)) continue;
    if (a == "--runs") o.runs = std::max(1, args.int_value());
    else if (a == "--threads") o.threads = std::max(1, args.int_value());
    else if (a == "--budget") o.budget = args.double_value();
    else if (a == "--alpha") o.alpha = args.double_value();
    else if (a == "--node-alpha") o.node_alpha = args.double_value();
    else if (a == "--spatial-bins") o.spatial_bins = args.u32_value();
    else if (a == "--embree-budget") o.embree_budget = args.double_value();
    else if (a == "--opt-seconds") o.opt_seconds = args.double_value();
    else if (a == "--no-embree") o.embree = false;
    else if (a == "--compare") o.compare = true;
    else if (a == "--c-t") o.cost.traversal = args.double_value();
    else if (a == "--c-i") o.cost.intersection = args.double_value();
    else if (a == "--rays") o.rays = args.u64_value();
    else if (a == "--ray-passes") o.ray_passes = std::max(1, args.int_value());
    else if (a == "--ray-threads") o.ray_threads = std::max(1, args.int_value());
    else if (a == "--wide-block") {
      o.wide_block = args.double_value();
      if (!(o.wide_block > 0.0)) throw Error("--wide-block takes a positive cost");
    }
    else if (a == "--rotate") {
      o.rotations.clear();
      for (auto& r : split_list(args.value())) o.rotations.push_back(float(parse_double(r, a)));
    } else if (a == "--json") o.json_path = args.value();
    else if (a == "--help" || a == "-h") {
      std::cout << "sbvh_bench [--scenes DIR] [--scene FILE]... [--runs 5] [--threads 2] [--budget 1.3] [--alpha 1e-5]\n"
                   "           [--node-alpha 0.1] [--spatial-bins 32]\n"
                   "           [--embree-budget 1.5] [--opt-seconds S] [--no-embree] [--json FILE]\n"
                   "sbvh_bench --compare [--rotate 0,30] [--rays N] [--ray-passes 11] [--ray-threads 1]\n"
                   "           [--opt-seconds 20] [--wide-block 0.25] ...\n";
      std::exit(0);
    } else {
      throw Error("unknown option '" + a + "' (try --help)");
    }
  }
  return o;
}

// Wall and CPU seconds of one call.
struct Timing {
  double wall = 0.0, cpu = 0.0;
};
Timing time_call(const std::function<void()>& f) {
  const double c0 = process_cpu_seconds();
  Timing t;
  t.wall = seconds_of(f);
  t.cpu = process_cpu_seconds() - c0;
  return t;
}

// A tree and what it is measured by.
struct Tree {
  Bvh bvh;
  PrimitiveRefs refs;
};

#ifdef BVHOPT_HAVE_EMBREE
// ---- Embree HIGH through rtcBuildBVH, with spatial splits.

struct EmbreeUser {
  const Mesh* mesh;
};

// The triangle cut at the plane in float, as Embree's own triangle splitter cuts it: each
// corner to its side(s), each edge crossing the plane adds its crossing point to both, and
// each side is bounded within the piece's box. (Our exact double clipping here would make
// the peer's build time mostly ours: the callback runs for every piece Embree bins.)
void embree_split(const RTCBuildPrimitive* prim, unsigned int dim, float pos, RTCBounds* left, RTCBounds* right,
                  void* user) {
  const Mesh& mesh = *static_cast<EmbreeUser*>(user)->mesh;
  const Box box(Vec3(prim->lower_x, prim->lower_y, prim->lower_z), Vec3(prim->upper_x, prim->upper_y, prim->upper_z));
  const Triangle tri = mesh.triangle(prim->primID);
  const Vec3 v[3] = {tri.v0, tri.v1, tri.v2};
  const int a = int(dim);
  Box l, r;
  for (int e = 0; e < 3; ++e) {
    const Vec3& p = v[e];
    const Vec3& q = v[e == 2 ? 0 : e + 1];
    if (p[a] <= pos) l.extend(p);
    if (p[a] >= pos) r.extend(p);
    if ((p[a] < pos && pos < q[a]) || (q[a] < pos && pos < p[a])) {
      const float t = (pos - p[a]) / (q[a] - p[a]);
      Vec3 c = p + (q - p) * t;
      c[a] = pos;
      l.extend(c);
      r.extend(c);
    }
  }
  l = intersect(l, box), r = intersect(r, box);
  // Embree expects both sides non-empty; a side rounding lost is the plane itself.
  if (l.is_empty()) l = box, l.max[dim] = pos, l.min[dim] = std::min(l.min[dim], pos);
  if (r.is_empty()) r = box, r.min[dim] = pos, r.max[dim] = std::max(r.max[dim], pos);
  *left = RTCBounds{l.min.x, l.min.y, l.min.z, 0, l.max.x, l.max.y, l.max.z, 0};
  *right = RTCBounds{r.min.x, r.min.y, r.min.z, 0, r.max.x, r.max.y, r.max.z, 0};
}

Tree convert_embree(const EmbreeNode* root) {
  Tree t;
  auto rec = [&](auto&& self, const EmbreeNode* e, uint32_t parent) -> uint32_t {
    const uint32_t me = static_cast<uint32_t>(t.bvh.nodes.size());
    t.bvh.nodes.emplace_back();
    t.bvh.nodes[me].parent = parent;
    if (e->leaf) {
      const uint32_t r = static_cast<uint32_t>(t.refs.size());
      t.refs.boxes.push_back(e->box);
      t.refs.centroids.push_back(e->box.center());
      t.refs.triangle_ids.push_back(e->prim);
      t.bvh.nodes[me].make_leaf(static_cast<uint32_t>(t.bvh.ref_indices.size()), 1);
      t.bvh.ref_indices.push_back(r);
      return me;
    }
    const uint32_t l = self(self, e->children[0], me);
    const uint32_t r = self(self, e->children[1], me);
    t.bvh.nodes[me].make_inner(l, r);
    return me;
  };
  t.bvh.root = rec(rec, root, kInvalidNode);
  t.bvh.refit(t.refs);
  return t;
}

Timing embree_high(RTCDevice device, const Mesh& mesh, const PrimitiveRefs& refs, double budget, const CostModel& cost,
                   Tree* keep) {
  const size_t capacity = std::max(refs.size(), size_t(budget * double(refs.size())));
  std::vector<RTCBuildPrimitive> prims(capacity);
  for (size_t k = 0; k < refs.size(); ++k) {
    const Box& b = refs.boxes[k];
    prims[k] = RTCBuildPrimitive{b.min.x, b.min.y, b.min.z, 0, b.max.x, b.max.y, b.max.z, refs.triangle_ids[k]};
  }
  EmbreeUser user{&mesh};
  RTCBVH ebvh = rtcNewBVH(device);
  RTCBuildArguments args = rtcDefaultBuildArguments();
  args.byteSize = sizeof(args);
  args.buildQuality = RTC_BUILD_QUALITY_HIGH;
  args.maxBranchingFactor = 2;
  args.maxLeafSize = 1;
  args.traversalCost = float(cost.traversal);
  args.intersectionCost = float(cost.intersection);
  args.bvh = ebvh;
  args.primitives = prims.data();
  args.primitiveCount = refs.size();
  args.primitiveArrayCapacity = capacity;
  set_embree_callbacks(args);
  args.splitPrimitive = embree_split;
  args.userPtr = &user;
  EmbreeNode* root = nullptr;
  const Timing t = time_call([&] { root = static_cast<EmbreeNode*>(rtcBuildBVH(&args)); });
  if (!root) {
    rtcReleaseBVH(ebvh);
    throw Error("embree: rtcBuildBVH failed");
  }
  if (keep) *keep = convert_embree(root);
  rtcReleaseBVH(ebvh);
  return t;
}
#endif

std::string scene_name(const std::string& spec) { return std::filesystem::path(spec).stem().string(); }

double ratio(double a, double b) { return b > 0.0 ? a / b : 0.0; }

// ---- The default table.

nlohmann::json run_scene(const Options& opt, const std::string& spec) {
  const CostModel cost;
  const Mesh mesh = load_scene(spec);
  const PrimitiveRefs refs = make_references(mesh);
  const std::string name = scene_name(spec);
  const double tris = double(mesh.triangle_count());
  SpatialSplitConfig config;
  config.cost = cost;
  config.budget = opt.budget;
  config.alpha = opt.alpha;
  config.node_alpha = opt.node_alpha;
  config.spatial_bins = opt.spatial_bins;

  ThreadLimit limit(opt.threads);
  std::vector<double> ours_wall, ours_cpu, peer_wall, peer_cpu;
  SpatialSplitResult ours;
  Tree peer;
  bool have_peer = false;
#ifdef BVHOPT_HAVE_EMBREE
  RTCDevice device = nullptr;
  if (opt.embree) {
    const std::string cfg = "threads=" + std::to_string(opt.threads);
    device = rtcNewDevice(cfg.c_str());
  }
#endif
  for (int run = -1; run < opt.runs; ++run) {  // run -1 warms up
    const Timing t = time_call([&] { ours = build_spatial_split(mesh, refs, config); });
    if (run >= 0) ours_wall.push_back(t.wall), ours_cpu.push_back(t.cpu);
#ifdef BVHOPT_HAVE_EMBREE
    if (device) {
      const Timing p = embree_high(device, mesh, refs, opt.embree_budget, cost, run + 1 == opt.runs ? &peer : nullptr);
      if (run >= 0) peer_wall.push_back(p.wall), peer_cpu.push_back(p.cpu);
      have_peer = true;
    }
#endif
  }
#ifdef BVHOPT_HAVE_EMBREE
  if (device) rtcReleaseDevice(device);
#endif
  const double cost_built = sah_cost(ours.bvh, ours.refs, cost);
  const double ocost_built = optimal_collapse_cost(ours.bvh, ours.refs, cost);
  InsertionConfig ic;
  ic.cost = cost;
  if (opt.opt_seconds > 0) ic.limits.time_limit = opt.opt_seconds;
  const OptimizeReport rep = optimize_insertion(ours.bvh, ic);
  const double cost_opt = sah_cost(ours.bvh, ours.refs, cost);
  // bake's collapse: leaves of at most the 64 triangles a wide leaf holds.
  const double ocost_one = optimal_collapse_cost(ours.bvh, ours.refs, cost, kWideMaxLeafTriangles);
  // bake --quality best's other starts: the SBVH's own SAH leaves of up to 8, and those with
  // spatial splits only in nodes of at most 256 references, each optimized by insertion, then
  // collapsed; best keeps the cheapest of the three collapsed trees.
  struct StartResult {
    double ocost, seconds;
  };
  const auto leafy_start = [&](uint32_t spatial_max) {
    SpatialSplitConfig leafy = config;
    leafy.leaf.max_leaf_size = 8;
    leafy.spatial_max = spatial_max;
    SpatialSplitResult tree = build_spatial_split(mesh, refs, leafy);
    const OptimizeReport rep = optimize_insertion(tree.bvh, ic);
    return StartResult{optimal_collapse_cost(tree.bvh, tree.refs, cost, kWideMaxLeafTriangles), rep.seconds};
  };
  const StartResult eight = leafy_start(0), limited = leafy_start(256);
  const double ocost_eight = eight.ocost, ocost_limited = limited.ocost;
  const double ocost_opt = std::min({ocost_one, ocost_eight, ocost_limited});

  const double wall = median(ours_wall), cpu = median(ours_cpu);
  const double pwall = median(peer_wall), pcpu = median(peer_cpu);
  const double peer_cost = have_peer ? sah_cost(peer.bvh, peer.refs, cost) : 0.0;
  const double peer_ocost = have_peer ? optimal_collapse_cost(peer.bvh, peer.refs, cost) : 0.0;
  const PeerFigures* best = peer_of(name);
  std::printf("%-18s %8.0f %6.3f %6.3f %8.1f %8.1f %6.3f %6.2f %8.2f %8.2f %6.4f %8.2f %8.2f %6.4f %8.2f %8.2f %6.4f %6.1f\n",
              name.c_str(), tris, ours.refs.size() / tris, have_peer ? peer.refs.size() / tris : 0.0, wall * 1e3,
              pwall * 1e3, ratio(wall, pwall), ratio(cpu, pcpu), cost_built, peer_cost, ratio(cost_built, peer_cost),
              cost_opt, best ? best->cost : 0.0, best ? ratio(cost_opt, best->cost) : 0.0, ocost_opt,
              best ? best->ocost : 0.0, best ? ratio(ocost_opt, best->ocost) : 0.0, rep.seconds);
  std::fflush(stdout);
  return {{"scene", name},
          {"triangles", mesh.triangle_count()},
          {"threads", opt.threads},
          {"refs_per_triangle", ours.refs.size() / tris},
          {"spatial_splits", ours.stats.spatial_splits},
          {"build_seconds", wall},
          {"build_cpu_seconds", cpu},
          {"refs_per_second", ours.refs.size() / wall},
          {"cost", cost_built},
          {"ocost", ocost_built},
          {"optimized_cost", cost_opt},
          {"optimized_ocost", ocost_one},
          {"optimize_seconds", rep.seconds},
          {"leaf8_optimized_ocost", ocost_eight},
          {"leaf8_optimize_seconds", eight.seconds},
          {"leaf8_spatial_max256_optimized_ocost", ocost_limited},
          {"leaf8_spatial_max256_optimize_seconds", limited.seconds},
          {"best_ocost", ocost_opt},
          {"embree_high",
           {{"refs_per_triangle", have_peer ? peer.refs.size() / tris : 0.0},
            {"build_seconds", pwall},
            {"build_cpu_seconds", pcpu},
            {"cost", peer_cost},
            {"ocost", peer_ocost}}},
          {"best_peer_cost", best ? best->cost : 0.0},
          {"best_peer_ocost", best ? best->ocost : 0.0}};
}

// ---- --compare: edge volume subdivision beside spatial splits.

struct Variant {
  const char* name;
  BuilderKind kind;
  bool evh;
  uint32_t leaf_size = 1;  // 8: bake --quality best's second start
  uint32_t spatial_max = 0;  // 256: its starts with spatial splits only in small nodes
};

// Isotropic random lines through the scene's box, the rays the SAH's cost model assumes: the
// probability that such a line meets a convex box inside is that box's area over the scene
// box's (Cauchy-Crofton). Drawn as a point uniform on the box's surface by area, with a
// direction cosine-distributed about the face's inward normal, unbounded. The random set
// (segments between two points of the box) is a different distribution wherever the box is
// flat: classroom's is 221 x 3.2 x 221, so its segments run almost level (the vertical part of
// their direction averages 1.4 % of its length) and weigh the trees' vertical faces.
std::vector<Ray> sah_lines(const Box& box, size_t count, uint64_t seed) {
  const Vec3 e = box.extent();
  const double face[3] = {double(e.y) * e.z, double(e.x) * e.z, double(e.x) * e.y};  // area of a face normal to x, y, z
  const double total = face[0] + face[1] + face[2];
  if (!(total > 0.0)) return {};
  std::vector<Ray> rays(count);
  RandomStream rng{seed * kGoldenGamma};
  for (Ray& r : rays) {
    double pick = rng.open_uniform() * total;
    int axis = 0;
    while (axis < 2 && pick >= face[axis]) pick -= face[axis++];
    const bool high = rng.below(2) == 1;
    float p[3] = {box.min.x + e.x * rng.uniform_float(), box.min.y + e.y * rng.uniform_float(),
                  box.min.z + e.z * rng.uniform_float()};
    const float bmin[3] = {box.min.x, box.min.y, box.min.z}, bmax[3] = {box.max.x, box.max.y, box.max.z};
    p[axis] = high ? bmax[axis] : bmin[axis];
    // Cosine-distributed about the inward normal: its component along the axis is sqrt(1 - u).
    const float u = rng.uniform_float(), phi = 2.0f * std::numbers::pi_v<float> * rng.uniform_float();
    const float along = std::sqrt(1.0f - u), across = std::sqrt(u);
    float d[3];
    d[axis] = high ? -along : along;
    d[(axis + 1) % 3] = across * std::cos(phi);
    d[(axis + 2) % 3] = across * std::sin(phi);
    r.org = Vec3(p[0], p[1], p[2]);
    r.dir = Vec3(d[0], d[1], d[2]);
    r.tmin = 0.0f;
    r.tmax = std::numeric_limits<float>::infinity();
  }
  return rays;
}

nlohmann::json compare_scene(const Options& opt, const std::string& spec, float angle) {
  const CostModel cost = opt.cost;
  Mesh mesh = load_scene(spec);
  if (angle != 0.0f) rotate_mesh(mesh, Vec3(angle, angle, 0.0f));
  const double tris = double(mesh.triangle_count());
  const std::string name = scene_name(spec) + (angle != 0.0f ? " rot" : "");
  ThreadLimit limit(opt.threads);
  // The starts of bake --quality best (with --builder sweep for the unsplit ones), and each
  // builder with edge volume subdivision first.
  const Variant variants[] = {{"sweep", BuilderKind::sweep_sah, false},
                              {"sweep-l8", BuilderKind::sweep_sah, false, 8},
                              {"sweep+evh", BuilderKind::sweep_sah, true},
                              {"sbvh", BuilderKind::spatial_split, false},
                              {"sbvh-l8", BuilderKind::spatial_split, false, 8},
                              {"sbvh-l8-m256", BuilderKind::spatial_split, false, 8, 256},
                              {"sbvh+evh", BuilderKind::spatial_split, true}};
  constexpr size_t kVariants = std::size(variants);
  // Primary, random, and the SAH's isotropic lines; the JSON fields' prefixes.
  constexpr int kSets = 3;
  const char* const set_names[kSets] = {"primary", "random", "lines"};
  std::vector<Ray> rays[kSets];
  std::vector<std::unique_ptr<WideTracer>> tracers;
  std::vector<double> ocosts;
  nlohmann::json out = nlohmann::json::array();
  for (const Variant& v : variants) {
    BuildOptions bo;
    bo.kind = v.kind;
    bo.cost = cost;
    bo.sbvh.budget = opt.budget;
    bo.sbvh.alpha = opt.alpha;
    bo.sbvh.node_alpha = opt.node_alpha;
    bo.sbvh.spatial_bins = opt.spatial_bins;
    bo.sbvh.spatial_max = v.spatial_max;
    bo.leaf.max_leaf_size = v.leaf_size;
    BuiltTree tree;
    std::vector<double> walls;
    for (int run = 0; run < opt.runs; ++run)
      walls.push_back(seconds_of([&] {
        tree = build_tree(mesh, v.evh ? subdivide_edge_volume(mesh).refs : make_references(mesh), bo);
      }));
    const double built = sah_cost(tree.bvh, tree.refs, cost);
    InsertionConfig ic;
    ic.cost = cost;
    ic.limits.time_limit = opt.opt_seconds > 0 ? opt.opt_seconds : 20.0;
    const OptimizeReport rep = optimize_insertion(tree.bvh, ic);
    const double optimized = sah_cost(tree.bvh, tree.refs, cost);
    // As bake: subtrees collapsed into leaves where cheaper, each triangle once in a leaf.
    CollapseConfig cc;
    cc.cost = cost;
    cc.max_leaf_size = kWideMaxLeafTriangles;
    const double collapsed = collapse_leaves(tree.bvh, tree.refs, cc).cost_after;
    ocosts.push_back(collapsed);
    const FlatBvh flat = finalize(tree.bvh, tree.refs);
    if (rays[0].empty()) {
      const Tracer tracer(flat, mesh);
      for (int k = 0; k < 2; ++k) {
        RaySetConfig rc;
        rc.kind = k == 0 ? RayKind::primary : RayKind::random;
        rc.count = opt.rays;
        rc.seed = 1;
        rays[k] = make_ray_set(mesh, tracer, rc).rays;
      }
      rays[2] = sah_lines(mesh_bounds(mesh), rays[1].size(), 1);
    }
    WideTracerOptions wo;
    wo.layout.collapse.width = 8;
    wo.layout.collapse.cost.block = opt.wide_block;
    tracers.push_back(std::make_unique<WideTracer>(flat, mesh, wo));
    out.push_back({{"scene", name},
                   {"variant", v.name},
                   {"refs_per_triangle", tree.refs.size() / tris},
                   {"build_seconds", median(walls)},
                   {"cost", built},
                   {"optimized_cost", optimized},
                   {"ocost", collapsed},
                   {"optimize_seconds", rep.seconds}});
  }
  // The trees are traced in turn, pass after pass (A, B, C, D, A, B, ...), so that a
  // change in the machine's load falls on all of them alike; each figure is the median of
  // its passes. On this shared VM one tree's rate moved by up to 76 % between two runs of
  // three back-to-back passes each, which flipped most split-against-unsplit verdicts.
  std::vector<double> rates[kVariants][kSets];
  double steps[kVariants][kSets], tests[kVariants][kSets];
  {
    ThreadLimit trace_limit(opt.ray_threads);
    // The work per ray, which does not depend on the machine's load: traversal steps
    // (nodes visited) and triangle tests, from one counting pass.
    for (size_t v = 0; v < kVariants; ++v)
      for (int k = 0; k < kSets; ++k) {
        const RayMeasurement m = measure_rays(AnyTracer(*tracers[v]), rays[k], RayQuery::closest, {.repeats = 1});
        steps[v][k] = m.steps.mean;
        tests[v][k] = m.triangle_tests.mean;
      }
    std::vector<Hit> hits;
    for (int pass = 0; pass < opt.ray_passes; ++pass)
      for (int k = 0; k < kSets; ++k)
        for (size_t v = 0; v < kVariants; ++v) {
          // On one thread the tracing thread's own CPU time: the process's would also count
          // the build's idle workers spinning down.
          const auto clock = opt.ray_threads == 1 ? thread_cpu_seconds : process_cpu_seconds;
          const double c0 = clock();
          trace_rays(AnyTracer(*tracers[v]), rays[k], RayQuery::closest, hits);
          const double cpu = (clock() - c0) / double(opt.ray_threads);
          rates[v][k].push_back(cpu > 0 ? double(rays[k].size()) / cpu : 0.0);
        }
  }
  for (size_t v = 0; v < kVariants; ++v) {
    nlohmann::json& row = out[v];
    double mrays[kSets];
    for (int k = 0; k < kSets; ++k) mrays[k] = median(rates[v][k]) * 1e-6;
    // The spread of the passes: a ratio between two trees is settled only when it exceeds it.
    const auto spread = [](std::vector<double> r) {
      std::sort(r.begin(), r.end());
      return r.back() > 0 ? (r[(3 * r.size()) / 4] - r[r.size() / 4]) / r[r.size() / 2] : 0.0;
    };
    for (int k = 0; k < kSets; ++k) {
      const std::string set = set_names[k];
      row[set + "_mrays"] = mrays[k];
      row[set + "_iqr_fraction"] = spread(rates[v][k]);
      row[set + "_steps_mean"] = steps[v][k];
      row[set + "_triangle_tests_mean"] = tests[v][k];
    }
    row["wide_bytes"] = tracers[v]->layout().stats().bytes;
    row["wide_blocks"] = tracers[v]->layout().stats().blocks;
    row["ray_passes"] = opt.ray_passes;
    row["ray_threads"] = opt.ray_threads;
    row["wide_sah_cost"] = tracers[v]->layout().stats().sah_cost;
    std::printf("%-22s %-12s %7.3f %9.1f %9.2f %9.2f %8.2f %6.1f %9.2f %9.2f %5.0f%% %5.0f%% %6.2f %6.2f %6.2f %6.2f %7.3f %7.1f %9.2f %5.0f%% %6.2f %6.2f\n",
                name.c_str(), variants[v].name, row["refs_per_triangle"].get<double>(),
                row["build_seconds"].get<double>() * 1e3, row["cost"].get<double>(),
                row["optimized_cost"].get<double>(), ocosts[v], row["optimize_seconds"].get<double>(), mrays[0],
                mrays[1], 100.0 * spread(rates[v][0]), 100.0 * spread(rates[v][1]), steps[v][0], tests[v][0],
                steps[v][1], tests[v][1], tracers[v]->layout().stats().sah_cost,
                double(tracers[v]->layout().stats().bytes) / (1 << 20), mrays[2], 100.0 * spread(rates[v][2]),
                steps[v][2], tests[v][2]);
  }
  // What bake --quality best keeps, with and without spatial splits: the start of the lowest
  // ocost among the sbvh ones and among the sweep ones (no EVH), and their rays side by side.
  size_t best[2] = {kVariants, kVariants};  // unsplit, split
  for (size_t v = 0; v < kVariants; ++v) {
    if (variants[v].evh) continue;
    size_t& b = best[variants[v].kind == BuilderKind::spatial_split];
    if (b == kVariants || ocosts[v] < ocosts[b]) b = v;
  }
  for (size_t v = 0; v < kVariants; ++v) {
    out[v]["best_unsplit"] = v == best[0];
    out[v]["best_split"] = v == best[1];
  }
  const auto mr = [&](size_t v, int k) { return median(rates[v][k]); };
  std::printf("%-22s best split %s (ocost %.2f) / best unsplit %s (ocost %.2f): primary %.3f, random %.3f, lines %.3f\n",
              name.c_str(), variants[best[1]].name, ocosts[best[1]], variants[best[0]].name, ocosts[best[0]],
              ratio(mr(best[1], 0), mr(best[0], 0)), ratio(mr(best[1], 1), mr(best[0], 1)),
              ratio(mr(best[1], 2), mr(best[0], 2)));
  std::fflush(stdout);
  return out;
}

int run(int argc, char** argv) {
  const Options opt = parse(argc, argv);
  nlohmann::json all = nlohmann::json::array();
  if (opt.compare) {
    std::printf("sbvh_bench --compare: %d build threads, budget %.2f, insertion %.0f s per tree, bvh8 layout; rays/s "
                "on %d thread(s) = rays over CPU time (the thread's on one) / threads, median of %d interleaved passes "
                "(iqr: interquartile range over the median); steps and triangle tests per ray\n",
                opt.threads, opt.budget, opt.opt_seconds > 0 ? opt.opt_seconds : 20.0, opt.ray_threads, opt.ray_passes);
    std::printf("%-22s %-12s %7s %9s %9s %9s %8s %6s %9s %9s %6s %6s %6s %6s %6s %6s %7s %7s %9s %6s %6s %6s\n", "scene", "variant",
                "ref/tri", "build ms", "cost", "opt cost", "ocost", "opt s", "prim Mr/s", "rand Mr/s", "p iqr", "r iqr",
                "p stp", "p tst", "r stp", "r tst", "wideSAH", "MiB", "line Mr/s", "l iqr", "l stp", "l tst");
    for (const std::string& spec : scene_specs(opt.scenes))
      for (float angle : opt.rotations)
        for (auto& row : compare_scene(opt, spec, angle)) all.push_back(row);
  } else {
    std::printf("sbvh_bench: %d threads, median of %d interleaved runs; budget ours %.2f, Embree HIGH %.2f; "
                "c_T=3 c_I=2, leaves of one; costs count each triangle once per leaf\n",
                opt.threads, opt.runs, opt.budget, opt.embree_budget);
    std::printf("%-18s %8s %6s %6s %8s %8s %6s %6s %8s %8s %6s %8s %8s %6s %8s %8s %6s %6s\n", "scene", "tris",
                "r/t", "r/t E", "ms", "ms E", "t/E", "cpu/E", "cost", "cost E", "c/E", "+ins", "best", "i/best",
                "ocost", "best oc", "o/best", "ins s");
    for (const std::string& spec : scene_specs(opt.scenes)) all.push_back(run_scene(opt, spec));
  }
  if (!opt.json_path.empty()) write_json(opt.json_path, all);
  return 0;
}

}  // namespace
}  // namespace bvhopt::bench

int main(int argc, char** argv) { return bvhopt::bench::guarded_main("sbvh_bench", [&] { return bvhopt::bench::run(argc, argv); }); }
