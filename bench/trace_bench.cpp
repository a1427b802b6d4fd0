// Ray tracing benchmark (issue 6): our single-ray traversal of binary trees against Embree 3
// (its own MEDIUM-quality BVH, rtcIntersect1 / rtcOccluded1 per ray) tracing the very same
// rays in the same run, on 1 and 2 threads; the two child orders; leaf sizes 1, <=4, <=8;
// and the correlation of SAH cost with time per ray across the trees of each scene.
//
//   trace_bench [--scenes DIR] [--scene FILE]... [--count N] [--repeats R]
//               [--kinds primary,random,ao] [--query closest|any] [--optimizers] [--quick] [--opt-seconds S]
//               [--best-seconds S] [--best-leaf N] [--json FILE]
//               [--no-wide] [--wide-variants] [--fit-costs] [--baked DIR]
//
// The row "best" is the tree a user would trace: sweep SAH, insertion optimization for
// --best-seconds (default 10), compaction into leaves of up to --best-leaf (default 8) with
// the default c_T/c_I. --quick keeps only sweep-l1 and best.
//
// With --baked DIR, the row "baked" is the tree in DIR/<scene name without extension>.bvh,
// as `bvhopt bake SCENE --quality best -o` wrote it: our best tree once spatial splits are
// allowed (the best of several optimized starts, split or not; docs/spatial-splits.md).
// It is traced with the references stored in the file. Scenes without a file get no row.
//
// Wide rows (unless --no-wide): the best tree (and the baked one) and the sweep-l1 tree collapsed SAH-optimally
// into bvh8 and bvh4 and traced by the wide tracer (the ISA default_isa() picks), the best
// bvh8 also on 2 threads, beside Embree MEDIUM and HIGH. --wide-variants adds the best bvh8
// with the other choices: distance-sorted children, the watertight triangle test, the greedy
// collapse, any-hit rays nearest first ("anynear"; shadow rays), the collapse with c_blk =
// 0.5, 0.7, 1 and 1.5 (c_node = 1; to recalibrate the default 1 : 0.25 on another CPU;
// --block-costs C,... traces those c_blk instead, and without --wide-variants only those),
// every ISA the CPU has, and 1 and 2 rays traced side by side; it and --closest-near add the
// best and baked bvh8 with closest-hit rays always nearest first ("bvh8-near", against the
// default ClosestHitOrder::adaptive); --any-far adds them with any-hit rays always from the
// far end ("bvh8-far", against the default AnyHitOrder::adaptive). --fit-costs prints, per row, the wide tracer's nodes and blocks per ray beside its
// ns/ray, the data the wide cost model is calibrated from. The run ends with each wide
// tree's geometric mean ratio to Embree MEDIUM over every scene and ray set, per ray set
// too, and the number of pairs where it is at least 1.
//
// --query traces every set as that query (Embree with rtcIntersect1 or rtcOccluded1 to match);
// a set so changed is named with the query ("ao-any": AO rays as a renderer's occlusion
// queries). Without it each set keeps its own: any hit for shadow rays, closest for the rest.
//
// --batch-sizes N,... adds the first bvh8 row (best-bvh8) traced on 1 thread in calls of N rays
// each, one call after the other on the calling thread: what a renderer that traces a tile
// or a packet at a time gets (the other rows trace each oneTBB chunk, thousands of rays, in
// one call); 1 is one call per ray.
//
// Every figure is the median of R timed passes; the candidates are timed round-robin within
// each repeat so machine load drifts alike over all of them. Ratios are ours / Embree's.
// 1-thread figures use the calling thread's CPU time (all the work runs there when oneTBB
// allows one thread), so a shared machine does not skew them; --wall uses wall time.
// 2-thread figures are the process's CPU time over 2 (the wall time if each thread had its
// own core), so 2t/1t measures parallel efficiency; --wall gives true wall times, which
// mean something only on an otherwise idle machine.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#ifdef BVHOPT_HAVE_EMBREE
#include <embree3/rtcore.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "bench_support.h"

#include "bvhopt/build.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/wide_tracer.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;
using namespace bench;

struct Options {
  SceneOptions scene_options = SceneOptions::files_only();
  std::vector<std::string> scenes;  // the files to run, from scene_options
  uint64_t count = 1'000'000;
  int repeats = 5;
  std::vector<RayKind> kinds{RayKind::primary, RayKind::random, RayKind::ao};
  std::optional<RayQuery> query;  // --query: every set traced as this query
  bool optimizers = false;
  bool quick = false;
  bool wall = false;   // 1-thread figures from wall time instead of thread CPU time  // only the leaf-1 sweep tree (for A/B runs while tuning)
  double opt_seconds = 10.0;
  // "best": the tree a user would trace (sweep SAH -> insertion optimization for
  // best_seconds -> compaction into leaves of up to best_leaf); 0 seconds drops the row.
  double best_seconds = 10.0;
  uint32_t best_leaf = 8;
  std::string json_path;
  bool wide = true;
  bool wide_variants = false;
  // c_blk values (c_node = 1) whose collapses of the best tree are traced beside the default:
  // --block-costs, or --wide-variants' 0.5, 0.7, 1 and 1.5.
  std::vector<double> block_costs;
  bool fit_costs = false;
  // --closest-near: the best and baked bvh8 also with closest-hit rays always nearest first
  // (ClosestHitOrder::near_first), traced in the same passes as the default's adaptive order.
  bool closest_near = false;
  // --any-far: the same with any-hit rays always from their far end (AnyHitOrder::far_first).
  bool any_far = false;
  std::string baked_dir;  // empty: no "baked" row
  std::vector<uint32_t> batch_sizes;  // --batch-sizes: best-bvh8 traced in calls of these many rays
};

