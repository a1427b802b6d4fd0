// Single-ray traversal of a laid-out tree: closest hit and any hit, watertight triangles.
#pragma once

#include <cstddef>
#include <cstdint>

#include "bvhopt/binary_layout.h"
#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"

namespace bvhopt {

// How traversal picks the child to visit first when the ray enters both. Both orders test
// the two child boxes together (they share one BinaryNode); they differ only in the choice.
enum class ChildOrder : uint8_t {
  // The split axis recorded by finalize and the sign of the ray's direction on it (Kensler,
  // section 5): a choice known before the box test finishes and well predicted for
  // coherent rays. The default: in bench/trace_bench (sweep SAH, leaf size 1, 1 thread)
  // `distance` ran at a median 0.94 of its speed over the 33 scene x ray-set pairs of the
  // shared scenes (0.72 to 1.11; faster only on two random-ray sets).
  split_axis = 0,
  // The child whose box the ray enters first.
  distance = 1,
};

// Work counters of one ray, as the heat maps and the statistics report them.
struct TraceCounters {
  uint32_t steps = 0;           // inner nodes visited (the root always) + leaves tested
  uint32_t triangle_tests = 0;  // ray-triangle tests
};

// Traces rays through a BinaryLayout.
class Tracer {
 public:
  Tracer(const FlatBvh& bvh, const Mesh& mesh);

  // The closest hit in [tmin, tmax]; counters accumulate into `counters`.
  Hit closest(const Ray& ray, TraceCounters& counters, ChildOrder order = ChildOrder::split_axis) const;
  // Whether anything is hit in [tmin, tmax]; stops at the first hit found.
  bool any(const Ray& ray, TraceCounters& counters, ChildOrder order = ChildOrder::split_axis) const;

  size_t node_count() const { return layout_.nodes.size(); }  // inner nodes (at least 1)
  size_t triangle_count() const { return layout_.mesh_triangles; }
  // The triangle behind leaf entry i (for tests).
  uint32_t triangle_id(size_t entry) const { return layout_.triangle_ids[entry]; }
  const BinaryLayout& layout() const { return layout_; }

 private:
  template <ChildOrder kOrder, bool kAny>
  bool traverse(const Ray& ray, Hit& hit, TraceCounters& counters, void* stack) const;
  template <bool kAny>
  bool run(const Ray& ray, Hit& hit, TraceCounters& counters, ChildOrder order) const;

  BinaryLayout layout_;  // beyond a fixed C-stack depth (tracer.cpp) a heap stack is used
};

}  // namespace bvhopt
