// Single-ray traversal of the binary layout: slab tests of both children at once, a stack of
// far children, the watertight triangle test inlined in the leaf loop.
#include "bvhopt/tracer.h"

// SSE is part of x86-64; elsewhere the same arithmetic runs lane by lane.
#if defined(__SSE2__) || defined(_M_X64)
#include <xmmintrin.h>
#define BVHOPT_TRACE_SSE 1
#endif

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "trace/watertight_test.h"

namespace bvhopt {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// (1 + 2 gamma_3) with gamma_3 = 3u / (1 - 3u), u = 2^-24: scaling the exit distance by it
// makes the slab test conservative against the rounding of (bound - org) * inv_dir
// (Ize, "Robust BVH ray traversal", 2013), so a box is never missed by a ray that touches it.
constexpr float kExitScale = 1.0f + 2.0f * (3.0f * 0x1p-24f / (1.0f - 3.0f * 0x1p-24f));

struct StackEntry {
  uint32_t node;
  float tnear;
};

constexpr size_t kFixedStack = 128;

// Per-ray values of the slab test.
struct SlabRay {
  float org[3];
  float inv[3];
  int neg[3];  // direction negative on the axis
#ifdef BVHOPT_TRACE_SSE
  __m128 ox, oy, oz, ix, iy, iz;  // broadcast to all four lanes
#endif
};

SlabRay make_slab_ray(const Ray& r) {
  SlabRay s;
  const float d[3] = {r.dir.x, r.dir.y, r.dir.z};
  const float biggest = std::max({std::fabs(d[0]), std::fabs(d[1]), std::fabs(d[2])});
  for (int a = 0; a < 3; ++a) {
    // A zero component would give an infinite inverse and 0 * inf = NaN for an origin on
    // a slab. Components below 1e-20 of the largest are raised to that size (sign kept):
    // the ray then drifts by at most 1e-20 of its length along that axis, far inside the
    // box padding, and every product stays finite.
    float c = d[a];
    if (std::fabs(c) < biggest * 1e-20f) c = std::signbit(c) ? -biggest * 1e-20f : biggest * 1e-20f;
    s.inv[a] = 1.0f / c;
    s.neg[a] = std::signbit(d[a]) ? 1 : 0;
  }
  s.org[0] = r.org.x;
  s.org[1] = r.org.y;
  s.org[2] = r.org.z;
#ifdef BVHOPT_TRACE_SSE
  s.ox = _mm_set1_ps(s.org[0]);
  s.oy = _mm_set1_ps(s.org[1]);
  s.oz = _mm_set1_ps(s.org[2]);
  s.ix = _mm_set1_ps(s.inv[0]);
  s.iy = _mm_set1_ps(s.inv[1]);
  s.iz = _mm_set1_ps(s.inv[2]);
#endif
  return s;
}

// Both children's boxes against the ray within [tmin, limit]: bit i of the result is set when
// child i is entered, tnear[i] its entry distance. Lanes [lo0, lo1, hi0, hi1]: swapping halves
// pairs each bound with its opposite, and min/max sort entry from exit whatever the sign.
#ifdef BVHOPT_TRACE_SSE
inline int intersect_children(const BinaryNode& n, const SlabRay& r, float tmin_s, float limit, float tnear[4]) {
  const __m128 tmin = _mm_set1_ps(tmin_s);
  const __m128 tx = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.x), r.ox), r.ix);
  const __m128 ty = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.y), r.oy), r.iy);
  const __m128 tz = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.z), r.oz), r.iz);
  const __m128 sx = _mm_shuffle_ps(tx, tx, _MM_SHUFFLE(1, 0, 3, 2));
  const __m128 sy = _mm_shuffle_ps(ty, ty, _MM_SHUFFLE(1, 0, 3, 2));
  const __m128 sz = _mm_shuffle_ps(tz, tz, _MM_SHUFFLE(1, 0, 3, 2));
  const __m128 near = _mm_max_ps(_mm_max_ps(_mm_min_ps(tx, sx), _mm_min_ps(ty, sy)), _mm_max_ps(_mm_min_ps(tz, sz), tmin));
  __m128 far = _mm_min_ps(_mm_min_ps(_mm_max_ps(tx, sx), _mm_max_ps(ty, sy)), _mm_max_ps(tz, sz));
  far = _mm_mul_ps(_mm_min_ps(far, _mm_set1_ps(limit)), _mm_set1_ps(kExitScale));
  _mm_storeu_ps(tnear, near);
  return _mm_movemask_ps(_mm_cmple_ps(near, far)) & 3;
}
inline void prefetch_node(const BinaryNode* n) { _mm_prefetch(reinterpret_cast<const char*>(n), _MM_HINT_T0); }
#else
inline int intersect_children(const BinaryNode& n, const SlabRay& r, float tmin, float limit, float tnear[4]) {
  const float* b[3] = {n.x, n.y, n.z};
  int mask = 0;
  for (int c = 0; c < 2; ++c) {
    float lo = tmin, hi = limit;
    for (int a = 0; a < 3; ++a) {
      const float t0 = (b[a][c] - r.org[a]) * r.inv[a];
      const float t1 = (b[a][c + 2] - r.org[a]) * r.inv[a];
      lo = std::max(lo, std::min(t0, t1));
      hi = std::min(hi, std::max(t0, t1));
    }
    tnear[c] = lo;
    mask |= lo <= hi * kExitScale ? (1 << c) : 0;
  }
  return mask;
}
inline void prefetch_node(const BinaryNode*) {}
#endif

}  // namespace

