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

// The most rays a kernel traces side by side (WideTracer's kMaxTraceLanes).
constexpr uint32_t kMaxLanes = 16;

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
  // The rays of an incoherent batch may enter children in slot order where few of them hit
  // anything (ClosestHitOrder::adaptive, AnyHitOrder::adaptive; see trace_adaptive).
  bool slot_order_when_missing;
  // The traversal stacks, one per lane, each as two arrays of at least
  // WideBvh::stack_entries() entries: child words and the entry distances of their boxes.
  uint32_t* stack_words;
  float* stack_t;
  size_t stack_stride;  // entries per lane: lane k's stack starts at entry k * stack_stride
  // Rays traced side by side (1: one after the other; at most kMaxLanes). More than one
  // only where ray after ray starts in a different part of the scene (random rays; not
  // camera, ambient occlusion or shadow rays): each then reads nodes the last one did not,
  // and their fetches can overlap.
  uint32_t lanes;
  const Ray* rays;
  size_t count;
  Hit* hits;          // closest hits
  uint8_t* any_hits;  // 1 where anything is hit
  TraceCounters* counters;
  // XORed into an any-hit ray's octant: 7 walks the octant order from its far end
  // (AnyHitOrder::far_first and adaptive), 0 as closest-hit rays do.
  uint32_t any_octant_flip;
};

// Whether rays[0, count) are coherent in the sense of Batch::coherent: of up to 32 pairs of
// neighbours spread over the batch (by the golden ratio), at least 7 in 8 have directions in
// the same octant and within about 2.5 degrees of each other. It depends on the batch's rays
// alone and changes the speed only: both ways visit the same nodes and give the same hits.
bool rays_coherent(const Ray* rays, size_t count);

// Whether rays[0, count) start scattered over the scene (see Batch::lanes): of the same pairs
// as rays_coherent, at least half start more than `distance` apart.
bool rays_scattered(const Ray* rays, size_t count, float distance);
// The distance rays_scattered is asked about: 1/64 of the scene box's diagonal (0 for an
// empty box). Random rays' neighbours start about half a diagonal apart; a camera's, an
// ambient occlusion pixel's or a shadow ray's neighbours a pixel's footprint or less.
float scatter_distance(const Box& scene);

void trace_sse42(const Batch& batch);
void trace_avx2(const Batch& batch);
void trace_avx512(const Batch& batch);

// One ray without a batch (WideTracer::closest(const Ray&) and any(const Ray&)): the kernel
// for a layout's width and triangle test, a child order and query, picked once per tracer.
// It returns whether anything was hit; `hit` gets the closest hit (closest-hit kernels only).
// Its stack holds kOneRayStackEntries entries: trees that need more take the batch path.
using OneRayFn = WideTracer::OneRayFn;
inline constexpr uint32_t kOneRayStackEntries = 256;
OneRayFn one_ray_sse42(uint32_t width, TriangleTest test, NearFirst order, bool any);
OneRayFn one_ray_avx2(uint32_t width, TriangleTest test, NearFirst order, bool any);
OneRayFn one_ray_avx512(uint32_t width, TriangleTest test, NearFirst order, bool any);

}  // namespace bvhopt::wide_kernels
