// The interface between the wide tracer and its per-ISA kernels (one translation unit each,
// wide_traversal_<isa>.cpp, compiled with that ISA's flags).
#pragma once

#include <cstddef>
#include <cstdint>

#include "bvhopt/ray.h"
#include "bvhopt/tracer.h"
#include "bvhopt/wide_bvh.h"
#include "bvhopt/wide_tracer.h"

namespace bvhopt::wide_kernels {

// One batch of rays through one layout. Exactly one of hits / any_hits is set.
struct Batch {
  const std::byte* arena;
  uint32_t root;
  uint32_t width;  // 4 or 8
  TriangleTest test;
  NearFirst near_first;
  // The traversal stack as two arrays of WideBvh::stack_entries() entries: child words and
  // the entry distances of their boxes.
  uint32_t* stack_words;
  float* stack_t;
  const Ray* rays;
  size_t count;
  Hit* hits;          // closest hits
  uint8_t* any_hits;  // 1 where anything is hit
  TraceCounters* counters;
};

void trace_sse42(const Batch& batch);
void trace_avx2(const Batch& batch);
void trace_avx512(const Batch& batch);

}  // namespace bvhopt::wide_kernels