Options parse(int argc, char** argv) {
  Options o;
  Args args(argc, argv, "trace_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (read_scene_option(args, o.scene_options)) continue;
    if (a == "--count") o.count = args.u64_value();
    else if (a == "--repeats") o.repeats = std::max(1, args.int_value());
    else if (a == "--json") o.json_path = args.value();
    else if (a == "--optimizers") o.optimizers = true;
    else if (a == "--quick") o.quick = true;
    else if (a == "--no-wide") o.wide = false;
    else if (a == "--wide-variants") o.wide_variants = true;
    else if (a == "--block-costs") o.block_costs = parse_positive_list(args.value(), a);
    else if (a == "--fit-costs") o.fit_costs = true;
    else if (a == "--closest-near") o.closest_near = true;
    else if (a == "--any-far") o.any_far = true;
    else if (a == "--wall") o.wall = true;
    else if (a == "--opt-seconds") o.opt_seconds = args.double_value();
    else if (a == "--best-seconds") o.best_seconds = args.double_value();
    else if (a == "--best-leaf") o.best_leaf = args.u32_value();
    else if (a == "--baked") o.baked_dir = args.value();
    else if (a == "--batch-sizes") {
      for (double v : parse_positive_list(args.value(), a)) {
        if (v != std::floor(v) || v > 1e9) throw Error("--batch-sizes: " + std::to_string(v) + " is not a whole number of rays");
        o.batch_sizes.push_back(uint32_t(v));
      }
    }
    else if (a == "--kinds") {
      o.kinds.clear();
      for (const std::string& k : split_list(args.value())) {
        auto kind = parse_ray_kind(k);
        if (!kind) throw Error("unknown ray kind '" + k + "'");
        o.kinds.push_back(*kind);
      }
    } else if (a == "--query") {
      const std::string q = args.value();
      if (q != "closest" && q != "any") throw Error("--query: '" + q + "' is not closest or any");
      o.query = q == "any" ? RayQuery::any : RayQuery::closest;
    } else if (a == "--help" || a == "-h") {
      std::cout << "trace_bench [--scenes DIR] [--scene FILE]... [--count N] [--repeats R]\n"
                   "            [--kinds primary,random,ao,path,shadow] [--query closest|any] [--optimizers] [--opt-seconds S]\n"
                   "            [--quick] [--wall]   (only the leaf-1 sweep tree and best)\n"
                   "            [--best-seconds S] [--best-leaf N]   (the 'best' row; S = 0 drops it)\n"
                   "            [--json FILE] [--no-wide] [--wide-variants] [--block-costs 0.25,0.35] [--fit-costs]\n"
                   "            [--baked DIR]   (the 'baked' row: DIR/<scene>.bvh from bvhopt bake --quality best)\n"
                   "            [--closest-near]   (best and baked bvh8 also with closest-hit rays always nearest first)\n"
                   "            [--any-far]   (best and baked bvh8 also with any-hit rays always from the far end)\n"
                   "            [--batch-sizes 1,16,256]   (best-bvh8 on 1 thread in calls of that many rays)\n";
      std::exit(0);
    } else {
      throw Error("unknown option '" + a + "'");
    }
  }
  o.scenes = scene_specs(o.scene_options);
  return o;
}

// CPU time of the calling thread. With one thread allowed, oneTBB runs the whole
// parallel_for on the calling thread, so this is the work of the trace alone, robust to the
// machine being shared (wall time counts the time other processes hold the core).
double thread_cpu_seconds_of(const std::function<void()>& f) {
  const double a = thread_cpu_seconds();
  f();
  return thread_cpu_seconds() - a;
}

// For a pass on T threads: the process's CPU time over T, i.e. the wall time the pass would
// take if each of its threads had a core to itself. On a shared machine wall time measures
// the other processes; this measures our parallel work, overheads included (idle workers
// spinning count against us).
double process_cpu_seconds_of(const std::function<void()>& f, int threads) {
  const double a = process_cpu_seconds();
  f();
  return (process_cpu_seconds() - a) / threads;
}

