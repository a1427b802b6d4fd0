// Single-ray traversal of a finalized tree: closest hit and any hit, watertight triangles.
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

// How traversal picks the child to visit first when the ray enters both. Both orders test
// the two child boxes together (they share one TraceNode); they differ only in the choice.
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

// Woop, Benthin and Wald (2013), "Watertight ray/triangle intersection": the triangle is
// sheared into the ray's space and tested with edge functions that are exact for shared
// edges (recomputed in double when one is zero), so a ray through an edge or vertex shared
// by two triangles never slips between them. On success fills t, u, v of `hit` (not the
// id) and returns true; hits only with t in [ray.tmin, ray.tmax] and t < hit.t.
// Zero-area triangles are never hit.
struct WatertightRay {
  float org[3];
  float shear_x, shear_y, shear_z;
  int kx, ky, kz;
  float tmin, tmax;
  explicit WatertightRay(const Ray& ray);
};
bool intersect_triangle(const WatertightRay& ray, const float* v0, const float* v1, const float* v2,
                        Hit& hit);
bool intersect_triangle(const Ray& ray, const Triangle& tri, Hit& hit);

// Traversal's own node: one inner node of the tree holding both children's boxes, so one
// 64-byte cache line answers "which children does the ray enter" for a pair of boxes with
// SIMD. Boxes per axis as [lo child 0, lo child 1, hi child 0, hi child 1]. A child is an
// inner node (count & kCountMask == kInnerChild, child = its TraceNode) or a leaf (that many
// entries from `child` in the entry arrays; 0 is an empty slot). count[0] >> 24 is the split
// axis finalize recorded (child 0 lies lower on it).
struct alignas(64) TraceNode {
  static constexpr uint32_t kCountMask = 0x00ffffffu;
  static constexpr uint32_t kInnerChild = 0x00ffffffu;
  float x[4], y[4], z[4];
  uint32_t child[2];
  uint32_t count[2];
};
static_assert(sizeof(TraceNode) == 64);

// A tree ready to trace: its inner nodes as TraceNodes (boxes padded, see traversal.cpp) and,
// per leaf entry, the triangle's nine vertex coordinates in leaf order.
// Trees of any leaf size (up to 65535) and with repeated triangle ids (subdivided
// references) are traced; a triangle met twice is tested twice.
class Tracer {
 public:
  Tracer(const FlatBvh& bvh, const Mesh& mesh);

  // The closest hit in [tmin, tmax]; counters accumulate into `counters`.
  Hit closest(const Ray& ray, TraceCounters& counters, ChildOrder order = ChildOrder::split_axis) const;
  // Whether anything is hit in [tmin, tmax]; stops at the first hit found.
  bool any(const Ray& ray, TraceCounters& counters, ChildOrder order = ChildOrder::split_axis) const;

  size_t node_count() const { return nodes_.size(); }  // inner nodes (at least 1)
  size_t triangle_count() const { return mesh_triangles_; }
  // The triangle behind leaf entry i (for tests).
  uint32_t triangle_id(size_t entry) const { return ids_[entry]; }

 private:
  template <ChildOrder kOrder, bool kAny>
  bool traverse(const Ray& ray, Hit& hit, TraceCounters& counters, void* stack) const;
  template <bool kAny>
  bool run(const Ray& ray, Hit& hit, TraceCounters& counters, ChildOrder order) const;

  std::vector<TraceNode> nodes_;
  std::vector<float> vertices_;  // 9 floats per leaf entry
  std::vector<uint32_t> ids_;
  size_t mesh_triangles_ = 0;
  size_t depth_ = 0;  // deepest node; beyond the fixed C-stack size a heap stack is used
};

// Every triangle of the mesh in id order: the oracle the tests and the measurements check
// traversal against. Ties in t keep the lowest triangle id.
Hit brute_force_closest(const Mesh& mesh, const Ray& ray);
bool brute_force_any(const Mesh& mesh, const Ray& ray);

// A flat tree straight from a Bvh and its references, independent of finalize: children
// ordered lower-first on the axis of widest centre separation, recorded in `axis`. The tests
// trace trees through it, and through finalize, so a fault in either shows separately.
FlatBvh flatten_for_tracing(const Bvh& bvh, const PrimitiveRefs& refs);

}  // namespace bvhopt