Tracer::Tracer(const FlatBvh& bvh, const Mesh& mesh) : layout_(make_binary_layout(bvh, mesh)) {}

// One function, over 80 lines, on purpose: the hot loop keeps its state (node, stack
// pointer, closest t) in registers only while it is not split across calls.
template <ChildOrder kOrder, bool kAny>
bool Tracer::traverse(const Ray& ray, Hit& hit, TraceCounters& counters, void* stack_memory) const {
  const BinaryNode* nodes = layout_.nodes.data();
  const float* verts = layout_.vertices.data();
  const uint32_t* ids = layout_.triangle_ids.data();
  StackEntry* stack = static_cast<StackEntry*>(stack_memory);
  const SlabRay sr = make_slab_ray(ray);
  WatertightRay wr(ray);
  const float tmin = ray.tmin;
  // hit.t is the exclusive upper bound of an acceptable t; it starts just above tmax so a
  // hit at exactly tmax counts.
  hit.t = ray.tmax < kInf ? std::nextafter(ray.tmax, kInf) : kInf;
  wr.tmax = kInf;
  uint32_t steps = 0, tests = 0;  // inner nodes visited and leaves tested; triangles tested
  size_t sp = 0;
  bool found = false;
  alignas(16) float tnear[4];

  uint32_t node = 0;
  for (;;) {
    const BinaryNode& n = nodes[node];
    ++steps;
    const int entered = intersect_children(n, sr, tmin, hit.t, tnear);
    const uint32_t count0 = n.count[0] & BinaryNode::kCountMask;
    const uint32_t count1 = n.count[1] & BinaryNode::kCountMask;
    const int inner = (count0 == BinaryNode::kInnerChild ? 1 : 0) | (count1 == BinaryNode::kInnerChild ? 2 : 0);
    // Leaves first: their hits shorten the ray before any inner child is entered.
    const int leaves = entered & ~inner;
    if (leaves) {
      for (int c = 0; c < 2; ++c) {
        if (!(leaves & (1 << c))) continue;
        ++steps;
        const uint32_t first = n.child[c];
        const uint32_t end = first + (c == 0 ? count0 : count1);
        tests += end - first;
        for (uint32_t e = first; e < end; ++e) {
          const float* v = verts + 9 * size_t(e);
          if (detail::watertight_test(wr, v, v + 3, v + 6, hit)) {
            hit.triangle_id = ids[e];
            found = true;
            if constexpr (kAny) goto done;
          }
        }
      }
    }
    int go = entered & inner;
    if (leaves && found) {
      // A hit in a leaf may lie before an inner sibling's entry.
      if ((go & 1) && tnear[0] > hit.t) go &= ~1;
      if ((go & 2) && tnear[1] > hit.t) go &= ~2;
    }
    if (go == 3) {
      uint32_t near;
      if constexpr (kOrder == ChildOrder::distance)
        near = tnear[1] < tnear[0] ? 1u : 0u;
      else
        near = static_cast<uint32_t>(sr.neg[n.count[0] >> 24]);
      stack[sp].node = n.child[1 - near];
      stack[sp].tnear = tnear[1 - near];
      ++sp;
      node = n.child[near];
      // The far child is usually visited soon; start its cache line on the way.
      prefetch_node(nodes + n.child[1 - near]);
      continue;
    }
    if (go != 0) {
      node = n.child[go >> 1];
      continue;
    }
    for (;;) {
      if (sp == 0) goto done;
      --sp;
      // Entries pushed before a closer hit was found may now lie beyond it.
      if (stack[sp].tnear <= hit.t) {
        node = stack[sp].node;
        break;
      }
    }
  }
done:
  counters.steps += steps;
  counters.triangle_tests += tests;
  if (!found) hit.t = kInf;
  return found;
}

template <bool kAny>
bool Tracer::run(const Ray& ray, Hit& hit, TraceCounters& counters, ChildOrder order) const {
  // A fixed stack on the C stack serves every tree up to kFixedStack deep; deeper (rare,
  // degenerate) trees get one sized to their depth.
  StackEntry fixed[kFixedStack];
  std::vector<StackEntry> heap;
  void* stack = fixed;
  if (layout_.depth >= kFixedStack) {
    heap.resize(layout_.depth + 1);
    stack = heap.data();
  }
  if (order == ChildOrder::distance) return traverse<ChildOrder::distance, kAny>(ray, hit, counters, stack);
  return traverse<ChildOrder::split_axis, kAny>(ray, hit, counters, stack);
}

Hit Tracer::closest(const Ray& ray, TraceCounters& counters, ChildOrder order) const {
  Hit hit;
  run<false>(ray, hit, counters, order);
  return hit;
}

bool Tracer::any(const Ray& ray, TraceCounters& counters, ChildOrder order) const {
  Hit hit;
  return run<true>(ray, hit, counters, order);
}

}  // namespace bvhopt