double pearson(const std::vector<double>& x, const std::vector<double>& y) {
  const size_t n = x.size();
  if (n < 3) return std::nan("");
  double mx = 0, my = 0;
  for (size_t i = 0; i < n; ++i) mx += x[i], my += y[i];
  mx /= double(n);
  my /= double(n);
  double sxy = 0, sxx = 0, syy = 0;
  for (size_t i = 0; i < n; ++i) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
    syy += (y[i] - my) * (y[i] - my);
  }
  return sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : std::nan("");
}

// Views for shared scenes the default camera rule frames badly: classroom.obj sits in
// a 220 x 220 ground plane, so the default exterior camera sees a speck. Others use
// default_camera.
std::optional<Camera> bench_view(const std::string& scene) {
  if (scene == "classroom.obj") {
    Camera c;
    c.position = Vec3(3.5f, 1.6f, 3.5f);  // inside the room, by the back wall
    c.target = Vec3(-2.0f, 1.0f, -3.0f);
    return c;
  }
  return std::nullopt;
}

#ifdef BVHOPT_HAVE_EMBREE
struct EmbreeScene {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  double build_seconds = 0.0;

  explicit EmbreeScene(const Mesh& mesh, RTCBuildQuality quality = RTC_BUILD_QUALITY_MEDIUM) {
    device = rtcNewDevice("threads=1");
    if (!device) throw Error("embree: rtcNewDevice failed");
    build_seconds = seconds_of([&] {
      scene = rtcNewScene(device);
      rtcSetSceneBuildQuality(scene, quality);
      RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
      auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                             3 * sizeof(float), mesh.vertex_count()));
      auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                3 * sizeof(unsigned), mesh.triangle_count()));
      std::copy(mesh.positions.begin(), mesh.positions.end(), vb);
      std::copy(mesh.indices.begin(), mesh.indices.end(), ib);
      rtcCommitGeometry(g);
      rtcAttachGeometry(scene, g);
      rtcReleaseGeometry(g);
      rtcCommitScene(scene);
    });
  }
  ~EmbreeScene() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void trace(const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits) const {
    hits.resize(rays.size());
    const Ray* in = rays.data();
    Hit* out = hits.data();
    RTCScene sc = scene;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), 256), [=](const tbb::blocked_range<size_t>& r) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const Ray& ray = in[i];
        if (query == RayQuery::closest) {
          RTCRayHit rh;
          rh.ray.org_x = ray.org.x;
          rh.ray.org_y = ray.org.y;
          rh.ray.org_z = ray.org.z;
          rh.ray.tnear = ray.tmin;
          rh.ray.dir_x = ray.dir.x;
          rh.ray.dir_y = ray.dir.y;
          rh.ray.dir_z = ray.dir.z;
          rh.ray.time = 0.0f;
          rh.ray.tfar = ray.tmax;
          rh.ray.mask = 0xffffffffu;
          rh.ray.id = 0;
          rh.ray.flags = 0;
          rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
          rtcIntersect1(sc, &ctx, &rh);
          Hit h;
          if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
            h.t = rh.ray.tfar;
            h.u = rh.hit.u;
            h.v = rh.hit.v;
            h.triangle_id = rh.hit.primID;
          }
          out[i] = h;
        } else {
          RTCRay rr;
          rr.org_x = ray.org.x;
          rr.org_y = ray.org.y;
          rr.org_z = ray.org.z;
          rr.tnear = ray.tmin;
          rr.dir_x = ray.dir.x;
          rr.dir_y = ray.dir.y;
          rr.dir_z = ray.dir.z;
          rr.time = 0.0f;
          rr.tfar = ray.tmax;
          rr.mask = 0xffffffffu;
          rr.id = 0;
          rr.flags = 0;
          rtcOccluded1(sc, &ctx, &rr);
          Hit h;
          if (rr.tfar < 0.0f) h.triangle_id = 0;
          out[i] = h;
        }
      }
    });
  }
};
#endif

struct Tree {
  std::string name;
  double sah = 0.0;
  double seconds = 0.0;  // build (+ optimize) time
  std::unique_ptr<Tracer> tracer;
  FlatBvh flat;
};

// A tree in a wide layout, as the wide rows trace it.
struct WideTree {
  std::string name;  // e.g. best-bvh8
  const Tree* from;
  std::unique_ptr<WideTracer> tracer;
  double layout_seconds = 0.0;  // collapse + layout
};

void trace_wide(const WideTracer& w, const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits) {
  hits.resize(rays.size());
  constexpr size_t kBlock = 256;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), kBlock), [&](const tbb::blocked_range<size_t>& r) {
    TraceCounters c;
    if (query == RayQuery::closest) {
      w.closest(rays.data() + r.begin(), r.size(), hits.data() + r.begin(), c);
      return;
    }
    uint8_t any[kBlock];
    for (size_t b = r.begin(); b < r.end(); b += kBlock) {
      const size_t n = std::min(kBlock, r.end() - b);
      w.any(rays.data() + b, n, any, c);
      for (size_t i = 0; i < n; ++i) hits[b + i] = any[i] ? Hit{0.0f, 0.0f, 0.0f, 0} : Hit{};
    }
  });
}

