// Structure-aware: the bytes describe a small triangle soup (shared and repeated vertices,
// degenerate triangles, one scale exponent for the whole soup) and a few rays. Every
// builder's tree must validate, every optimizer (a few passes) must leave a valid tree with
// a finite cost no higher than it started (hill climbing) or than the best it saw, and
// traversal must agree with brute force on every ray.
#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/references.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/validate.h"
#include "bvhopt/testing/brute_force.h"

namespace bvhopt {
namespace {

// Scale exponents of two, either side of 1. Wider scales (to the float limits, 2^±126) give
// non-finite SAH costs today (issue 14, item 3); widen this once areas are summed in double.
constexpr int kMaxScaleExponent = 40;
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

// Insertion reports NaN on a zero-area root where the other optimizers report the formula's
// value (issue 14, item 10, fixed separately); drop this allowance with that fix.
bool known_zero_area_nan(const Bvh& bvh, const std::string& what) {
  return what.find("insertion") != std::string::npos && !(bvh.nodes[bvh.root].area() > 0.0f);
}

void check_report(const OptimizeReport& report, const std::string& what, bool never_worse) {
  if (!std::isfinite(report.initial_cost) || !std::isfinite(report.final_cost))
    fail(what + ": non-finite cost in the report");
  if (never_worse && report.final_cost > report.initial_cost)
    fail(what + ": cost rose from " + std::to_string(report.initial_cost) + " to " + std::to_string(report.final_cost));
}

void optimize_all(const Bvh& built, const PrimitiveRefs& refs, uint64_t seed, const std::string& what) {
  OptimizeLimits limits;
  limits.max_passes = 4;
  {
    Bvh bvh = built;
    HillClimbConfig config;
    config.limits = limits;
    check_report(hill_climb(bvh, config), what + " hill-climb", true);
    check_tree(bvh, refs, what + " hill-climb");
  }
  {
    Bvh bvh = built;
    AnnealConfig config;
    config.limits = limits;
    config.schedule_passes = 3;
    config.period = 2;
    config.seed = seed;
    check_report(anneal(bvh, config), what + " anneal", true);  // keep_best: never above the start
    check_tree(bvh, refs, what + " anneal");
  }
  for (InsertionForm form : insertion_forms()) {
    Bvh bvh = built;
    InsertionConfig config;
    config.limits = limits;
    config.form = form;
    config.seed = seed;
    const std::string name = what + " insertion " + std::string(form_name(form));
    const OptimizeReport report = optimize_insertion(bvh, config);
    if (known_zero_area_nan(built, name)) continue;
    check_report(report, name, false);
    check_tree(bvh, refs, name);
  }
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
    for (ChildOrder order : {ChildOrder::split_axis, ChildOrder::distance}) {
      const Hit got = tracer.closest(ray, counters, order);
      if (got.hit() != expected.hit() || (expected.hit() && got.t != expected.t))
        fail(what + ": ray " + std::to_string(r) + " closest hit differs from brute force");
      if (tracer.any(ray, counters, order) != brute_force_any(mesh, ray))
        fail(what + ": ray " + std::to_string(r) + " any hit differs from brute force");
    }
  }
}

}  // namespace
}  // namespace bvhopt

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace bvhopt;
  FuzzedDataProvider in(data, size);
  const float scale = std::ldexp(1.0f, in.ConsumeIntegralInRange<int>(-kMaxScaleExponent, kMaxScaleExponent));
  const uint32_t leaf_size = in.ConsumeIntegralInRange<uint32_t>(1, 4);
  const uint64_t seed = in.ConsumeIntegral<uint8_t>();
  const Mesh mesh = triangle_soup(in, scale);
  const PrimitiveRefs refs = make_references(mesh);
  const size_t rays_at = in.remaining_bytes();
  for (BuilderKind kind : all_builders()) {
    BuildOptions options;
    options.kind = kind;
    options.leaf.max_leaf_size = leaf_size;
    const std::string what(builder_name(kind));
    const Bvh bvh = build_bvh(refs, options);
    check_tree(bvh, refs, what);
    optimize_all(bvh, refs, seed, what);
    // Every builder sees the same rays: the provider's remaining bytes, read afresh.
    FuzzedDataProvider rays(data + size - rays_at, rays_at);
    trace_against_brute_force(mesh, bvh, refs, rays, scale, what);
  }
  return 0;
}
