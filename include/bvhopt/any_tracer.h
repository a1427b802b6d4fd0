// One handle on whichever tracer traces a tree, so that measuring, rendering and checking
// work the same for every layout: the binary Tracer (bvh2) or the WideTracer (bvh4, bvh8).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>

#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/tracer.h"
#include "bvhopt/wide_tracer.h"

namespace bvhopt {

// The layouts a tree can be traced in. bvh8 is the default: the fastest on this project's
// benchmark machine (bench/trace_bench, Sponza, Conference and bunny, 1 thread, every ray set:
// bvh8 2.4-3.3x bvh2 and 1.07-1.42x bvh4, see docs/wide-bvh.md).
enum class TraceLayout : uint8_t { bvh2 = 0, bvh4 = 4, bvh8 = 8 };
inline constexpr TraceLayout kDefaultTraceLayout = TraceLayout::bvh8;
std::string_view trace_layout_name(TraceLayout layout);  // "bvh2", "bvh4", "bvh8"
std::optional<TraceLayout> parse_trace_layout(std::string_view name);

// The wide tracer of a bvh4 / bvh8 layout collapsed under `cost`, null for bvh2: what the
// command line's --layout, --wide-block, --any-hit-order and --closest-hit-order, the
// experiment and Python's trace() ask for.
std::unique_ptr<WideTracer> make_wide_tracer(const FlatBvh& flat, const Mesh& mesh, TraceLayout layout,
                                             const WideCostModel& cost = {},
                                             AnyHitOrder any_hit_order = AnyHitOrder::adaptive,
                                             ClosestHitOrder closest_hit_order = ClosestHitOrder::adaptive);

// Non-owning: the tracer must outlive the handle.
class AnyTracer {
 public:
  AnyTracer(const Tracer& tracer, ChildOrder order = ChildOrder::split_axis) : binary_(&tracer), order_(order) {}
  AnyTracer(const WideTracer& tracer) : wide_(&tracer) {}

  Hit closest(const Ray& ray, TraceCounters& counters) const;
  bool any(const Ray& ray, TraceCounters& counters) const;
  // Many rays in one call, counters summed (the wide kernels then run without a call per ray).
  void closest(const Ray* rays, size_t count, Hit* hits, TraceCounters& counters) const;
  void any(const Ray* rays, size_t count, uint8_t* hit, TraceCounters& counters) const;

  // Brute force with the same triangle test, the oracle the hits must equal.
  Hit brute_force(const Mesh& mesh, const Ray& ray) const;
  // Whether triangle `id` alone is hit at exactly `t` by that test (a tie with the oracle).
  bool hits_at(const Mesh& mesh, const Ray& ray, uint32_t id, float t) const;

  TraceLayout layout() const;
  // The instruction set the traversal runs: the wide kernel's, or "sse" for the binary
  // tracer (baseline x86-64 SSE).
  std::string_view isa() const;

 private:
  const Tracer* binary_ = nullptr;
  const WideTracer* wide_ = nullptr;
  ChildOrder order_ = ChildOrder::split_axis;
};

}  // namespace bvhopt
