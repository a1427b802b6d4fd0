// Build benchmark: every builder on every scene, on 1 and 2 threads, against Embree's
// rtcBuildBVH (quality MEDIUM, binary nodes, one reference per leaf) timed in the same run
// and scored with our cost function.
//
//   build_bench [--scenes DIR] [--scene SPEC]... [--no-builtin] [--builtin SPEC]
//               [--threads 1,2] [--runs 5] [--builders sweep,binned,...] [--json FILE]
//
// Times are the median of --runs runs after one warm-up; the builders (and the peer) take
// turns round by round, so that load from other processes falls on all of them alike and
// the ratios stay meaningful on a shared machine. Peak heap is the most the builder held
// at once beyond what existed before it started (counted by a replaced operator new): the
// tree it returns plus its scratch; the references (40 bytes each) come on top.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <malloc.h>
#include <new>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench_support.h"

#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/scene_file.h"

#ifdef BVHOPT_HAVE_EMBREE
#include <embree3/rtcore.h>

#include "embree_build.h"
#endif

// ---- heap accounting: live bytes and their peak, for the memory figures ----
namespace {
std::atomic<int64_t> g_live{0};
std::atomic<int64_t> g_peak{0};
void note_alloc(void* p) {
  if (!p) return;
  int64_t now = g_live.fetch_add(int64_t(malloc_usable_size(p)), std::memory_order_relaxed) + int64_t(malloc_usable_size(p));
  int64_t peak = g_peak.load(std::memory_order_relaxed);
  while (now > peak && !g_peak.compare_exchange_weak(peak, now, std::memory_order_relaxed)) {
  }
}
void note_free(void* p) {
  if (p) g_live.fetch_sub(int64_t(malloc_usable_size(p)), std::memory_order_relaxed);
}
void* counted_alloc(size_t n, size_t align) {
  void* p = align <= alignof(std::max_align_t) ? std::malloc(n ? n : 1) : std::aligned_alloc(align, (n + align - 1) / align * align);
  if (!p) throw std::bad_alloc();
  note_alloc(p);
  return p;
}
}  // namespace

