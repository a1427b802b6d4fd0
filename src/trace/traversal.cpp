// Single-ray traversal over the finalized tree and the watertight triangle test.
#include "bvhopt/traversal.h"

// SSE is part of x86-64; elsewhere the same arithmetic runs lane by lane.
#if defined(__SSE2__) || defined(_M_X64)
#include <xmmintrin.h>
#define BVHOPT_TRACE_SSE 1
#endif

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "bvhopt/error.h"

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
inline int intersect_children(const TraceNode& n, const SlabRay& r, float tmin_s, float limit, float tnear[4]) {
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
inline void prefetch_node(const TraceNode* n) { _mm_prefetch(reinterpret_cast<const char*>(n), _MM_HINT_T0); }
#else
inline int intersect_children(const TraceNode& n, const SlabRay& r, float tmin, float limit, float tnear[4]) {
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
inline void prefetch_node(const TraceNode*) {}
#endif

}  // namespace

WatertightRay::WatertightRay(const Ray& ray) {
  const float d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
  org[0] = ray.org.x;
  org[1] = ray.org.y;
  org[2] = ray.org.z;
  kz = 0;
  if (std::fabs(d[1]) > std::fabs(d[kz])) kz = 1;
  if (std::fabs(d[2]) > std::fabs(d[kz])) kz = 2;
  kx = kz == 2 ? 0 : kz + 1;
  ky = kx == 2 ? 0 : kx + 1;
  // Keep the winding of the sheared triangle independent of the direction's sign.
  if (d[kz] < 0.0f) std::swap(kx, ky);
  shear_x = d[kx] / d[kz];
  shear_y = d[ky] / d[kz];
  shear_z = 1.0f / d[kz];
  tmin = ray.tmin;
  tmax = ray.tmax;
}

namespace {
// Inlined into the traversal loop; the public intersect_triangle calls the same code.
inline __attribute__((always_inline)) bool watertight_test(const WatertightRay& r, const float* v0, const float* v1, const float* v2, Hit& hit) {
  const float ax = v0[r.kx] - r.org[r.kx], ay = v0[r.ky] - r.org[r.ky], az = v0[r.kz] - r.org[r.kz];
  const float bx = v1[r.kx] - r.org[r.kx], by = v1[r.ky] - r.org[r.ky], bz = v1[r.kz] - r.org[r.kz];
  const float cx = v2[r.kx] - r.org[r.kx], cy = v2[r.ky] - r.org[r.ky], cz = v2[r.kz] - r.org[r.kz];
  const float Ax = ax - r.shear_x * az, Ay = ay - r.shear_y * az;
  const float Bx = bx - r.shear_x * bz, By = by - r.shear_y * bz;
  const float Cx = cx - r.shear_x * cz, Cy = cy - r.shear_y * cz;
  float U = Cx * By - Cy * Bx;
  float V = Ax * Cy - Ay * Cx;
  float W = Bx * Ay - By * Ax;
  // A zero edge function is where float rounding could decide the side differently for the
  // two triangles of an edge; double makes the products exact, so both agree.
  if (U == 0.0f || V == 0.0f || W == 0.0f) {
    U = static_cast<float>(double(Cx) * double(By) - double(Cy) * double(Bx));
    V = static_cast<float>(double(Ax) * double(Cy) - double(Ay) * double(Cx));
    W = static_cast<float>(double(Bx) * double(Ay) - double(By) * double(Ax));
  }
  if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return false;
  const float det = U + V + W;
  if (det == 0.0f) return false;
  const float T = U * (r.shear_z * az) + V * (r.shear_z * bz) + W * (r.shear_z * cz);
  const float inv_det = 1.0f / det;
  const float t = T * inv_det;
  if (!(t >= r.tmin && t <= r.tmax && t < hit.t)) return false;
  hit.t = t;
  hit.u = V * inv_det;
  hit.v = W * inv_det;
  return true;
}
}  // namespace

bool intersect_triangle(const WatertightRay& r, const float* v0, const float* v1, const float* v2, Hit& hit) {
  return watertight_test(r, v0, v1, v2, hit);
}

bool intersect_triangle(const Ray& ray, const Triangle& tri, Hit& hit) {
  const WatertightRay r(ray);
  const float a[3] = {tri.v0.x, tri.v0.y, tri.v0.z};
  const float b[3] = {tri.v1.x, tri.v1.y, tri.v1.z};
  const float c[3] = {tri.v2.x, tri.v2.y, tri.v2.z};
  return intersect_triangle(r, a, b, c, hit);
}

Tracer::Tracer(const FlatBvh& bvh, const Mesh& mesh) : mesh_triangles_(mesh.triangle_count()) {
  const size_t n = bvh.nodes.size();
  if (n == 0) throw Error("tracer: the tree has no nodes");
  const size_t entries = bvh.triangle_ids.size();
  for (size_t i = 0; i < n; ++i) {
    const FlatNode& f = bvh.nodes[i];
    if (f.is_leaf()) {
      if (size_t(f.index) + f.count > entries)
        throw Error("tracer: node " + std::to_string(i) + ": leaf entries " + std::to_string(f.index) + "+" +
                    std::to_string(f.count) + " beyond the " + std::to_string(entries) + " triangle ids");
    } else if (i + 1 >= n || f.index <= i + 1 || f.index >= n) {
      throw Error("tracer: node " + std::to_string(i) + ": right child " + std::to_string(f.index) +
                  " is not a later node (the tree has " + std::to_string(n) + " nodes)");
    }
  }

  // Padding. The slab test is exact up to the 1+2*gamma_3 scaling, but the triangle test
  // is watertight, not exact: it may accept a ray that passes a few ulps (of the
  // vertex-to-origin distance) outside a triangle, e.g. through the far side of a shared
  // vertex, whose box the exact ray then misses. Boxes grow by 2^-17 of the largest
  // coordinate (about 64 ulps), which covers that error for origins up to about ten scene
  // sizes away; the cost is a few more box hits at grazing angles.
  float largest = 0.0f;
  for (const FlatNode& f : bvh.nodes)
    for (float c : {f.box.min.x, f.box.min.y, f.box.min.z, f.box.max.x, f.box.max.y, f.box.max.z})
      if (std::isfinite(c)) largest = std::max(largest, std::fabs(c));
  const float pad = largest * 0x1p-17f;

  // One TraceNode per inner flat node, numbered in the flat (depth-first) order so a left
  // child's TraceNode follows its parent's. A tree that is a single leaf gets one TraceNode
  // holding that leaf and an empty slot.
  std::vector<uint32_t> pair_of(n, kInvalidNode);
  uint32_t pairs = 0;
  for (size_t i = 0; i < n; ++i)
    if (!bvh.nodes[i].is_leaf()) pair_of[i] = pairs++;
  nodes_.assign(std::max<uint32_t>(pairs, 1), TraceNode{});
  auto set_child = [&](TraceNode& t, int slot, size_t flat) {
    const FlatNode& c = bvh.nodes[flat];
    t.x[slot] = c.box.min.x - pad;
    t.x[slot + 2] = c.box.max.x + pad;
    t.y[slot] = c.box.min.y - pad;
    t.y[slot + 2] = c.box.max.y + pad;
    t.z[slot] = c.box.min.z - pad;
    t.z[slot + 2] = c.box.max.z + pad;
    t.child[slot] = c.is_leaf() ? c.index : pair_of[flat];
    t.count[slot] = (t.count[slot] & ~TraceNode::kCountMask) | (c.is_leaf() ? c.count : TraceNode::kInnerChild);
  };
  std::vector<uint32_t> depth(n, 0);
  if (pairs == 0) {
    set_child(nodes_[0], 0, 0);
    set_child(nodes_[0], 1, 0);
    nodes_[0].count[1] = 0;  // empty slot
  }
  for (size_t i = 0; i < n; ++i) {
    const FlatNode& f = bvh.nodes[i];
    if (f.is_leaf()) continue;
    TraceNode& t = nodes_[pair_of[i]];
    t.count[0] = uint32_t(f.axis > 2 ? 0 : f.axis) << 24;
    set_child(t, 0, i + 1);
    set_child(t, 1, f.index);
    depth[i + 1] = depth[f.index] = depth[i] + 1;
    depth_ = std::max<size_t>(depth_, depth[i] + 1);
  }

  ids_ = bvh.triangle_ids;
  vertices_.resize(9 * entries);
  for (size_t e = 0; e < entries; ++e) {
    if (ids_[e] >= mesh_triangles_)
      throw Error("tracer: leaf entry " + std::to_string(e) + ": triangle id " + std::to_string(ids_[e]) +
                  " out of range (mesh " + mesh.name + " has " + std::to_string(mesh_triangles_) + " triangles)");
    const Triangle t = mesh.triangle(ids_[e]);
    const float v[9] = {t.v0.x, t.v0.y, t.v0.z, t.v1.x, t.v1.y, t.v1.z, t.v2.x, t.v2.y, t.v2.z};
    std::copy(v, v + 9, vertices_.begin() + 9 * e);
  }
}

template <ChildOrder kOrder, bool kAny>
bool Tracer::traverse(const Ray& ray, Hit& hit, TraceCounters& counters, void* stack_memory) const {
  const TraceNode* nodes = nodes_.data();
  const float* verts = vertices_.data();
  const uint32_t* ids = ids_.data();
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
    const TraceNode& n = nodes[node];
    ++steps;
    const int entered = intersect_children(n, sr, tmin, hit.t, tnear);
    const uint32_t count0 = n.count[0] & TraceNode::kCountMask;
    const uint32_t count1 = n.count[1] & TraceNode::kCountMask;
    const int inner = (count0 == TraceNode::kInnerChild ? 1 : 0) | (count1 == TraceNode::kInnerChild ? 2 : 0);
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
          if (watertight_test(wr, v, v + 3, v + 6, hit)) {
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
  if (depth_ >= kFixedStack) {
    heap.resize(depth_ + 1);
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

Hit brute_force_closest(const Mesh& mesh, const Ray& ray) {
  Hit hit;
  hit.t = ray.tmax < kInf ? std::nextafter(ray.tmax, kInf) : kInf;
  WatertightRay wr(ray);
  wr.tmax = kInf;
  const size_t n = mesh.triangle_count();
  for (size_t i = 0; i < n; ++i) {
    const Triangle t = mesh.triangle(i);
    const float a[3] = {t.v0.x, t.v0.y, t.v0.z};
    const float b[3] = {t.v1.x, t.v1.y, t.v1.z};
    const float c[3] = {t.v2.x, t.v2.y, t.v2.z};
    if (intersect_triangle(wr, a, b, c, hit)) hit.triangle_id = static_cast<uint32_t>(i);
  }
  if (!hit.hit()) hit.t = kInf;
  return hit;
}

bool brute_force_any(const Mesh& mesh, const Ray& ray) { return brute_force_closest(mesh, ray).hit(); }

FlatBvh flatten_for_tracing(const Bvh& bvh, const PrimitiveRefs& refs) {
  FlatBvh out;
  if (bvh.empty()) return out;
  struct Item {
    uint32_t node;
    uint32_t parent_slot;  // flat index whose `index` becomes this node (right children)
  };
  std::vector<Item> todo{{bvh.root, kInvalidNode}};
  while (!todo.empty()) {
    const Item it = todo.back();
    todo.pop_back();
    const uint32_t flat = static_cast<uint32_t>(out.nodes.size());
    if (it.parent_slot != kInvalidNode) out.nodes[it.parent_slot].index = flat;
    const BvhNode& n = bvh[it.node];
    FlatNode f{};
    f.box = n.box;
    if (n.is_leaf()) {
      f.index = static_cast<uint32_t>(out.triangle_ids.size());
      f.count = static_cast<uint16_t>(n.ref_count());
      for (uint32_t i = 0; i < n.ref_count(); ++i)
        out.triangle_ids.push_back(refs.triangle_ids[bvh.ref_indices[n.first_ref() + i]]);
      out.nodes.push_back(f);
      continue;
    }
    // Lower child on the axis of widest centre separation first, so split_axis order works.
    uint32_t a = n.left(), b = n.right();
    const Vec3 ca = bvh[a].box.center(), cb = bvh[b].box.center();
    const Vec3 d = cb - ca;
    int axis = 0;
    if (std::fabs(d.y) > std::fabs(d[axis])) axis = 1;
    if (std::fabs(d.z) > std::fabs(d[axis])) axis = 2;
    if (d[axis] < 0.0f) std::swap(a, b);
    f.axis = static_cast<uint8_t>(axis);
    out.nodes.push_back(f);
    todo.push_back({b, flat});
    todo.push_back({a, kInvalidNode});
  }
  return out;
}

}  // namespace bvhopt