// The rays traced in calls of `batch` rays each, one after the other on the calling thread.
void trace_wide_calls(const WideTracer& w, const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits,
                      size_t batch) {
  hits.resize(rays.size());
  TraceCounters c;
  std::vector<uint8_t> any(query == RayQuery::closest ? 0 : batch);
  for (size_t b = 0; b < rays.size(); b += batch) {
    const size_t n = std::min(batch, rays.size() - b);
    if (query == RayQuery::closest) {
      w.closest(rays.data() + b, n, hits.data() + b, c);
    } else {
      w.any(rays.data() + b, n, any.data(), c);
      for (size_t i = 0; i < n; ++i) hits[b + i] = any[i] ? Hit{0.0f, 0.0f, 0.0f, 0} : Hit{};
    }
  }
}

// Bytes per triangle of the binary trace layout (a 64-byte TraceNode per inner node, 36 bytes of
// vertices and a 4-byte id per leaf entry).
double binary_bytes_per_triangle(const Tracer& t, const FlatBvh& flat) {
  return (64.0 * double(t.node_count()) + 40.0 * double(flat.triangle_ids.size())) / double(t.triangle_count());
}

// Fraction of rays on which two tracers agree: both miss, or both hit at distances within
// 1e-4 relative (different triangles at one distance are a tie, not a disagreement).
double agreement(const std::vector<Hit>& a, const std::vector<Hit>& b, RayQuery query) {
  size_t same = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].hit() != b[i].hit()) continue;
    if (!a[i].hit() || query == RayQuery::any ||
        std::fabs(a[i].t - b[i].t) <= 1e-4f * std::max(std::fabs(a[i].t), 1e-6f))
      ++same;
  }
  return a.empty() ? 1.0 : double(same) / double(a.size());
}

// The wide rows' tracers: bvh8 and bvh4 of the best and the sweep-l1 trees, and with
// `variants` the other choices for the best bvh8.
std::vector<WideTree> wide_trees(const std::vector<Tree>& trees, const Mesh& mesh, bool variants,
                                 std::vector<double> block_costs, bool closest_near, bool any_far) {
  std::vector<WideTree> out;
  auto add = [&](const Tree& t, const std::string& suffix, WideTracerOptions o) {
    WideTree w;
    w.name = t.name + "-" + suffix;
    w.from = &t;
    w.layout_seconds = seconds_of([&] { w.tracer = std::make_unique<WideTracer>(t.flat, mesh, o); });
    out.push_back(std::move(w));
  };
  for (const char* name : {"best", "baked", "sweep-l1"}) {
    for (const Tree& t : trees) {
      if (t.name != name) continue;
      for (uint32_t width : {8u, 4u}) {
        WideTracerOptions o;
        o.layout.collapse.width = width;
        add(t, "bvh" + std::to_string(width), o);
      }
      if ((closest_near || variants) && t.name != std::string("sweep-l1")) {
        WideTracerOptions o;
        o.closest_hit_order = ClosestHitOrder::near_first;
        add(t, "bvh8-near", o);
      }
      if (any_far && t.name != std::string("sweep-l1")) {
        WideTracerOptions o;
        o.any_hit_order = AnyHitOrder::far_first;
        add(t, "bvh8-far", o);
      }
      if (t.name != "best") continue;
      if (variants && block_costs.empty()) block_costs = {0.5, 0.7, 1.0, 1.5};
      // The collapse's cost ratio, to calibrate c_blk : c_node on this CPU (c_node = 1; the
      // default c_blk is WideCostModel's, 0.25).
      for (double block : block_costs) {
        WideTracerOptions o;
        o.layout.collapse.cost.block = block;
        char suffix[32];
        std::snprintf(suffix, sizeof suffix, "bvh8-blk%.*f", block == std::round(block * 10) / 10 ? 1 : 2, block);
        add(t, suffix, o);
      }
      if (!variants) continue;
      WideTracerOptions o;
      o.near_first = NearFirst::distance_sort;
      add(t, "bvh8-sorted", o);
      o = {};
      o.layout.test = TriangleTest::watertight;
      add(t, "bvh8-watertight", o);
      o = {};
      o.layout.collapse.method = CollapseMethod::greedy;
      add(t, "bvh8-greedy", o);
      // Any-hit (shadow) rays nearest first, as closest-hit rays: the default walks from
      // their far end (AnyHitOrder).
      o = {};
      o.any_hit_order = AnyHitOrder::near_first;
      add(t, "bvh8-anynear", o);
      for (Isa isa : {Isa::sse42, Isa::avx2, Isa::avx512}) {
        if (!isa_supported(isa)) continue;
        o = {};
        o.isa = isa;
        add(t, "bvh8-" + std::string(isa_name(isa)), o);
      }
      // Rays traced one after the other and 2, 4 or 8 side by side (the default is 16 on
      // scattered batches; the same on the others).
      for (uint32_t lanes : {1u, 2u, 4u, 8u}) {
        o = {};
        o.lanes = lanes;
        add(t, "bvh8-lanes" + std::to_string(lanes), o);
      }
    }
  }
  return out;
}