void* operator new(size_t n) { return counted_alloc(n, 0); }
void* operator new[](size_t n) { return counted_alloc(n, 0); }
void* operator new(size_t n, std::align_val_t a) { return counted_alloc(n, size_t(a)); }
void* operator new[](size_t n, std::align_val_t a) { return counted_alloc(n, size_t(a)); }
void operator delete(void* p) noexcept { note_free(p), std::free(p); }
void operator delete[](void* p) noexcept { note_free(p), std::free(p); }
void operator delete(void* p, size_t) noexcept { note_free(p), std::free(p); }
void operator delete[](void* p, size_t) noexcept { note_free(p), std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { note_free(p), std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { note_free(p), std::free(p); }
void operator delete(void* p, size_t, std::align_val_t) noexcept { note_free(p), std::free(p); }
void operator delete[](void* p, size_t, std::align_val_t) noexcept { note_free(p), std::free(p); }

namespace bvhopt {
namespace {

using namespace bench;
using Clock = std::chrono::steady_clock;

struct Timing {
  double wall_ms = 0.0;
  double cpu_ms = 0.0;
};

// Wall and CPU milliseconds of `f`. The CPU time is the whole process's: on one thread it is
// the build's own time even when other processes crowd the machine; on more threads it adds
// up all threads (spinning included).
Timing time_ms(const std::function<void()>& f) {
  const double c0 = process_cpu_seconds();
  const auto t0 = Clock::now();
  f();
  const auto t1 = Clock::now();
  const double c1 = process_cpu_seconds();
  return Timing{std::chrono::duration<double, std::milli>(t1 - t0).count(), (c1 - c0) * 1e3};
}

struct Options {
  SceneOptions scenes;
  std::vector<int> threads{1, 2};
  int runs = 5;
  std::vector<BuilderKind> builders = all_builders();
  bool embree = true;
  std::string json_path;
};

Options parse(int argc, char** argv) {
  Options o;
  Args args(argc, argv, "build_bench");
  while (args.next()) {
    const std::string& a = args.current();
    if (read_scene_option(args, o.scenes)) continue;
    if (a == "--no-embree") o.embree = false;
    else if (a == "--json") o.json_path = args.value();
    else if (a == "--runs") o.runs = std::max(1, args.int_value());
    else if (a == "--threads") {
      o.threads.clear();
      for (auto& t : split_list(args.value())) o.threads.push_back(std::max(1, parse_int(t, a)));
    } else if (a == "--builders") {
      o.builders.clear();
      for (auto& b : split_list(args.value())) {
        auto k = parse_builder(b);
        if (!k || *k == BuilderKind::spatial_split)
          throw Error("unknown builder '" + b +
                      "' (sweep, binned, spatial-median, object-median; sbvh has its own bench: sbvh_bench)");
        o.builders.push_back(*k);
      }
    } else if (a == "--help" || a == "-h") {
      std::cout << "build_bench [--scenes DIR] [--scene SPEC]... [--no-builtin] [--builtin SPEC] [--threads 1,2]\n"
                   "            [--runs 5] [--builders sweep,binned,spatial-median,object-median] [--no-embree]\n"
                   "            [--json FILE]\n";
      std::exit(0);
    } else {
      throw Error("unknown option '" + a + "' (try --help)");
    }
  }
  return o;
}

struct Result {
  std::string scene;
  size_t refs = 0;
  std::string builder;
  int threads = 0;
  double ms = 0.0;
  double cpu_ms = 0.0;
  double cost = 0.0;
  double ocost = 0.0;
  size_t nodes = 0;
  double peak_bytes_per_ref = 0.0;  // builder's own peak heap, beyond the references
};

// One builder under test: run(keep) builds once and returns the milliseconds of the timed
// part; with keep set it also leaves the tree in `tree` for scoring.
struct Contestant {
  std::string name;
  bool peer = false;
  std::function<Timing(bool keep)> run;
  Bvh tree;
  std::vector<double> times, cpu_times;
  int64_t peak_extra_bytes = 0;  // ours only: most heap held at once beyond the input
  bool failed = false;
};

// Runs every contestant once to warm up, then `runs` rounds of all of them in turn, so
// that load from other processes on a shared machine falls on all of them alike.
// A peer that fails is reported and dropped, not fatal: ours are still measured.
void run_rounds(std::vector<Contestant>& cs, int runs, const std::string& scene, int threads) {
  for (int round = 0; round <= runs; ++round)
    for (Contestant& c : cs) {
      if (c.failed) continue;
      try {
        Timing t = c.run(round == runs);
        if (round > 0) {
          c.times.push_back(t.wall_ms);
          c.cpu_times.push_back(t.cpu_ms);
        }
      } catch (const Error& e) {
        if (!c.peer) throw;
        std::printf("%-22s %-15s %3d   %s\n", scene.c_str(), c.name.c_str(), threads, e.what());
        c.failed = true;
      }
    }
}

#ifdef BVHOPT_HAVE_EMBREE
std::string g_embree_message = "no message";
void embree_error(void*, RTCError code, const char* message) {
  g_embree_message = "error " + std::to_string(int(code)) + " (" + (message ? message : "") + ")";
}

Bvh convert_embree(const EmbreeNode* root, const PrimitiveRefs& refs) {
  Bvh bvh;
  bvh.nodes.reserve(2 * refs.size());
  bvh.ref_indices.reserve(refs.size());
  auto rec = [&](auto&& self, const EmbreeNode* e, uint32_t parent) -> uint32_t {
    uint32_t me = static_cast<uint32_t>(bvh.nodes.size());
    bvh.nodes.emplace_back();
    bvh.nodes[me].parent = parent;
    if (e->leaf) {
      bvh.nodes[me].make_leaf(static_cast<uint32_t>(bvh.ref_indices.size()), 1);
      bvh.ref_indices.push_back(e->prim);
      return me;
    }
    uint32_t l = self(self, e->children[0], me);
    uint32_t r = self(self, e->children[1], me);
    bvh.nodes[me].make_inner(l, r);
    return me;
  };
  bvh.root = rec(rec, root, kInvalidNode);
  bvh.refit(refs);
  return bvh;
}

// One peer build: fills the primitive array (untimed; the build reorders it), times only
// rtcBuildBVH, and converts the tree when asked.
Timing embree_build_once(RTCDevice device, const PrimitiveRefs& refs, std::vector<RTCBuildPrimitive>& prims,
                         const CostModel& cost, Bvh* keep) {
  for (size_t k = 0; k < refs.size(); ++k) {
    const Box& b = refs.boxes[k];
    prims[k] = RTCBuildPrimitive{b.min.x, b.min.y, b.min.z, 0, b.max.x, b.max.y, b.max.z, static_cast<unsigned>(k)};
  }
  RTCBVH ebvh = rtcNewBVH(device);
  RTCBuildArguments args = rtcDefaultBuildArguments();
  args.byteSize = sizeof(args);
  args.buildQuality = RTC_BUILD_QUALITY_MEDIUM;
  args.maxBranchingFactor = 2;
  args.maxLeafSize = 1;
  args.traversalCost = float(cost.traversal);
  args.intersectionCost = float(cost.intersection);
  args.bvh = ebvh;
  args.primitives = prims.data();
  args.primitiveCount = prims.size();
  args.primitiveArrayCapacity = prims.size();
  set_embree_callbacks(args);
  EmbreeNode* root = nullptr;
  const Timing t = time_ms([&] { root = static_cast<EmbreeNode*>(rtcBuildBVH(&args)); });
  if (!root) {
    rtcReleaseBVH(ebvh);
    throw Error("embree: rtcBuildBVH failed: " + g_embree_message);
  }
  if (keep) *keep = convert_embree(root, refs);
  rtcReleaseBVH(ebvh);
  return t;
}
#endif

int run(int argc, char** argv) {
  Options opt = parse(argc, argv);
  const CostModel cost;
  std::vector<Result> results;
  std::printf("build_bench: median of %d interleaved runs after a warm-up; cost c_T=%g c_I=%g; leaf size 1;"
              " t/peer and c/peer = time and cost over Embree MEDIUM's on the same thread count\n",
              opt.runs, cost.traversal, cost.intersection);
  std::printf("%-22s %9s %-15s %3s %10s %10s %9s %9s %9s %10s %8s %8s %8s\n", "scene", "refs", "builder", "thr",
              "ms", "cpu ms", "Mrefs/s", "cost", "ocost", "heap B/ref", "t/peer", "cpu/peer", "c/peer");
  for (const std::string& spec : scene_specs(opt.scenes)) {
    Mesh mesh = load_scene(spec);
    PrimitiveRefs refs = make_references(mesh);
    std::string scene = std::filesystem::path(spec).filename().string();
    if (scene.rfind("builtin", 0) == 0) scene = spec;
    const size_t n = refs.size();
    for (int threads : opt.threads) {
      ThreadLimit limit(threads);
      std::vector<Contestant> cs;
      cs.reserve(opt.builders.size() + 1);
#ifdef BVHOPT_HAVE_EMBREE
      RTCDevice device = nullptr;
      std::vector<RTCBuildPrimitive> prims;
      if (opt.embree) {
        std::string config = "threads=" + std::to_string(threads);
        device = rtcNewDevice(config.c_str());
        rtcSetDeviceErrorFunction(device, embree_error, nullptr);
        prims.resize(n);
        Contestant& c = cs.emplace_back();
        c.name = "embree-medium";
        c.peer = true;
        c.run = [&, device, &c = c](bool keep) { return embree_build_once(device, refs, prims, cost, keep ? &c.tree : nullptr); };
      }
#endif
      for (BuilderKind kind : opt.builders) {
        Contestant& c = cs.emplace_back();
        c.name = std::string(builder_name(kind));
        c.run = [&, kind, &c = c](bool keep) {
          BuildOptions bo;
          bo.kind = kind;
          bo.cost = cost;
          c.tree = Bvh{};
          int64_t before = g_live.load();
          g_peak.store(before);
          Bvh bvh;
          const Timing t = time_ms([&] { bvh = build_bvh(refs, bo); });
          c.peak_extra_bytes = std::max(c.peak_extra_bytes, g_peak.load() - before);
          if (keep) c.tree = std::move(bvh);
          return t;
        };
      }
      run_rounds(cs, opt.runs, scene, threads);
#ifdef BVHOPT_HAVE_EMBREE
      if (device) rtcReleaseDevice(device);
#endif
      std::vector<Result> row;
      Result peer;
      bool have_peer = false;
      for (Contestant& c : cs) {
        if (c.failed) continue;
        Result r;
        r.builder = c.name;
        r.ms = median(c.times);
        r.cpu_ms = median(c.cpu_times);
        r.cost = sah_cost(c.tree, cost);
        r.ocost = optimal_collapse_cost(c.tree, cost);
        r.nodes = c.tree.nodes.size();
        r.peak_bytes_per_ref = double(c.peak_extra_bytes) / double(std::max<size_t>(1, n));
        if (c.peer) {
          peer = r;
          have_peer = true;
        }
        row.push_back(r);
      }
      for (Result& r : row) {
        r.scene = scene;
        r.refs = n;
        r.threads = threads;
        std::string heap = "-", tr = "-", cpur = "-", cr = "-";
        if (r.builder != "embree-medium") heap = strprintf("%.1f", r.peak_bytes_per_ref);
        if (have_peer && r.builder != "embree-medium") {
          tr = strprintf("%.2f", r.ms / peer.ms);
          cpur = strprintf("%.2f", r.cpu_ms / peer.cpu_ms);
          cr = strprintf("%.3f", r.cost / peer.cost);
        }
        std::printf("%-22s %9zu %-15s %3d %10.2f %10.2f %9.2f %9.2f %9.2f %10s %8s %8s %8s\n", scene.c_str(), n,
                    r.builder.c_str(), threads, r.ms, r.cpu_ms, double(n) / (r.ms * 1e3), r.cost, r.ocost,
                    heap.c_str(), tr.c_str(), cpur.c_str(), cr.c_str());
        std::fflush(stdout);
        results.push_back(r);
      }
    }
  }
  if (!opt.json_path.empty()) {
    nlohmann::json out = nlohmann::json::array();
    for (const Result& r : results)
      out.push_back({{"scene", r.scene},
                     {"references", r.refs},
                     {"builder", r.builder},
                     {"threads", r.threads},
                     {"median_ms", r.ms},
                     {"median_cpu_ms", r.cpu_ms},
                     {"refs_per_second", double(r.refs) / (r.ms * 1e-3)},
                     {"cost", r.cost},
                     {"ocost", r.ocost},
                     {"nodes", r.nodes},
                     {"peak_heap_bytes_per_ref", r.builder == "embree-medium" ? nlohmann::json() : nlohmann::json(r.peak_bytes_per_ref)}});
    write_json(opt.json_path, out);
  }
  return 0;
}

}  // namespace
}  // namespace bvhopt

int main(int argc, char** argv) {
  return bvhopt::bench::guarded_main("build_bench", [&] { return bvhopt::run(argc, argv); });
}
