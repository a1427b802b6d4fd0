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
  // Whether the rays go mostly the same way, ray after ray (camera rays): the kernel then
  // orders children with branches the CPU predicts, else (AVX-512) without branches.
  bool coherent;
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

// Whether rays[0, count) are coherent in the sense of Batch::coherent: of up to 32 pairs of
// neighbours spread over the batch (by the golden ratio), at least 7 in 8 have directions in
// the same octant and within about 2.5 degrees of each other. It depends on the batch's rays
// alone and changes the speed only: both ways visit the same nodes and give the same hits.
bool rays_coherent(const Ray* rays, size_t count);

void trace_sse42(const Batch& batch);
void trace_avx2(const Batch& batch);
void trace_avx512(const Batch& batch);

}  // namespace bvhopt::wide_kernels