template <class Mrays>
nlohmann::json wide_rows(const std::vector<WideTree>& wide, const std::vector<Ray>& rays, RayQuery query,
                         const Mrays& mrays, double embree_1t, bool fit_costs) {
  nlohmann::json rows = nlohmann::json::array();
  for (const WideTree& w : wide) {
    const double mr = mrays(w.name);
    const WideLayoutStats& st = w.tracer->layout().stats();
    // The work of the query timed: any-hit rays stop at their first hit.
    TraceCounters c;
    if (query == RayQuery::any) {
      std::vector<uint8_t> blocked(rays.size());
      w.tracer->any(rays.data(), rays.size(), blocked.data(), c);
    } else {
      std::vector<Hit> hits(rays.size());
      w.tracer->closest(rays.data(), rays.size(), hits.data(), c);
    }
    const double steps = double(c.steps) / double(rays.size()), blocks = double(c.triangle_tests) / 4.0 / double(rays.size());
    std::printf("%-8s %8s %6s | %-16s %7.2f %7s %7s | %7.2f   (wide SAH %.2f, steps %.1f, blocks %.1f%s)\n", "", "", "",
                w.name.c_str(), mr, "", "", embree_1t > 0 ? mr / embree_1t : 0.0, st.sah_cost, steps, blocks,
                fit_costs ? (", ns/ray " + std::to_string(1e3 / mr)).c_str() : "");
    rows.push_back({{"tree", w.name}, {"isa", std::string(isa_name(w.tracer->isa()))}, {"wide_sah", st.sah_cost},
                    {"bytes", st.bytes}, {"layout_seconds", w.layout_seconds}, {"mrays_1t", mr},
                    {"ratio_1t", embree_1t > 0 ? mr / embree_1t : 0.0}, {"steps_mean", steps}, {"blocks_mean", blocks},
                    {"query", query == RayQuery::any ? "any" : "closest"}});
  }
  return rows;
}

// The summary of the wide rows over every scene and ray set of the run: per tree
// (best-bvh8, baked-bvh8, ...), the geometric mean of its ratio to Embree MEDIUM, per ray set
// and over all, and on how many pairs it is at least 1.
void print_wide_summary(const nlohmann::json& rows) {
  struct Tally {
    double log_sum = 0.0;
    size_t pairs = 0, at_least_one = 0;
    std::vector<std::pair<std::string, std::pair<double, size_t>>> per_kind;  // kind -> (log sum, pairs)
  };
  std::vector<std::pair<std::string, Tally>> trees;  // in the order first met
  for (const auto& row : rows) {
    if (!row.contains("wide")) continue;
    const std::string kind = row["rays"];
    for (const auto& w : row["wide"]) {
      const double ratio = w["ratio_1t"];
      if (ratio <= 0.0) continue;  // no Embree figure
      const std::string name = w["tree"];
      auto it = std::find_if(trees.begin(), trees.end(), [&](const auto& t) { return t.first == name; });
      if (it == trees.end()) it = trees.insert(trees.end(), {name, Tally{}});
      Tally& t = it->second;
      t.log_sum += std::log(ratio);
      ++t.pairs;
      t.at_least_one += ratio >= 1.0;
      auto k = std::find_if(t.per_kind.begin(), t.per_kind.end(), [&](const auto& e) { return e.first == kind; });
      if (k == t.per_kind.end()) k = t.per_kind.insert(t.per_kind.end(), {kind, {0.0, 0}});
      k->second.first += std::log(ratio);
      ++k->second.second;
    }
  }
  if (trees.empty()) return;
  std::printf("\n## Wide trees against Embree MEDIUM over the run (1 thread): geometric mean of the ratio\n");
  for (const auto& [name, t] : trees) {
    std::printf("%-20s %.3f over %zu pairs (", name.c_str(), std::exp(t.log_sum / double(t.pairs)), t.pairs);
    for (size_t i = 0; i < t.per_kind.size(); ++i)
      std::printf("%s%s %.3f", i ? ", " : "", t.per_kind[i].first.c_str(),
                  std::exp(t.per_kind[i].second.first / double(t.per_kind[i].second.second)));
    std::printf("); at least 1 on %zu\n", t.at_least_one);
  }
}

