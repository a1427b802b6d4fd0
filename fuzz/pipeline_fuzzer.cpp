// Structure-aware: the bytes describe a small triangle soup (shared and repeated vertices,
// degenerate triangles, one power-of-two scale for the whole soup), which builder makes its
// tree (any of them, the SBVH too, over the triangles or over their edge volume pieces) and
// a few rays. The tree must validate; every optimizer (a few passes) must leave a valid
// tree with a finite cost no higher than it started (hill climbing, annealing's best) and
// equal to the cost recomputed from scratch; compaction must lower no cost it cannot; and
// traversal must agree with brute force on every ray.
#include <fuzzer/FuzzedDataProvider.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/references.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/validate.h"
#include "bvhopt/testing/brute_force.h"

namespace bvhopt {
namespace {

// Scale exponents of two, either side of 1: trees and costs over nearly the whole float
// range (coordinates up to 4 * 2^120, so box extents stay finite floats; areas and costs are
// double). Rays only up to 2^+-40: the float triangle tests square edge lengths, and a
// fuzzed soup's shortest edges (fractions down to about 2^-32 of the scale) leave the
// normal floats below that.
constexpr int kMaxScaleExponent = 120;
constexpr int kMaxRayScaleExponent = 40;
constexpr int kMaxTriangles = 48;
constexpr int kRays = 16;

[[noreturn]] void fail(const std::string& what) {
  std::fprintf(stderr, "%s\n", what.c_str());
  std::abort();
}

float coordinate(FuzzedDataProvider& in, float scale) {
  // Small integers make coincident and axis-aligned geometry likely; fractions the rest.
  if (in.ConsumeBool()) return float(in.ConsumeIntegralInRange<int>(-4, 4)) * scale;
  return in.ConsumeFloatingPointInRange<float>(-1.0f, 1.0f) * scale;
}

Vec3 point(FuzzedDataProvider& in, float scale) {
  const float x = coordinate(in, scale), y = coordinate(in, scale);
  return {x, y, coordinate(in, scale)};
}

Mesh triangle_soup(FuzzedDataProvider& in, float scale) {
  Mesh mesh;
  mesh.name = "fuzz soup";
  const int triangles = in.ConsumeIntegralInRange<int>(1, kMaxTriangles);
  const int vertices = in.ConsumeIntegralInRange<int>(1, 3 * triangles);
  for (int v = 0; v < vertices; ++v) mesh.add_vertex(point(in, scale));
  for (int t = 0; t < triangles; ++t) {
    const uint32_t a = in.ConsumeIntegralInRange<uint32_t>(0, vertices - 1);
    const uint32_t b = in.ConsumeIntegralInRange<uint32_t>(0, vertices - 1);
    mesh.add_triangle(a, b, in.ConsumeIntegralInRange<uint32_t>(0, vertices - 1));
  }
  return mesh;
}

void check_tree(const Bvh& bvh, const PrimitiveRefs& refs, const std::string& what) {
  const ValidationReport report = validate(bvh, refs);
  if (!report.ok()) fail(what + ": invalid tree: " + report.summary());
  const double cost = sah_cost(bvh);
  if (!std::isfinite(cost)) fail(what + ": non-finite cost " + std::to_string(cost));
}

// The report's final cost is the tree's: an optimizer that tracks its cost incrementally
// must end where a fresh sum over the tree ends (up to rounding of the running sum).
void check_report(const OptimizeReport& report, const Bvh& bvh, const std::string& what, bool never_worse) {
  if (!std::isfinite(report.initial_cost) || !std::isfinite(report.final_cost))
    fail(what + ": non-finite cost in the report");
  if (never_worse && report.final_cost > report.initial_cost)
    fail(what + ": cost rose from " + std::to_string(report.initial_cost) + " to " + std::to_string(report.final_cost));
  const double fresh = sah_cost(bvh);
  if (std::fabs(fresh - report.final_cost) > 1e-9 * std::max(1.0, fresh))
    fail(what + ": reported cost " + std::to_string(report.final_cost) + " but the tree costs " + std::to_string(fresh));
}

// Compaction over the optimized tree: never above the cost it started from, exactly the
// optimal collapse's cost, and a tree that still validates (each leaf keeps one reference
// per triangle; a reference dropped as a duplicate is allowed).
Bvh compact(Bvh bvh, const PrimitiveRefs& refs, const std::string& what) {
  const std::string name = what + " compaction";
  const double optimum = optimal_collapse_cost(bvh, refs);
  const CollapseResult result = collapse_leaves(bvh, refs);
  if (!std::isfinite(result.cost_after) || result.cost_after > result.cost_before * (1.0 + 1e-12))
    fail(name + ": cost " + std::to_string(result.cost_before) + " -> " + std::to_string(result.cost_after));
  const double fresh = sah_cost(bvh, refs);
  if (std::fabs(fresh - result.cost_after) > 1e-9 * std::max(1.0, fresh) ||
      std::fabs(optimum - result.cost_after) > 1e-9 * std::max(1.0, optimum))
    fail(name + ": reported " + std::to_string(result.cost_after) + ", tree " + std::to_string(fresh) +
         ", optimal collapse " + std::to_string(optimum));
  const ValidationReport report = validate_deduplicated(bvh, refs);
  if (!report.ok()) fail(name + ": invalid tree: " + report.summary());
  return bvh;
}

// One optimizer per input (hill climbing, annealing or an insertion form), then compaction
// of its result; returns the compacted tree, for tracing.
Bvh optimize_and_compact(const Bvh& built, const PrimitiveRefs& refs, uint32_t which, uint64_t seed,
                         const std::string& what) {
  OptimizeLimits limits;
  limits.max_passes = 4;
  Bvh bvh = built;
  std::string name;
  if (which == 0) {
    HillClimbConfig config;
    config.limits = limits;
    name = what + " hill-climb";
    check_report(hill_climb(bvh, config), bvh, name, true);
  } else if (which == 1) {
    AnnealConfig config;
    config.limits = limits;
    config.schedule_passes = 3;
    config.period = 2;
    config.seed = seed;
    name = what + " anneal";
    check_report(anneal(bvh, config), bvh, name, true);  // keep_best: never above the start
  } else {
    InsertionConfig config;
    config.limits = limits;
    config.form = insertion_forms()[which - 2];
    config.seed = seed;
    name = what + " insertion " + std::string(form_name(config.form));
    check_report(optimize_insertion(bvh, config), bvh, name, false);
  }
  check_tree(bvh, refs, name);
  return compact(bvh, refs, name);
}

void trace_against_brute_force(const Mesh& mesh, const Bvh& bvh, const PrimitiveRefs& refs,
                               FuzzedDataProvider& in, float scale, const std::string& what) {
  const Tracer tracer(finalize(bvh, refs), mesh);
  for (int r = 0; r < kRays; ++r) {
    Ray ray;
    ray.org = point(in, 2.0f * scale);
    ray.dir = point(in, 1.0f);
    if (ray.dir.x == 0.0f && ray.dir.y == 0.0f && ray.dir.z == 0.0f) ray.dir.z = 1.0f;
    TraceCounters counters;
    const Hit expected = brute_force_closest(mesh, ray);
    const bool expected_any = expected.hit();  // brute_force_any is this very test
    for (ChildOrder order : {ChildOrder::split_axis, ChildOrder::distance}) {
      const Hit got = tracer.closest(ray, counters, order);
      if (got.hit() != expected.hit() || (expected.hit() && got.t != expected.t))
        fail(what + ": ray " + std::to_string(r) + " closest hit differs from brute force");
      if (tracer.any(ray, counters, order) != expected_any)
        fail(what + ": ray " + std::to_string(r) + " any hit differs from brute force");
    }
  }
}

}  // namespace
}  // namespace bvhopt

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace bvhopt;
  FuzzedDataProvider in(data, size);
  const int exponent = in.ConsumeIntegralInRange<int>(-kMaxScaleExponent, kMaxScaleExponent);
  const float scale = std::ldexp(1.0f, exponent);
  // One builder and one optimizer per input keep an execution short; the fuzzer's mutations
  // reach every pair.
  const std::vector<BuilderKind> builders = all_mesh_builders();
  const BuilderKind kind = builders[in.ConsumeIntegralInRange<size_t>(0, builders.size() - 1)];
  const bool edge_volume = in.ConsumeBool();
  const uint32_t leaf_size = in.ConsumeIntegralInRange<uint32_t>(1, 4);
  const uint32_t optimizer = in.ConsumeIntegralInRange<uint32_t>(0, 1 + uint32_t(insertion_forms().size()));
  const uint64_t seed = in.ConsumeIntegral<uint8_t>();
  const Mesh mesh = triangle_soup(in, scale);

  EdgeVolumeConfig evh;
  evh.t = 6;  // small soups: a few pieces per fat triangle, not thousands
  const PrimitiveRefs refs = edge_volume ? subdivide_edge_volume(mesh, evh).refs : make_references(mesh);
  BuildOptions options;
  options.kind = kind;
  options.leaf.max_leaf_size = leaf_size;
  const std::string what = std::string(builder_name(kind)) + (edge_volume ? " + evh" : "");
  const BuiltTree built = build_tree(mesh, refs, options);
  check_tree(built.bvh, built.refs, what);
  const Bvh compacted = optimize_and_compact(built.bvh, built.refs, optimizer, seed, what);
  if (std::abs(exponent) <= kMaxRayScaleExponent) {
    // Both trees see the same rays: the provider's remaining bytes, read afresh.
    const size_t rays_at = in.remaining_bytes();
    FuzzedDataProvider rays(data + size - rays_at, rays_at), again(data + size - rays_at, rays_at);
    trace_against_brute_force(mesh, built.bvh, built.refs, rays, scale, what);
    trace_against_brute_force(mesh, compacted, built.refs, again, scale, what + " optimized and compacted");
  }
  return 0;
}
