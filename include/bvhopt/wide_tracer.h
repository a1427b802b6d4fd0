// Single-ray SIMD traversal of wide BVHs (bvhopt/wide_bvh.h), closest and any hit, with the
// kernel picked at run time for the CPU: SSE4.2, AVX2+FMA or AVX-512 (256-bit vectors).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/tracer.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {

// Instruction sets a kernel is compiled for, each in its own translation unit.
enum class Isa : uint8_t { sse42 = 0, avx2 = 1, avx512 = 2 };

// "sse", "avx2", "avx512" (the values BVHOPT_ISA takes).
std::string_view isa_name(Isa isa);
std::optional<Isa> parse_isa(std::string_view name);
// Whether this CPU runs the kernel (cpuid, through __builtin_cpu_supports).
bool isa_supported(Isa isa);
// The kernel used when none is asked for: $BVHOPT_ISA if set (Error if the CPU lacks it or
// the name is unknown), else the best the CPU has. Decided once, at the first call.
Isa default_isa();

// How a node with several children entered orders them, nearest first.
enum class NearFirst : uint8_t {
  // The child ranks computed at build time for the ray's octant (Bvh8Node::octant_rank),
  // the entered children compacted in that order: no comparisons of distances at run time.
  octant_order = 0,
  // The entered children sorted by their entry distance.
  distance_sort = 1,
};

// Where an any-hit (shadow) ray starts among several children entered, in the octant order.
// Any order gives the same answers; what differs is how soon the ray meets an occluder. A
// secondary ray starts on a surface, so it enters every box around its origin and rarely
// hits a triangle there; its other end (a light) mostly lies in open space, where the boxes
// it enters hold its occluders. Measured (docs/wide-bvh.md, "Any-hit rays from the far
// end"): shadow rays 1.00-1.46x as fast from the far end on 10 of 11 shared scenes with the
// light outside the objects or in the room, 0.84-0.91x on staircase, whose light sat in the
// stairs' solid geometry. (NearFirst::distance_sort orders nearest first either way.)
enum class AnyHitOrder : uint8_t {
  // The ray's far end first: the octant order reversed. In incoherent batches on bvh8 (the
  // compacting kernels, AVX2 and AVX-512) a ray goes first into the child it enters last, by
  // the slab test's entry distances, and takes the rest in that order: the octant's order
  // judges by the diagonal of the ray's octant, which misleads rays far from it (classroom's
  // near-vertical AO rays: 4.4 wide nodes a ray that way, 2.9 this way). One ray a call and
  // coherent batches keep the octant's order alone, where the distances cost more than they
  // saved; the answers are the same either way, the counted work may differ.
  far_first = 0,
  near_first = 1,  // as closest-hit rays
  // From the far end, but an incoherent batch's rays, in runs of 32 after the first, enter
  // children in slot order while at most one in 8 of the rays traced so far in the batch hit
  // anything and they took 4 steps a ray or more, as ClosestHitOrder::adaptive does:
  // occlusion rays off the closed meshes, 2-7 % of them blocked, about 5-8 % faster
  // (docs/wide-bvh.md, "Rays that mostly hit nothing"). The default.
  adaptive = 2,
};
// "auto", "far", "near" (the command line's --any-hit-order and Python's any_hit_order).
std::string_view any_hit_order_name(AnyHitOrder order);
std::optional<AnyHitOrder> parse_any_hit_order(std::string_view name);

// How the closest-hit rays of a batch order the children they enter. A ray that hits
// nothing visits every box it enters whatever the order, so for it the near-first order is
// work without use; the answers are the same either way, the counted work may differ.
enum class ClosestHitOrder : uint8_t {
  // Nearest first, but an incoherent batch's rays, in runs of 32 after the first, enter
  // children in slot order, without the ordering's work, while at most one in 8 of the rays
  // traced so far in the batch hit anything and they took 4 steps a ray or more (fewer, and
  // the ordering costs little): ambient occlusion rays off the closed meshes, 2-7 % of them
  // blocked, about 6-11 % faster (docs/wide-bvh.md, "Rays that mostly hit nothing"). One ray
  // a call, coherent batches and rays traced side by side stay nearest first.
  adaptive = 0,
  near_first = 1,  // always, as one ray a call is traced
};
// "auto", "near" (the command line's --closest-hit-order and Python's closest_hit_order).
std::string_view closest_hit_order_name(ClosestHitOrder order);
std::optional<ClosestHitOrder> parse_closest_hit_order(std::string_view name);

struct WideTracerOptions {
  WideLayoutOptions layout;
  std::optional<Isa> isa;  // default: default_isa()
  NearFirst near_first = NearFirst::octant_order;
  AnyHitOrder any_hit_order = AnyHitOrder::adaptive;
  ClosestHitOrder closest_hit_order = ClosestHitOrder::adaptive;
  // Rays traced side by side on batches of scattered rays (random rays; see the kernel's
  // trace_interleaved): 0 picks the measured best (16), 1 traces one ray after the other,
  // at most kMaxTraceLanes. Hits and counted work are the same either way.
  uint32_t lanes = 0;
};

inline constexpr uint32_t kMaxTraceLanes = 16;

// Hits are exact against brute force with the same triangle test: the closest triangle, ties
// in t going to the lowest triangle id, as brute_force_closest does, so every kernel returns
// the same hit for the same ray, whatever the order it visits the tree in.
class WideTracer {
 public:
  WideTracer(const FlatBvh& bvh, const Mesh& mesh, const WideTracerOptions& options = {});

  // One ray per call, as a renderer's ray at a time: a kernel of its own, picked when the
  // tracer is made, with no batch to set up (docs/wide-bvh.md, "One ray a call").
  Hit closest(const Ray& ray, TraceCounters& counters) const;
  bool any(const Ray& ray, TraceCounters& counters) const;
  // Many rays in one call; counters accumulate. Batches of more than 16 rays are looked at
  // first (coherent camera rays, scattered random rays) to pick how they are traced; smaller
  // ones go ray by ray as above. The hits are the same either way, and so is the counted
  // work but where the adaptive orders or AnyHitOrder::far_first take another order.
  void closest(const Ray* rays, size_t count, Hit* hits, TraceCounters& counters) const;
  void any(const Ray* rays, size_t count, uint8_t* hit, TraceCounters& counters) const;

  Isa isa() const { return isa_; }
  const WideBvh& layout() const { return bvh_; }

  // The per-ray kernels' type (internal: src/trace/wide_kernels.h).
  using OneRayFn = bool (*)(const std::byte* arena, uint32_t root, const Ray& ray, Hit& hit, TraceCounters& counters,
                            uint32_t any_octant_flip);

 private:
  WideBvh bvh_;
  Isa isa_;
  NearFirst near_first_;
  uint32_t any_octant_flip_;  // wide_kernels::Batch::any_octant_flip for the options' AnyHitOrder
  AnyHitOrder any_hit_order_;
  ClosestHitOrder closest_hit_order_;
  uint32_t lanes_;
  float scatter_distance_;  // wide_kernels::scatter_distance of the scene, computed once
  // The kernels of the per-ray entry points, picked once; null where the tree needs a deeper
  // stack than theirs (those calls take the batch path).
  OneRayFn one_closest_ = nullptr;
  OneRayFn one_any_ = nullptr;
};

}  // namespace bvhopt