int run(const Options& opt) {
  using nlohmann::json;
  json out = json::array();
  std::printf("# trace_bench: %u hardware threads; Mrays/s = median of %d passes; ratio = ours / Embree\n",
              std::thread::hardware_concurrency(), opt.repeats);
#ifndef BVHOPT_HAVE_EMBREE
  std::printf("# Embree not found at configure time: no peer figures\n");
#endif
  for (const std::string& scene_path : opt.scenes) {
    Mesh mesh;
    try {
      mesh = load_mesh_file(scene_path);
    } catch (const Error& e) {
      std::fprintf(stderr, "skipping %s: %s\n", scene_path.c_str(), e.what());
      continue;
    }
    const std::string scene = fs::path(scene_path).filename().string();
    const PrimitiveRefs refs = make_references(mesh);

    std::vector<Tree> trees;
    auto add_tree = [&](const std::string& name, Bvh bvh, double secs, const PrimitiveRefs* own_refs = nullptr) {
      Tree t;
      t.name = name;
      t.sah = sah_cost(bvh);
      t.seconds = secs;
      t.flat = finalize(bvh, own_refs ? *own_refs : refs);
      t.tracer = std::make_unique<Tracer>(t.flat, mesh);
      trees.push_back(std::move(t));
    };
    Bvh sweep1;
    for (uint32_t leaf : {1u, 4u, 8u}) {
      BuildOptions b;
      b.leaf.max_leaf_size = leaf;
      Bvh bvh;
      const double s = seconds_of([&] { bvh = build_bvh(refs, b); });
      if (leaf == 1) sweep1 = bvh;
      if (opt.quick && leaf != 1) continue;
      add_tree("sweep-l" + std::to_string(leaf), std::move(bvh), s);
    }
    for (BuilderKind k : {BuilderKind::binned_sah, BuilderKind::spatial_median, BuilderKind::object_median}) {
      if (opt.quick) break;
      BuildOptions b;
      b.kind = k;
      Bvh bvh;
      const double s = seconds_of([&] { bvh = build_bvh(refs, b); });
      add_tree(std::string(builder_name(k)) + "-l1", std::move(bvh), s);
    }
    if (opt.best_seconds > 0) {
      Bvh bvh = sweep1;
      const double s = seconds_of([&] {
        InsertionConfig c;
        c.limits.time_limit = opt.best_seconds;
        optimize_insertion(bvh, c);
        CollapseConfig cc;
        cc.max_leaf_size = opt.best_leaf;
        collapse_leaves(bvh, cc);
      });
      add_tree("best", std::move(bvh), s);
    }
    if (!opt.baked_dir.empty()) {
      const fs::path file = fs::path(opt.baked_dir) / (fs::path(scene_path).stem().string() + ".bvh");
      if (fs::exists(file)) {
        try {
          BvhFile baked = read_bvh_file(file);
          check_tree_matches_scene(file.string(), baked.info, mesh);
          add_tree("baked", std::move(baked.bvh), 0.0, &baked.refs);
          std::printf("# baked: %s (%s)\n", file.string().c_str(), baked.info.method.c_str());
        } catch (const Error& e) {
          // A stale or damaged file costs its row, not the run.
          std::fprintf(stderr, "trace_bench: no baked row for %s: %s\n", scene.c_str(), e.what());
        }
      } else {
        std::printf("# baked: no %s\n", file.string().c_str());
      }
    }
    if (opt.optimizers) {
      {
        Bvh bvh = sweep1;
        HillClimbConfig c;
        c.limits.time_limit = opt.opt_seconds;
        const double s = seconds_of([&] { hill_climb(bvh, c); });
        add_tree("sweep+hill", std::move(bvh), s);
      }
      {
        Bvh bvh = sweep1;
        AnnealConfig c;
        c.limits.time_limit = opt.opt_seconds;
        const double s = seconds_of([&] { anneal(bvh, c); });
        add_tree("sweep+anneal", std::move(bvh), s);
      }
      {
        Bvh bvh = sweep1;
        InsertionConfig c;
        c.limits.time_limit = opt.opt_seconds;
        const double s = seconds_of([&] { optimize_insertion(bvh, c); });
        add_tree("sweep+insertion", std::move(bvh), s);
      }
    }
#ifdef BVHOPT_HAVE_EMBREE
    const EmbreeScene embree(mesh);
    const EmbreeScene embree_high(mesh, RTC_BUILD_QUALITY_HIGH);
#endif
    std::printf("\n## %s: %zu triangles\n", scene.c_str(), mesh.triangle_count());
    std::vector<WideTree> wide;
    if (opt.wide) wide = wide_trees(trees, mesh, opt.wide_variants, opt.block_costs, opt.closest_near, opt.any_far);
    for (const WideTree& w : wide) {
      const WideLayoutStats& st = w.tracer->layout().stats();
      // One cold run, the tracer's construction included; layout_bench times the target
      // figure (collapse + layout against the sweep build, median of several rounds).
      std::printf("# %-22s wide SAH %.3f, %.1f B/triangle (binary %.1f), collapse+layout %.1f ms = %.1f%% of the "
                  "sweep build (once, cold; see layout_bench), isa %s\n",
                  w.name.c_str(), st.sah_cost, double(st.bytes) / double(mesh.triangle_count()),
                  binary_bytes_per_triangle(*w.from->tracer, w.from->flat), 1e3 * w.layout_seconds,
                  100.0 * w.layout_seconds / trees[0].seconds, std::string(isa_name(w.tracer->isa())).c_str());
    }
    std::printf("%-8s %8s %6s | %-16s %7s %7s %7s | %7s %7s %7s %7s | %6s %6s | %6s\n", "rays", "count", "hit%",
                "tree", "1t", "dist1t", "embr1t", "ratio1", "2t", "embr2t", "ratio2", "2t/1t", "steps", "agree");
    for (RayKind kind : opt.kinds) {
      RaySetConfig cfg;
      cfg.kind = kind;
      cfg.seed = 1;
      cfg.count = kind == RayKind::primary ? 0 : opt.count;  // primary: 1024 x 768
      cfg.camera = bench_view(scene);
      cfg.query = opt.query;
      // A scene may have no rays of a kind (shadow rays start only at lit hits; nefertiti's
      // default light lights almost none): that set is skipped, the run goes on.
      RaySet set;
      try {
        set = make_ray_set(mesh, *trees[0].tracer, cfg);
      } catch (const Error& e) {
        std::printf("%-8s skipped: %s\n", std::string(ray_kind_name(kind)).c_str(), e.what());
        std::fflush(stdout);
        continue;
      }
      const std::vector<Ray>& rays = set.rays;
      const std::string set_name =
          std::string(ray_kind_name(kind)) +
          (set.query == default_query(kind) ? "" : set.query == RayQuery::any ? "-any" : "-closest");

      // Candidates: each tree with the default (split-axis) order on 1 thread; the first tree
      // also with the distance order and on 2 threads; Embree on 1 and 2 threads.
      struct Candidate {
        std::string label;
        int threads;
        std::function<void(std::vector<Hit>&)> trace;
        std::vector<double> times;
      };
      std::vector<Candidate> cands;
      for (size_t t = 0; t < trees.size(); ++t) {
        const Tracer* tr = trees[t].tracer.get();
        cands.push_back({trees[t].name, 1, [=, &rays, &set](std::vector<Hit>& h) {
                           trace_rays(*tr, rays, set.query, h, nullptr, ChildOrder::split_axis);
                         }, {}});
      }
      const Tracer* base = trees[0].tracer.get();
      cands.push_back({"dist", 1, [=, &rays, &set](std::vector<Hit>& h) {
                         trace_rays(*base, rays, set.query, h, nullptr, ChildOrder::distance);
                       }, {}});
      cands.push_back({"ours2", 2, [=, &rays, &set](std::vector<Hit>& h) {
                         trace_rays(*base, rays, set.query, h, nullptr, ChildOrder::split_axis);
                       }, {}});
#ifdef BVHOPT_HAVE_EMBREE
      for (int th : {1, 2})
        cands.push_back({th == 1 ? "embree1" : "embree2", th,
                         [&](std::vector<Hit>& h) { embree.trace(rays, set.query, h); }, {}});
      cands.push_back({"embreeH1", 1, [&](std::vector<Hit>& h) { embree_high.trace(rays, set.query, h); }, {}});
#endif
      for (const WideTree& w : wide) {
        const WideTracer* wt = w.tracer.get();
        cands.push_back({w.name, 1, [=, &rays, &set](std::vector<Hit>& h) { trace_wide(*wt, rays, set.query, h); }, {}});
        if (w.name == "best-bvh8") {
          cands.push_back({"best-bvh8-2t", 2,
                           [=, &rays, &set](std::vector<Hit>& h) { trace_wide(*wt, rays, set.query, h); }, {}});
          for (uint32_t n : opt.batch_sizes)
            cands.push_back({"best-bvh8-calls-" + std::to_string(n), 1, [=, &rays, &set](std::vector<Hit>& h) {
                               trace_wide_calls(*wt, rays, set.query, h, n);
                             }, {}});
        }
      }
      std::vector<Hit> hits;
      for (int r = 0; r < opt.repeats; ++r)
        for (Candidate& c : cands) {
          ThreadLimit limit(c.threads);
          if (opt.wall)
            c.times.push_back(seconds_of([&] { c.trace(hits); }));
          else if (c.threads == 1)
            c.times.push_back(thread_cpu_seconds_of([&] { c.trace(hits); }));
          else
            c.times.push_back(process_cpu_seconds_of([&] { c.trace(hits); }, c.threads));
        }
      auto mrays = [&](const std::string& label) {
        for (const Candidate& c : cands)
          if (c.label == label) return double(rays.size()) / upper_median(c.times) / 1e6;
        return 0.0;
      };

      RayMeasurement m;
      {
        ThreadLimit limit(2);
        m = measure_rays(*base, rays, set.query, {.repeats = 1});
      }
      double agree = std::nan("");
      double e1 = 0, e2 = 0;
#ifdef BVHOPT_HAVE_EMBREE
      std::vector<Hit> ours, theirs;
      trace_rays(*base, rays, set.query, ours);
      embree.trace(rays, set.query, theirs);
      agree = agreement(ours, theirs, set.query);
      e1 = mrays("embree1");
      e2 = mrays("embree2");
#endif
      const double o1 = mrays(trees[0].name), o2 = mrays("ours2"), a1 = mrays("dist");
      std::printf("%-8s %8zu %6.1f | %-16s %7.2f %7.2f %7.2f | %7.2f %7.2f %7.2f %7.2f | %6.2f %6.1f | %6.4f\n",
                  set_name.c_str(), rays.size(), 100.0 * m.hit_rate, trees[0].name.c_str(),
                  o1, a1, e1, e1 > 0 ? o1 / e1 : 0.0, o2, e2, e2 > 0 ? o2 / e2 : 0.0, o2 / o1, m.steps.mean, agree);
      json row = {{"scene", scene},
                  {"triangles", mesh.triangle_count()},
                  {"rays", set_name},
                  {"query", set.query == RayQuery::any ? "any" : "closest"},
                  {"count", rays.size()},
                  {"hit_rate", m.hit_rate},
                  {"steps_mean", m.steps.mean},
                  {"tests_mean", m.triangle_tests.mean},
                  {"steps_p90", m.steps.p90},
                  {"ours_1t_mrays", o1},
                  {"ours_distance_order_1t_mrays", a1},
                  {"ours_2t_mrays", o2},
                  {"embree_1t_mrays", e1},
                  {"embree_2t_mrays", e2},
                  {"ratio_1t", e1 > 0 ? o1 / e1 : 0.0},
                  {"ratio_2t", e2 > 0 ? o2 / e2 : 0.0},
                  {"scaling_2t", o2 / o1},
                  {"agreement_with_embree", agree}};
      std::vector<double> costs, ns_per_ray;
      json tree_rows = json::array();
      for (const Tree& t : trees) {
        const double mr = mrays(t.name);
        costs.push_back(t.sah);
        ns_per_ray.push_back(1e3 / mr);
        tree_rows.push_back({{"tree", t.name}, {"sah", t.sah}, {"build_seconds", t.seconds}, {"mrays_1t", mr},
                             {"ratio_1t", e1 > 0 ? mr / e1 : 0.0}});
        if (&t != &trees[0])
          std::printf("%-8s %8s %6s | %-16s %7.2f %7s %7s | %7.2f   (SAH %.2f)\n", "", "", "", t.name.c_str(), mr, "",
                      "", e1 > 0 ? mr / e1 : 0.0, t.sah);
      }
      row["trees"] = tree_rows;
      row["wide"] = wide_rows(wide, rays, set.query, mrays, e1, opt.fit_costs);
#ifdef BVHOPT_HAVE_EMBREE
      row["embree_high_1t_mrays"] = mrays("embreeH1");
      std::printf("%-8s %8s %6s | %-16s %7.2f %7s %7s | %7.2f   (Embree HIGH)\n", "", "", "", "embree-high",
                  mrays("embreeH1"), "", "", e1 > 0 ? mrays("embreeH1") / e1 : 0.0);
#endif
      if (!wide.empty() && wide[0].name == "best-bvh8") {
        std::printf("%-8s best-bvh8 on 2 threads: %.2f Mrays/s, %.2fx its 1 thread\n", "", mrays("best-bvh8-2t"),
                    mrays("best-bvh8-2t") / mrays("best-bvh8"));
        json calls = json::array();
        for (uint32_t n : opt.batch_sizes) {
          const double m = mrays("best-bvh8-calls-" + std::to_string(n));
          std::printf("%-8s best-bvh8 in calls of %u rays: %.2f Mrays/s, %.2fx its one call a chunk, %.2fx Embree MEDIUM\n",
                      "", n, m, m / mrays("best-bvh8"), e1 > 0 ? m / e1 : 0.0);
          calls.push_back({{"rays_per_call", n}, {"mrays_1t", m}, {"ratio_1t", e1 > 0 ? m / e1 : 0.0}});
        }
        if (!opt.batch_sizes.empty()) row["wide_calls"] = calls;
      }
      row["sah_vs_time_correlation"] = pearson(costs, ns_per_ray);
      std::printf("%-8s correlation(SAH cost, ns/ray) over %zu trees: %.3f   (sweep-l1 SAH %.2f)\n", "",
                  trees.size(), pearson(costs, ns_per_ray), trees[0].sah);
      out.push_back(row);
      std::fflush(stdout);
    }
  }
  print_wide_summary(out);
  if (!opt.json_path.empty()) write_json(opt.json_path, out);
  return 0;
}

}  // namespace
}  // namespace bvhopt

int main(int argc, char** argv) {
  return bvhopt::bench::guarded_main("trace_bench", [&] { return bvhopt::run(bvhopt::parse(argc, argv)); });
}
