// The wide traversal kernel, written once and compiled once per ISA: each
// wide_traversal_<isa>.cpp includes this file under its own compile flags. Everything here
// has internal linkage (an unnamed namespace), so the copies built for different ISAs never
// meet at link time; for the same reason this file calls nothing from the standard library
// that could be emitted out of line (a shared inline function compiled with AVX-512 could
// otherwise be the copy the linker keeps for everyone).
//
// Exactness across ISAs: the triangle tests use no fused multiply-add (the ISA files are
// compiled with -ffp-contract=off) and the same operation order as the scalar oracles, so
// every kernel computes bit-identical t, u, v; ties in t go to the lowest triangle id. Only
// the slab test differs (fused on AVX2/AVX-512), which changes which padded boxes are
// entered at grazing angles but never the closest hit.
#pragma once

#include <immintrin.h>

#include <cstdint>

#include "bvhopt/ray_triangle.h"
#include "trace/wide_kernels.h"

namespace bvhopt::wide_kernels {
namespace {

constexpr float kInfinity = __builtin_inff();
constexpr float kLargest = 3.40282347e+38f;
// The conservative exit scaling of the binary tracer (Ize 2013, see traversal.cpp), there
// 1 + 2 gamma(3) for the three roundings of (b - o) * rdir. Here it is folded into the far
// planes' reciprocal and origin term (KernelRay::far_rdir, far_org_rdir), which adds two
// roundings: gamma(5). Folded, it leaves no multiply between a node's load and its child
// mask (armadillo, 1 thread: AO rays +1 %, random +0.5 %; RaysFromFarAway... tests it).
constexpr float kExitScale = 1.0f + 2.0f * (5.0f * 0x1p-24f / (1.0f - 5.0f * 0x1p-24f));

inline float abs_f(float x) { return __builtin_fabsf(x); }
inline float max_f(float a, float b) { return a > b ? a : b; }
inline uint32_t lowest_bit(uint32_t m) { return uint32_t(__builtin_ctz(m)); }
// The same as an array index (m != 0). Counted by the builtins, GCC sign- or zero-extends
// the count before the load it indexes, one more instruction on the traversal's chain from a
// node's slab test to its only entered child; counted in a 64-bit register, it is the index.
// (The encoding of tzcnt runs as bsf on CPUs without BMI1: the same result for m != 0.)
inline size_t lowest_bit_index(uint32_t m) {
  uint64_t i;
  asm("tzcnt %1, %0" : "=r"(i) : "r"(uint64_t(m)) : "cc");
  return i;
}

// Per-ray values, computed once.
struct KernelRay {
  float org[3], dir[3];
  float rdir[3], org_rdir[3];
  float far_rdir[3], far_org_rdir[3];  // the two above times kExitScale, for the far planes
  uint32_t near_row[3], far_row[3];  // bounds row (0..5) of the near and far plane per axis
  uint32_t octant;
  float tmin;
  // Moller-Trumbore runs on dir * t_scale, a power of two that brings the largest component
  // to [0.5, 1): its determinant is a product of the direction and two edges, which for an
  // unnormalized direction (segment rays) is a cube of the scene's scale and leaves the
  // float range above about 7e12 or below 1e-13. Exact, so the hits are those of dir itself;
  // the distance found is multiplied back by t_scale.
  float t_scale;
  // Watertight test (Woop et al. 2013).
  int kx, ky, kz;
  float sx, sy, sz;
};

// Inlined by force here and in traverse: with the interleaved kernels beside them, GCC stopped
// inlining both, and the call, its KernelRay returned through memory, cost camera rays 9 %.
template <TriangleTest kTest>
inline __attribute__((always_inline)) KernelRay make_ray(const Ray& ray) {
  KernelRay r{};
  const float d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
  const float o[3] = {ray.org.x, ray.org.y, ray.org.z};
  const float biggest = max_f(abs_f(d[0]), max_f(abs_f(d[1]), abs_f(d[2])));
  r.t_scale = mt_direction_scale(biggest);
  r.octant = 0;
  // A zero component is raised to 1e-20 of the largest (sign kept), as in the binary
  // tracer: the inverse stays finite, so no 0 * inf = NaN on a slab through the origin.
  float c[3];
  for (int a = 0; a < 3; ++a) {
    c[a] = d[a];
    if (abs_f(c[a]) < biggest * 1e-20f) c[a] = __builtin_signbit(d[a]) ? -biggest * 1e-20f : biggest * 1e-20f;
  }
  // The three inverses in one division: every slab test waits for them, and three scalar
  // divisions in a row take longer than one of four lanes (the same correctly rounded
  // quotients). Gathered from registers: stored and loaded as a vector, they waited for
  // the stores to forward.
  alignas(16) float inv[4];
  _mm_store_ps(inv, _mm_div_ps(_mm_set1_ps(1.0f), _mm_setr_ps(c[0], c[1], c[2], 1.0f)));
  for (int a = 0; a < 3; ++a) {
    const bool neg = __builtin_signbit(d[a]) != 0;
    r.org[a] = o[a];
    r.dir[a] = d[a] * r.t_scale;
    r.rdir[a] = inv[a];
    r.org_rdir[a] = o[a] * r.rdir[a];
    r.far_rdir[a] = r.rdir[a] * kExitScale;
    r.far_org_rdir[a] = r.org_rdir[a] * kExitScale;
    r.near_row[a] = uint32_t(2 * a + (neg ? 1 : 0));
    r.far_row[a] = uint32_t(2 * a + (neg ? 0 : 1));
    r.octant |= (neg ? 1u : 0u) << a;
  }
  r.tmin = ray.tmin;
  // The watertight test's axis permutation and shear, from the one constructor (out of line,
  // baseline code) the binary tracer uses too; only when the blocks need it, since the call
  // costs the Moller-Trumbore kernel some 10% (it spills the loop's vector registers).
  if constexpr (kTest == TriangleTest::watertight) {
    const WatertightRay w(ray);
    r.kx = w.kx;
    r.ky = w.ky;
    r.kz = w.kz;
    r.sx = w.shear_x;
    r.sy = w.shear_y;
    r.sz = w.shear_z;
  }
  return r;
}

// The closest hit so far. t is an inclusive bound: a hit at exactly t replaces it only with
// a lower triangle id (so the result does not depend on the visiting order).
struct BestHit {
  float t;
  float u = 0.0f, v = 0.0f;
  uint32_t id = kNoHit;

  bool offer(float t_, float u_, float v_, uint32_t id_) {
    if (t_ < t || (t_ == t && id_ < id)) {
      t = t_;
      u = u_;
      v = v_;
      id = id_;
      return true;
    }
    return false;
  }
};

// ---- Slab test: all children of a node at once. -------------------------------------------

// Entry distances to tnear, and the mask of children entered within [tmin, limit].
template <uint32_t W>
inline uint32_t slab_test(const float (*bounds)[W], const KernelRay& r, float limit, float* tnear);

#if defined(__AVX2__)
// The slab test's per-ray operands, broadcast once per ray. Broadcast from KernelRay's
// scalars at every node instead, they cost a dozen shuffles a node on the port that the
// child ordering needs too (with the folded exit scaling, against neither, 1 thread:
// armadillo +2 % on primary, random and AO rays; Conference primary +0.2 %, random +1.8 %,
// AO +1.2 %). traverse keeps these in registers; the side-by-side kernel, whose lanes' worth
// would not fit, broadcasts per node (see slab_operands; kept per lane in memory instead,
// they made random rays 3.5 % slower on armadillo).
struct SlabRay8 {
  __m256 rdir[3], org_rdir[3], far_rdir[3], far_org_rdir[3], tmin;
  uint32_t near_row[3], far_row[3];
  __attribute__((always_inline)) explicit SlabRay8(const KernelRay& r) {
    for (int a = 0; a < 3; ++a) {
      rdir[a] = _mm256_set1_ps(r.rdir[a]);
      org_rdir[a] = _mm256_set1_ps(r.org_rdir[a]);
      far_rdir[a] = _mm256_set1_ps(r.far_rdir[a]);
      far_org_rdir[a] = _mm256_set1_ps(r.far_org_rdir[a]);
      near_row[a] = r.near_row[a];
      far_row[a] = r.far_row[a];
    }
    tmin = _mm256_set1_ps(r.tmin);
  }
};

inline __m256 row8(const float (*b)[8], uint32_t row) { return _mm256_load_ps(b[row]); }
// With the exit limit scaled and broadcast by the caller, once per closer hit: per node, the
// multiply and broadcast sat on the shuffle port the child ordering needs.
inline __attribute__((always_inline)) uint32_t slab_test(const float (*b)[8], const SlabRay8& s, __m256 far_limit,
                                                         float* tnear) {
  const __m256 nx = _mm256_fmsub_ps(row8(b, s.near_row[0]), s.rdir[0], s.org_rdir[0]);
  const __m256 ny = _mm256_fmsub_ps(row8(b, s.near_row[1]), s.rdir[1], s.org_rdir[1]);
  const __m256 nz = _mm256_fmsub_ps(row8(b, s.near_row[2]), s.rdir[2], s.org_rdir[2]);
  const __m256 fx = _mm256_fmsub_ps(row8(b, s.far_row[0]), s.far_rdir[0], s.far_org_rdir[0]);
  const __m256 fy = _mm256_fmsub_ps(row8(b, s.far_row[1]), s.far_rdir[1], s.far_org_rdir[1]);
  const __m256 fz = _mm256_fmsub_ps(row8(b, s.far_row[2]), s.far_rdir[2], s.far_org_rdir[2]);
  const __m256 tn = _mm256_max_ps(_mm256_max_ps(nx, ny), _mm256_max_ps(nz, s.tmin));
  const __m256 tf = _mm256_min_ps(_mm256_min_ps(fx, fy), _mm256_min_ps(fz, far_limit));
  _mm256_store_ps(tnear, tn);
#if defined(__AVX512VL__)
  return uint32_t(_mm256_cmp_ps_mask(tn, tf, _CMP_LE_OQ));
#else
  return uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ)));
#endif
}
inline __attribute__((always_inline)) uint32_t slab_test(const float (*b)[8], const SlabRay8& s, float limit,
                                                         float* tnear) {
  return slab_test(b, s, _mm256_set1_ps(limit * kExitScale), tnear);
}
template <>
inline __attribute__((always_inline)) uint32_t slab_test<8>(const float (*b)[8], const KernelRay& r, float limit,
                                                            float* tnear) {
  return slab_test(b, SlabRay8(r), limit, tnear);
}
#endif

// The exit limit visit_node hands the slab test for the closest hit so far at distance t:
// t itself, or for bvh8 with AVX2 or AVX-512, t scaled and broadcast.
template <uint32_t W>
inline __attribute__((always_inline)) auto node_limit(float t) {
#if defined(__AVX2__)
  if constexpr (W == 8) return _mm256_set1_ps(t * kExitScale);
  else
#endif
    return t;
}

// Four lanes starting at column `col` of a W-wide node.
template <uint32_t W>
inline __attribute__((always_inline)) uint32_t slab_test4(const float (*b)[W], uint32_t col, const KernelRay& r,
                                                          float limit, float* tnear) {
  auto row = [&](uint32_t i) { return _mm_load_ps(b[i] + col); };
  const __m128 rx = _mm_set1_ps(r.rdir[0]), ry = _mm_set1_ps(r.rdir[1]), rz = _mm_set1_ps(r.rdir[2]);
  const __m128 ox = _mm_set1_ps(r.org_rdir[0]), oy = _mm_set1_ps(r.org_rdir[1]), oz = _mm_set1_ps(r.org_rdir[2]);
  const __m128 fax = _mm_set1_ps(r.far_rdir[0]), fay = _mm_set1_ps(r.far_rdir[1]), faz = _mm_set1_ps(r.far_rdir[2]);
  const __m128 fox = _mm_set1_ps(r.far_org_rdir[0]), foy = _mm_set1_ps(r.far_org_rdir[1]),
               foz = _mm_set1_ps(r.far_org_rdir[2]);
#if defined(__FMA__)
  const __m128 nx = _mm_fmsub_ps(row(r.near_row[0]), rx, ox);
  const __m128 ny = _mm_fmsub_ps(row(r.near_row[1]), ry, oy);
  const __m128 nz = _mm_fmsub_ps(row(r.near_row[2]), rz, oz);
  const __m128 fx = _mm_fmsub_ps(row(r.far_row[0]), fax, fox);
  const __m128 fy = _mm_fmsub_ps(row(r.far_row[1]), fay, foy);
  const __m128 fz = _mm_fmsub_ps(row(r.far_row[2]), faz, foz);
#else
  const __m128 nx = _mm_sub_ps(_mm_mul_ps(row(r.near_row[0]), rx), ox);
  const __m128 ny = _mm_sub_ps(_mm_mul_ps(row(r.near_row[1]), ry), oy);
  const __m128 nz = _mm_sub_ps(_mm_mul_ps(row(r.near_row[2]), rz), oz);
  const __m128 fx = _mm_sub_ps(_mm_mul_ps(row(r.far_row[0]), fax), fox);
  const __m128 fy = _mm_sub_ps(_mm_mul_ps(row(r.far_row[1]), fay), foy);
  const __m128 fz = _mm_sub_ps(_mm_mul_ps(row(r.far_row[2]), faz), foz);
#endif
  const __m128 tn = _mm_max_ps(_mm_max_ps(nx, ny), _mm_max_ps(nz, _mm_set1_ps(r.tmin)));
  const __m128 tf = _mm_min_ps(_mm_min_ps(fx, fy), _mm_min_ps(fz, _mm_set1_ps(limit * kExitScale)));
  _mm_store_ps(tnear + col, tn);
#if defined(__AVX512VL__)
  return uint32_t(_mm_cmp_ps_mask(tn, tf, _CMP_LE_OQ)) << col;
#else
  return uint32_t(_mm_movemask_ps(_mm_cmple_ps(tn, tf))) << col;
#endif
}

template <>
inline __attribute__((always_inline)) uint32_t slab_test<4>(const float (*b)[4], const KernelRay& r, float limit,
                                                            float* tnear) {
  return slab_test4<4>(b, 0, r, limit, tnear);
}

#if !defined(__AVX2__)
template <>
inline __attribute__((always_inline)) uint32_t slab_test<8>(const float (*b)[8], const KernelRay& r, float limit,
                                                            float* tnear) {
  return slab_test4<8>(b, 0, r, limit, tnear) | slab_test4<8>(b, 4, r, limit, tnear);
}
#endif

// ---- Triangle tests on a block of four. -----------------------------------------------------

// Offers the block's accepted lanes to `best`; whether any lane was accepted (for any-hit:
// whether anything was hit at all).
inline bool offer_lanes(uint32_t mask, __m128 t, __m128 u, __m128 v, const uint32_t* ids, BestHit& best) {
  alignas(16) float ts[4], us[4], vs[4];
  _mm_store_ps(ts, t);
  _mm_store_ps(us, u);
  _mm_store_ps(vs, v);
  bool any = false;
  for (; mask; mask &= mask - 1) {
    const uint32_t l = lowest_bit(mask);
    any |= best.offer(ts[l], us[l], vs[l], ids[l]);
  }
  return any;
}

// Moller-Trumbore with the operation order of brute_force_closest_mt. The barycentric and
// distance numerators are compared against |det| before any division (their signs flipped
// with det's), so a block the ray misses costs no division; only blocks with a lane inside
// the triangle divide. The distance is e2 . (q / |det|): e2 . q is a cube of the scene's
// scale, which overflows a float above coordinates of about 7e12.
inline __attribute__((always_inline)) bool block_moller_trumbore(const TriangleBlock& b, const KernelRay& r, BestHit& best) {
  const __m128 dx = _mm_set1_ps(r.dir[0]), dy = _mm_set1_ps(r.dir[1]), dz = _mm_set1_ps(r.dir[2]);
  const __m128 e1x = _mm_load_ps(b.p[3]), e1y = _mm_load_ps(b.p[4]), e1z = _mm_load_ps(b.p[5]);
  const __m128 e2x = _mm_load_ps(b.p[6]), e2y = _mm_load_ps(b.p[7]), e2z = _mm_load_ps(b.p[8]);
  const __m128 px = _mm_sub_ps(_mm_mul_ps(dy, e2z), _mm_mul_ps(dz, e2y));
  const __m128 py = _mm_sub_ps(_mm_mul_ps(dz, e2x), _mm_mul_ps(dx, e2z));
  const __m128 pz = _mm_sub_ps(_mm_mul_ps(dx, e2y), _mm_mul_ps(dy, e2x));
  const __m128 det = _mm_add_ps(_mm_add_ps(_mm_mul_ps(e1x, px), _mm_mul_ps(e1y, py)), _mm_mul_ps(e1z, pz));
  const __m128 tx = _mm_sub_ps(_mm_set1_ps(r.org[0]), _mm_load_ps(b.p[0]));
  const __m128 ty = _mm_sub_ps(_mm_set1_ps(r.org[1]), _mm_load_ps(b.p[1]));
  const __m128 tz = _mm_sub_ps(_mm_set1_ps(r.org[2]), _mm_load_ps(b.p[2]));
  const __m128 sign = _mm_and_ps(det, _mm_set1_ps(-0.0f));
  const __m128 adet = _mm_xor_ps(det, sign);
  const __m128 uu = _mm_xor_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(tx, px), _mm_mul_ps(ty, py)), _mm_mul_ps(tz, pz)), sign);
  const __m128 qx = _mm_sub_ps(_mm_mul_ps(ty, e1z), _mm_mul_ps(tz, e1y));
  const __m128 qy = _mm_sub_ps(_mm_mul_ps(tz, e1x), _mm_mul_ps(tx, e1z));
  const __m128 qz = _mm_sub_ps(_mm_mul_ps(tx, e1y), _mm_mul_ps(ty, e1x));
  const __m128 vv = _mm_xor_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, qx), _mm_mul_ps(dy, qy)), _mm_mul_ps(dz, qz)), sign);
  const __m128 zero = _mm_setzero_ps();
  __m128 ok = _mm_and_ps(_mm_cmpneq_ps(det, zero), _mm_cmpge_ps(uu, zero));
  ok = _mm_and_ps(ok, _mm_cmpge_ps(vv, zero));
  ok = _mm_and_ps(ok, _mm_cmple_ps(_mm_add_ps(uu, vv), adet));
  if (_mm_movemask_ps(ok) == 0) return false;
  const __m128 inv = _mm_xor_ps(_mm_div_ps(_mm_set1_ps(1.0f), adet), sign);
  const __m128 ts = _mm_add_ps(_mm_add_ps(_mm_mul_ps(e2x, _mm_mul_ps(qx, inv)), _mm_mul_ps(e2y, _mm_mul_ps(qy, inv))),
                               _mm_mul_ps(e2z, _mm_mul_ps(qz, inv)));
  const __m128 t = _mm_mul_ps(ts, _mm_set1_ps(r.t_scale));
  ok = _mm_and_ps(ok, _mm_cmpge_ps(t, _mm_set1_ps(r.tmin)));
  ok = _mm_and_ps(ok, _mm_cmple_ps(t, _mm_set1_ps(best.t)));
  const uint32_t mask = uint32_t(_mm_movemask_ps(ok));
  const __m128 ainv = _mm_xor_ps(inv, sign);
  return mask != 0 && offer_lanes(mask, t, _mm_mul_ps(uu, ainv), _mm_mul_ps(vv, ainv), b.id, best);
}

#if defined(__AVX2__)
// The same test on two blocks at once (blocks b and b + 1), lane for lane the same operations
// as block_moller_trumbore, so hits are bit-identical; both blocks are judged against the best
// distance before either, which offer() re-checks. Bit k of the result: block b + k gave a
// closer hit (for any-hit: block b + k was hit, where block b was not if k = 1).
inline __attribute__((always_inline)) uint32_t block_pair_moller_trumbore(const TriangleBlock* b, const KernelRay& r,
                                                                          BestHit& best) {
  const auto row = [&](int k) {
    return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(b[0].p[k])), _mm_load_ps(b[1].p[k]), 1);
  };
  const __m256 dx = _mm256_set1_ps(r.dir[0]), dy = _mm256_set1_ps(r.dir[1]), dz = _mm256_set1_ps(r.dir[2]);
  const __m256 e1x = row(3), e1y = row(4), e1z = row(5);
  const __m256 e2x = row(6), e2y = row(7), e2z = row(8);
  const __m256 px = _mm256_sub_ps(_mm256_mul_ps(dy, e2z), _mm256_mul_ps(dz, e2y));
  const __m256 py = _mm256_sub_ps(_mm256_mul_ps(dz, e2x), _mm256_mul_ps(dx, e2z));
  const __m256 pz = _mm256_sub_ps(_mm256_mul_ps(dx, e2y), _mm256_mul_ps(dy, e2x));
  const __m256 det =
      _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(e1x, px), _mm256_mul_ps(e1y, py)), _mm256_mul_ps(e1z, pz));
  const __m256 tx = _mm256_sub_ps(_mm256_set1_ps(r.org[0]), row(0));
  const __m256 ty = _mm256_sub_ps(_mm256_set1_ps(r.org[1]), row(1));
  const __m256 tz = _mm256_sub_ps(_mm256_set1_ps(r.org[2]), row(2));
  const __m256 sign = _mm256_and_ps(det, _mm256_set1_ps(-0.0f));
  const __m256 adet = _mm256_xor_ps(det, sign);
  const __m256 uu = _mm256_xor_ps(
      _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(tx, px), _mm256_mul_ps(ty, py)), _mm256_mul_ps(tz, pz)), sign);
  const __m256 qx = _mm256_sub_ps(_mm256_mul_ps(ty, e1z), _mm256_mul_ps(tz, e1y));
  const __m256 qy = _mm256_sub_ps(_mm256_mul_ps(tz, e1x), _mm256_mul_ps(tx, e1z));
  const __m256 qz = _mm256_sub_ps(_mm256_mul_ps(tx, e1y), _mm256_mul_ps(ty, e1x));
  const __m256 vv = _mm256_xor_ps(
      _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, qx), _mm256_mul_ps(dy, qy)), _mm256_mul_ps(dz, qz)), sign);
  const __m256 zero = _mm256_setzero_ps();
  __m256 ok = _mm256_and_ps(_mm256_cmp_ps(det, zero, _CMP_NEQ_UQ), _mm256_cmp_ps(uu, zero, _CMP_GE_OS));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(vv, zero, _CMP_GE_OS));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(_mm256_add_ps(uu, vv), adet, _CMP_LE_OS));
  if (_mm256_movemask_ps(ok) == 0) return 0;
  const __m256 inv = _mm256_xor_ps(_mm256_div_ps(_mm256_set1_ps(1.0f), adet), sign);
  const __m256 ts = _mm256_add_ps(
      _mm256_add_ps(_mm256_mul_ps(e2x, _mm256_mul_ps(qx, inv)), _mm256_mul_ps(e2y, _mm256_mul_ps(qy, inv))),
      _mm256_mul_ps(e2z, _mm256_mul_ps(qz, inv)));
  const __m256 t = _mm256_mul_ps(ts, _mm256_set1_ps(r.t_scale));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(t, _mm256_set1_ps(r.tmin), _CMP_GE_OS));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(t, _mm256_set1_ps(best.t), _CMP_LE_OS));
  const uint32_t mask = uint32_t(_mm256_movemask_ps(ok));
  if (mask == 0) return 0;
  const __m256 ainv = _mm256_xor_ps(inv, sign);
  const __m256 u = _mm256_mul_ps(uu, ainv), v = _mm256_mul_ps(vv, ainv);
  uint32_t hit = 0;
  if (mask & 15u)
    hit |= offer_lanes(mask & 15u, _mm256_castps256_ps128(t), _mm256_castps256_ps128(u), _mm256_castps256_ps128(v),
                       b[0].id, best)
               ? 1u
               : 0u;
  if (mask >> 4)
    hit |= offer_lanes(mask >> 4, _mm256_extractf128_ps(t, 1), _mm256_extractf128_ps(u, 1),
                       _mm256_extractf128_ps(v, 1), b[1].id, best)
               ? 2u
               : 0u;
  return hit;
}
#endif

// Woop et al.'s watertight test with the operation order of the scalar one in traversal.cpp,
// including its double-precision recomputation when an edge function is zero.
inline __attribute__((always_inline)) bool block_watertight(const TriangleBlock& b, const KernelRay& r, BestHit& best) {
  const __m128 okx = _mm_set1_ps(r.org[r.kx]), oky = _mm_set1_ps(r.org[r.ky]), okz = _mm_set1_ps(r.org[r.kz]);
  const __m128 ax = _mm_sub_ps(_mm_load_ps(b.p[r.kx]), okx), ay = _mm_sub_ps(_mm_load_ps(b.p[r.ky]), oky);
  const __m128 az = _mm_sub_ps(_mm_load_ps(b.p[r.kz]), okz);
  const __m128 bx = _mm_sub_ps(_mm_load_ps(b.p[3 + r.kx]), okx), by = _mm_sub_ps(_mm_load_ps(b.p[3 + r.ky]), oky);
  const __m128 bz = _mm_sub_ps(_mm_load_ps(b.p[3 + r.kz]), okz);
  const __m128 cx = _mm_sub_ps(_mm_load_ps(b.p[6 + r.kx]), okx), cy = _mm_sub_ps(_mm_load_ps(b.p[6 + r.ky]), oky);
  const __m128 cz = _mm_sub_ps(_mm_load_ps(b.p[6 + r.kz]), okz);
  const __m128 sx = _mm_set1_ps(r.sx), sy = _mm_set1_ps(r.sy), sz = _mm_set1_ps(r.sz);
  const __m128 Ax = _mm_sub_ps(ax, _mm_mul_ps(sx, az)), Ay = _mm_sub_ps(ay, _mm_mul_ps(sy, az));
  const __m128 Bx = _mm_sub_ps(bx, _mm_mul_ps(sx, bz)), By = _mm_sub_ps(by, _mm_mul_ps(sy, bz));
  const __m128 Cx = _mm_sub_ps(cx, _mm_mul_ps(sx, cz)), Cy = _mm_sub_ps(cy, _mm_mul_ps(sy, cz));
  __m128 U = _mm_sub_ps(_mm_mul_ps(Cx, By), _mm_mul_ps(Cy, Bx));
  __m128 V = _mm_sub_ps(_mm_mul_ps(Ax, Cy), _mm_mul_ps(Ay, Cx));
  __m128 W = _mm_sub_ps(_mm_mul_ps(Bx, Ay), _mm_mul_ps(By, Ax));
  const __m128 zero = _mm_setzero_ps();
  const uint32_t zeros = uint32_t(_mm_movemask_ps(
      _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(U, zero), _mm_cmpeq_ps(V, zero)), _mm_cmpeq_ps(W, zero))));
  if (zeros) {
    alignas(16) float f[6][4], e[3][4];
    _mm_store_ps(f[0], Ax), _mm_store_ps(f[1], Ay), _mm_store_ps(f[2], Bx);
    _mm_store_ps(f[3], By), _mm_store_ps(f[4], Cx), _mm_store_ps(f[5], Cy);
    _mm_store_ps(e[0], U), _mm_store_ps(e[1], V), _mm_store_ps(e[2], W);
    for (uint32_t m = zeros; m; m &= m - 1) {
      const uint32_t l = lowest_bit(m);
      const double dAx = f[0][l], dAy = f[1][l], dBx = f[2][l], dBy = f[3][l], dCx = f[4][l], dCy = f[5][l];
      e[0][l] = float(dCx * dBy - dCy * dBx);
      e[1][l] = float(dAx * dCy - dAy * dCx);
      e[2][l] = float(dBx * dAy - dBy * dAx);
    }
    U = _mm_load_ps(e[0]);
    V = _mm_load_ps(e[1]);
    W = _mm_load_ps(e[2]);
  }
  const __m128 neg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(U, zero), _mm_cmplt_ps(V, zero)), _mm_cmplt_ps(W, zero));
  const __m128 pos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(U, zero), _mm_cmpgt_ps(V, zero)), _mm_cmpgt_ps(W, zero));
  const __m128 det = _mm_add_ps(_mm_add_ps(U, V), W);
  __m128 ok = _mm_andnot_ps(_mm_and_ps(neg, pos), _mm_cmpneq_ps(det, zero));
  if (_mm_movemask_ps(ok) == 0) return false;
  // The distance from the normalized barycentrics, as in the scalar test (no cube of the
  // scene's scale to overflow).
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), det);
  const __m128 u = _mm_mul_ps(U, inv), v = _mm_mul_ps(V, inv), w = _mm_mul_ps(W, inv);
  const __m128 t = _mm_add_ps(_mm_add_ps(_mm_mul_ps(u, _mm_mul_ps(sz, az)), _mm_mul_ps(v, _mm_mul_ps(sz, bz))),
                              _mm_mul_ps(w, _mm_mul_ps(sz, cz)));
  ok = _mm_and_ps(ok, _mm_cmpge_ps(t, _mm_set1_ps(r.tmin)));
  ok = _mm_and_ps(ok, _mm_cmple_ps(t, _mm_set1_ps(best.t)));
  const uint32_t mask = uint32_t(_mm_movemask_ps(ok));
  return mask != 0 && offer_lanes(mask, t, v, w, b.id, best);
}

// ---- Traversal. -----------------------------------------------------------------------------

template <uint32_t W>
struct WideNode;
template <>
struct WideNode<8> {
  using Node = Bvh8Node;
  static constexpr uint32_t kBits = 3;
  static uint32_t order(const Node& n, uint32_t octant) { return n.octant_order[octant]; }
};
template <>
struct WideNode<4> {
  using Node = Bvh4Node;
  static constexpr uint32_t kBits = 2;
  static uint32_t order(const Node& n, uint32_t octant) { return n.octant_order[octant]; }
};

template <class T>
inline const T* at_unit(const std::byte* arena, uint32_t word) {
  return reinterpret_cast<const T*>(arena + size_t(word & kWideOffsetMask) * kWideUnit);
}

// An inner node's word is its offset alone (no flag, no count bits; the layout keeps offsets
// under 2^27), so its address needs no mask: one instruction less on the chain from a
// node's slab test to its child's load.
template <class T>
inline const T* at_inner_unit(const std::byte* arena, uint32_t word) {
  return reinterpret_cast<const T*>(arena + size_t(word) * kWideUnit);
}

// Asks for the four cache lines at a child word's target (a whole node, or the first of a
// leaf's blocks). The traversal is a chain of dependent loads, each node's address known
// only once its parent's slab test is done, so on incoherent rays most of a step is the wait
// for the node; the next pop is known earlier than that (see traverse). Measured on
// Conference and armadillo (1 thread): random rays +5 %, AO rays +1 to 5 %, primary rays,
// whose nodes are mostly in cache already, -1 to 2 %.
inline __attribute__((always_inline)) void prefetch_unit(const std::byte* arena, uint32_t word) {
  const char* p = reinterpret_cast<const char*>(arena + size_t(word & kWideOffsetMask) * kWideUnit);
  _mm_prefetch(p, _MM_HINT_T0);
  _mm_prefetch(p + 64, _MM_HINT_T0);
  _mm_prefetch(p + 128, _MM_HINT_T0);
  _mm_prefetch(p + 192, _MM_HINT_T0);
}

// The traversal stack (two arrays, see Batch).
struct Stack {
  uint32_t* words;
  float* t;
  uint32_t size = 0;
  void push(uint32_t word, float tn) {
    words[size] = word;
    t[size] = tn;
    ++size;
  }
};

#if defined(__AVX2__) && !defined(__AVX512VL__)
// Per 8-bit mask, the positions of its set bits, lowest first, one per byte (the rest 0).
struct CompactionTable {
  alignas(64) uint8_t rows[256][8];
  constexpr CompactionTable() : rows{} {
    for (uint32_t m = 0; m < 256; ++m) {
      uint32_t k = 0;
      for (uint32_t b = 0; b < 8; ++b)
        if (m & (1u << b)) rows[m][k++] = uint8_t(b);
    }
  }
};
constexpr CompactionTable kCompaction{};
#endif

#if defined(__AVX2__)
// Of the children entered (the bits of `mask`, two or more), the one with the largest entry
// distance (the lowest slot of those tied): where an any-hit ray from its far end goes first
// in the compacting kernels (see order_children).
inline __attribute__((always_inline)) uint32_t entered_last(uint32_t mask, const float* tnear) {
  const __m256 tn = _mm256_load_ps(tnear);
#if defined(__AVX512VL__)
  const __m256 m = _mm256_mask_blend_ps(__mmask8(mask), _mm256_set1_ps(-kInfinity), tn);
#else
  const __m256i bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  const __m256i sel = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(mask)), bits), bits);
  const __m256 m = _mm256_blendv_ps(_mm256_set1_ps(-kInfinity), tn, _mm256_castsi256_ps(sel));
#endif
  __m256 top = _mm256_max_ps(m, _mm256_permute_ps(m, 0xb1));
  top = _mm256_max_ps(top, _mm256_permute_ps(top, 0x4e));
  top = _mm256_max_ps(top, _mm256_permute2f128_ps(top, top, 1));
  return lowest_bit(uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(m, top, _CMP_EQ_OQ))) & mask);
}
#endif

// Two or more children entered (the bits of `mask`): the nearest is returned as the next
// node, the others go on the stack farthest first, so the next pop is the next nearest.
//
// In the compacting kernels (incoherent batches, bvh8, AVX2 and AVX-512) an any-hit ray
// from its far end (far_end_first) instead goes first into the child it enters last, by the
// entry distances, and stacks the rest in its flipped octant's order. The octant's order
// sorts children along the diagonal of the ray's octant, a guess that fails for rays far
// from it: classroom's AO rays (from a camera inside the room, mostly near-vertical, 96 %
// blocked by the floor or the ceiling) took 4.4 wide nodes a ray on the baked tree walking
// that order from the far end, 2.9 this way (0.66 -> 1.02 of Embree's rtcOccluded1). The
// walk below keeps the octant's order: there the rule cost coherent shadow rays 10-20 %
// (the CPU no longer fetched the next child on a predicted branch), and sorting every
// entered child by distance had cost shadow rays 15-20 % (docs/wide-bvh.md).
template <uint32_t W, NearFirst kOrder, bool kCompact>
inline __attribute__((always_inline)) uint32_t order_children(const typename WideNode<W>::Node& n, uint32_t octant,
                                                              uint32_t mask, const float* tnear, Stack& stack,
                                                              bool far_end_first) {
  if constexpr (kOrder == NearFirst::distance_sort) {
    // Insertion into the stack top, kept sorted with the nearest on top.
    const uint32_t base = stack.size;
    for (; mask; mask &= mask - 1) {
      const uint32_t c = lowest_bit(mask);
      const uint32_t word = n.child[c];
      const float t = tnear[c];
      uint32_t i = stack.size++;
      while (i > base && stack.t[i - 1] < t) {
        stack.words[i] = stack.words[i - 1];
        stack.t[i] = stack.t[i - 1];
        --i;
      }
      stack.words[i] = word;
      stack.t[i] = t;
    }
    return stack.words[--stack.size];
  } else {
#if defined(__AVX512VL__)
    if constexpr (W == 8 && kCompact) {
      // The octant's order, farthest first, permutes children, distances and the entered
      // mask; compression packs the entered ones; one store pushes them all. No branch, so
      // nothing to mispredict on incoherent rays; but the next node's address waits for the
      // whole chain, where the walk below lets a predicted branch fetch it early (Zen 4, bvh8,
      // 1 thread: random rays 1-13 % faster this way on 10 of 11 scenes, primary rays 9-25 %
      // slower on the 4 measured). trace_all picks by the batch's coherence.
      const __m256i shifts = _mm256_setr_epi32(21, 18, 15, 12, 9, 6, 3, 0);
      const __m256i far_first =
          _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(int(n.octant_order[octant])), shifts), _mm256_set1_epi32(7));
      uint32_t first = 0;
      if (far_end_first) {
        first = entered_last(mask, tnear);
        mask &= ~(1u << first);
      }
      const __mmask8 entered = _mm256_movepi32_mask(_mm256_permutexvar_epi32(far_first, _mm256_movm_epi32(__mmask8(mask))));
      const __m256i words = _mm256_maskz_compress_epi32(
          entered, _mm256_permutexvar_epi32(far_first, _mm256_load_si256(reinterpret_cast<const __m256i*>(n.child))));
      const __m256 dist = _mm256_maskz_compress_ps(entered, _mm256_permutexvar_ps(far_first, _mm256_load_ps(tnear)));
      const uint32_t count = uint32_t(__builtin_popcount(entered));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack.words + stack.size), words);
      _mm256_storeu_ps(stack.t + stack.size, dist);
      if (far_end_first) {
        stack.size += count;
        return n.child[first];
      }
      stack.size += count - 1;
      return uint32_t(_mm_cvtsi128_si32(
          _mm256_castsi256_si128(_mm256_permutexvar_epi32(_mm256_set1_epi32(int(count - 1)), words))));
    }
#elif defined(__AVX2__)
    if constexpr (W == 8 && kCompact) {
      // The same without a compress instruction: the entered flags in the octant's order pick
      // a row of kCompaction (the entered positions, packed), which composed with the order
      // gives one permutation of children and distances (armadillo, 1 thread, AVX2 kernel:
      // random rays +28 %, AO +4 % against the walk; random rays now at 0.97 of the AVX-512
      // kernel, from 0.76).
      const __m256i shifts = _mm256_setr_epi32(21, 18, 15, 12, 9, 6, 3, 0);
      const __m256i far_first =
          _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(int(n.octant_order[octant])), shifts), _mm256_set1_epi32(7));
      uint32_t first = 0;
      if (far_end_first) {
        first = entered_last(mask, tnear);
        mask &= ~(1u << first);
      }
      const __m256i flags = _mm256_slli_epi32(_mm256_srlv_epi32(_mm256_set1_epi32(int(mask)), far_first), 31);
      const uint32_t entered = uint32_t(_mm256_movemask_ps(_mm256_castsi256_ps(flags)));
      const __m256i packed =
          _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(kCompaction.rows[entered])));
      const __m256i pick = _mm256_permutevar8x32_epi32(far_first, packed);
      const __m256i words = _mm256_permutevar8x32_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(n.child)), pick);
      const __m256 dist = _mm256_permutevar8x32_ps(_mm256_load_ps(tnear), pick);
      const uint32_t count = uint32_t(__builtin_popcount(entered));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack.words + stack.size), words);
      _mm256_storeu_ps(stack.t + stack.size, dist);
      if (far_end_first) {
        stack.size += count;
        return n.child[first];
      }
      stack.size += count - 1;
      return stack.words[stack.size];
    }
#endif
    // Walk the octant's order from the far end, pushing the entered children; the last one
    // pushed is the nearest, taken straight back off.
    const uint32_t order = WideNode<W>::order(n, octant);
    for (uint32_t k = W; k-- > 0;) {
      const uint32_t c = (order >> (WideNode<W>::kBits * k)) & (W - 1);
      if (mask & (1u << c)) stack.push(n.child[c], tnear[c]);
    }
    return stack.words[--stack.size];
  }
}

// Two or more children entered, or one (the bits of `mask`, not 0), for a ray that will
// most likely hit nothing: the lowest entered slot is returned as the next node, the rest go
// on the stack in slot order, with no ordering by the ray at all. A ray that hits nothing
// visits every box it enters whatever the order, so for it the near-first order is work
// without use; without it, and without the branch on how many children were entered (the
// CPU mispredicts it on incoherent rays), the next node's address is known a few
// instructions after the slab test. Every ISA pushes the same entries in the same order, so
// the visits and the counted work are the same on each. See trace_range for when it is used.
template <uint32_t W>
inline __attribute__((always_inline)) uint32_t enter_in_slot_order(const std::byte* arena,
                                                                   const typename WideNode<W>::Node& n,
                                                                   uint32_t mask, const float* tnear, Stack& stack) {
  const uint32_t rest = mask & (mask - 1);
#if defined(__AVX2__)
  if constexpr (W == 8) {
#if defined(__AVX512VL__)
    const __m256i words =
        _mm256_maskz_compress_epi32(__mmask8(rest), _mm256_load_si256(reinterpret_cast<const __m256i*>(n.child)));
    const __m256 dist = _mm256_maskz_compress_ps(__mmask8(rest), _mm256_load_ps(tnear));
#else
    const __m256i pick = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(kCompaction.rows[rest])));
    const __m256i words = _mm256_permutevar8x32_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(n.child)), pick);
    const __m256 dist = _mm256_permutevar8x32_ps(_mm256_load_ps(tnear), pick);
#endif
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack.words + stack.size), words);
    _mm256_storeu_ps(stack.t + stack.size, dist);
    stack.size += uint32_t(__builtin_popcount(rest));
  } else
#endif
  {
    for (uint32_t m = rest; m; m &= m - 1) {
      const uint32_t c = lowest_bit(m);
      stack.push(n.child[c], tnear[c]);
    }
  }
  // The next pop, the highest slot pushed; with none pushed, slot 0's child, which the next
  // rays of the batch (an AO batch's share their origin) may enter. Asked for the root's
  // lines there instead (a select), the closed meshes' AO rays gained 0-2 % from the slot
  // order instead of 5-10 % (Zen 5, two runs in turn).
  prefetch_unit(arena, n.child[31 - __builtin_clz(rest | 1u)]);
  return n.child[lowest_bit_index(mask)];
}

// The blocks of one leaf; whether any gave a closer hit (any hit at all, for any-hit).
// kPairs: Moller-Trumbore blocks two at a time, where it pays: single rays of incoherent
// batches (AO +1 to 3 %), and any-hit rays there in the slot order, which mostly hit nothing
// (occlusion rays off the closed meshes +3 to 6 %; in the usual order it cost classroom's,
// 96 % blocked, 3-7 %); in the coherent walk it cost camera rays 1-2 %, in the side-by-side
// kernel random rays 2-3 %. kAny: stops at the first block with a hit, since any hit ends an
// any-hit ray; `tests` counts the triangles of the blocks tested.
template <TriangleTest kTest, bool kPairs = false, bool kAny = false>
inline __attribute__((always_inline)) bool test_leaf(const std::byte* arena, uint32_t word, const KernelRay& r,
                                                     BestHit& best, uint32_t& tests) {
  const TriangleBlock* blocks = at_unit<TriangleBlock>(arena, word);
  const uint32_t count = ((word >> 27) & 15u) + 1;
  if constexpr (!kAny) tests += 4 * count;
  bool found = false;
  uint32_t i = 0;
#if defined(__AVX2__)
  if constexpr (kPairs && kTest == TriangleTest::moller_trumbore) {
    for (; i + 1 < count; i += 2) {
      const uint32_t hit = block_pair_moller_trumbore(blocks + i, r, best);
      if constexpr (kAny) {
        // Counted as a block at a time would have: up to the first block that hits, so
        // every kernel counts the same work.
        if (hit != 0) {
          tests += 4 * (i + ((hit & 1u) ? 1 : 2));
          return true;
        }
      } else {
        found |= hit != 0;
      }
    }
  }
#endif
  for (; i < count; ++i) {
    found |= kTest == TriangleTest::watertight ? block_watertight(blocks[i], r, best)
                                               : block_moller_trumbore(blocks[i], r, best);
    if constexpr (kAny) {
      if (found) {
        tests += 4 * (i + 1);
        return true;
      }
    }
  }
  if constexpr (kAny) tests += 4 * count;
  return found;
}

// What visit_node and pop_next return when there is nothing to visit. It has the leaf flag
// set, so a loop over inner nodes stops at it without a test of its own.
constexpr uint32_t kNoWord = kWideEmptyChild;

// The operands traverse hands the slab test: the ray's broadcast once (bvh8 with AVX2 or
// AVX-512), else the ray itself.
template <uint32_t W>
inline __attribute__((always_inline)) auto slab_operands(const KernelRay& r) {
#if defined(__AVX2__)
  if constexpr (W == 8) return SlabRay8(r);
  else
#endif
    return r;
}

// One inner node: pushes the entered children but the nearest, which it returns (kNoWord
// when the ray enters none). `slab`: r's slab_operands, or r itself. far_end_first: an
// any-hit ray searching from its far end (AnyHitOrder::far_first, its octant then flipped;
// see order_children); a parameter rather than a KernelRay field, so that the closest-hit
// kernels, which pass the constant false (inlined, the rule compiles away), keep their ray
// as it was.
template <uint32_t W, NearFirst kOrder, bool kCompact, bool kSlotOrder = false, class Slab, class Limit>
inline __attribute__((always_inline)) uint32_t visit_node(const std::byte* arena, uint32_t word, const KernelRay& r,
                                                          const Slab& slab, Limit limit, Stack& stack,
                                                          bool far_end_first) {
  using Node = typename WideNode<W>::Node;
  const Node& n = *at_inner_unit<Node>(arena, word);
  // The layout puts a node's leaf blocks right after it, then its first inner child:
  // asked for now, their fetch overlaps the node's own (armadillo, 1 thread: random rays
  // +10 %, AO +4 %, primary unchanged; two lines did better than four).
  const char* after = reinterpret_cast<const char*>(&n + 1);
  _mm_prefetch(after, _MM_HINT_T0);
  _mm_prefetch(after + 64, _MM_HINT_T0);
  alignas(32) float tnear[W];
  const uint32_t mask = slab_test(n.bounds, slab, limit, tnear);
  if (mask == 0) return kNoWord;
  if constexpr (kSlotOrder) return enter_in_slot_order<W>(arena, n, mask, tnear, stack);
  if ((mask & (mask - 1)) == 0) return n.child[lowest_bit_index(mask)];  // one child: no stack traffic
  const uint32_t next = order_children<W, kOrder, kCompact>(n, r.octant, mask, tnear, stack, far_end_first);
  // The next nearest child, pushed just now: popped as soon as the nearest one's subtree is
  // done, often after a step or two in a wide tree.
  prefetch_unit(arena, stack.words[stack.size - 1]);
  return next;
}

// The next stack entry not beyond the closest hit (entries pushed before a closer hit was
// found may now lie beyond it); kNoWord once the stack is empty.
inline __attribute__((always_inline)) uint32_t pop_next(Stack& stack, float limit) {
  while (stack.size != 0) {
    --stack.size;
    if (stack.t[stack.size] <= limit) return stack.words[stack.size];
  }
  return kNoWord;
}

inline void store_hit(const BestHit& best, bool found, Hit& out) {
  out = Hit{};
  if (found) {
    out.t = best.t;
    out.u = best.u;
    out.v = best.v;
    out.triangle_id = best.id;
  }
}

inline float initial_limit(const Ray& ray) { return ray.tmax < kLargest ? ray.tmax : kLargest; }

template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kAny, bool kCompact, bool kSlotOrder = false>
inline __attribute__((always_inline)) bool traverse(const std::byte* arena, uint32_t root, Stack stack, const Ray& ray,
                                                    Hit& out, TraceCounters& counters, uint32_t any_octant_flip) {
  KernelRay r = make_ray<kTest>(ray);
  if constexpr (kAny) r.octant ^= any_octant_flip;
  const bool far_end_first = kAny && any_octant_flip != 0;
  const auto slab = slab_operands<W>(r);
  BestHit best;
  best.t = initial_limit(ray);
  auto limit = node_limit<W>(best.t);
  uint32_t steps = 0, tests = 0;
  bool found = false;
  uint32_t word = root;
  for (;;) {
    while (!(word & kWideLeafFlag)) {
      ++steps;
      word = visit_node<W, kOrder, kCompact, kSlotOrder>(arena, word, r, slab, limit, stack, far_end_first);
    }
    if (word != kNoWord) {
      ++steps;
      // The stack top is what comes after this leaf unless the leaf hits nearer: its fetch
      // overlaps the triangle tests.
      if (stack.size != 0) prefetch_unit(arena, stack.words[stack.size - 1]);
      // Blocks in pairs for any-hit rays only in the slot order, whose rays mostly hit
      // nothing: a blocked ray stops at the first block that hits, and tested in pairs it
      // pays for the second too (test_leaf).
      const bool hit = test_leaf<kTest, kCompact && (!kAny || kSlotOrder), kAny>(arena, word, r, best, tests);
      found |= hit;
      if (kAny && hit) goto done;
      if (hit) limit = node_limit<W>(best.t);
    }
    // pop_next written out: with its kNoWord and a test of it here, AO rays ran 2 % slower
    // and classroom's random rays 5 %.
    for (;;) {
      if (stack.size == 0) goto done;
      --stack.size;
      // Entries pushed before a closer hit was found may now lie beyond it.
      if (stack.t[stack.size] <= best.t) {
        word = stack.words[stack.size];
        break;
      }
    }
  }
done:
  counters.steps += steps;
  counters.triangle_tests += tests;
  store_hit(best, found, out);
  return found;
}

// Several rays traced side by side, a node or leaf of each in turn (K lanes, each with its
// own stack). One ray's traversal is a chain of dependent loads, each node's address known
// only when its parent's slab test is done, so on incoherent rays a core mostly waits; with
// the next node of every lane asked for as soon as it is known, K fetches are in flight at
// once. Every ray visits the same nodes in the same order as alone, so hits and counted work
// are those of traverse.
// The lane count is a run-time loop bound, not a template argument: unrolled for 8 and 16
// lanes, the side-by-side kernels grew the translation unit enough to cost the one-ray
// kernels 2-3 % (AO rays, armadillo) through code placement.
template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kAny, bool kCompact>
void trace_interleaved(const Batch& b) {
  struct Lane {
    KernelRay r;
    BestHit best;
    Stack stack;
    uint32_t word;
    size_t ray;
    bool found;
  };
  const uint32_t K = b.lanes < kMaxLanes ? b.lanes : kMaxLanes;
  Lane lanes[kMaxLanes];
  uint32_t steps = 0, tests = 0;
  size_t next_ray = 0;
  // Puts the next ray of the batch in a lane; false when none is left.
  auto start = [&](Lane& l) {
    if (next_ray == b.count) return false;
    const Ray& ray = b.rays[next_ray];
    l.r = make_ray<kTest>(ray);
    if constexpr (kAny) l.r.octant ^= b.any_octant_flip;
    l.best = BestHit{};
    l.best.t = initial_limit(ray);
    l.stack.size = 0;
    l.word = b.root;
    l.ray = next_ray++;
    l.found = false;
    return true;
  };
  uint32_t live = 0;
  for (uint32_t k = 0; k < K; ++k) {
    lanes[k].stack = Stack{b.stack_words + size_t(k) * b.stack_stride, b.stack_t + size_t(k) * b.stack_stride};
    if (start(lanes[k])) live |= 1u << k;
  }
  while (live) {
    for (uint32_t k = 0; k < K; ++k) {
      if (!(live & (1u << k))) continue;
      Lane& l = lanes[k];
      ++steps;
      uint32_t next;
      if (!(l.word & kWideLeafFlag)) {
        // The ray's own scalars, broadcast per node (see SlabRay8).
        next = visit_node<W, kOrder, kCompact>(b.arena, l.word, l.r, l.r, l.best.t, l.stack,
                                                      kAny && b.any_octant_flip != 0);
        if (next == kNoWord) next = pop_next(l.stack, l.best.t);
      } else {
        const bool hit = test_leaf<kTest, false, kAny>(b.arena, l.word, l.r, l.best, tests);
        l.found |= hit;
        next = kAny && hit ? kNoWord : pop_next(l.stack, l.best.t);
      }
      if (next == kNoWord) {
        if (kAny)
          b.any_hits[l.ray] = l.found ? 1 : 0;
        else
          store_hit(l.best, l.found, b.hits[l.ray]);
        if (!start(l)) {
          live &= ~(1u << k);
          continue;
        }
        next = l.word;
      }
      l.word = next;
      // Wanted when this lane's turn comes again, after the other lanes' steps.
      prefetch_unit(b.arena, next);
    }
  }
  b.counters->steps += steps;
  b.counters->triangle_tests += tests;
}

// The rays of an incoherent batch go in runs of kOrderRun: the first in the usual order
// (closest hit: nearest first; any hit: as AnyHitOrder asks), each after it in slot order
// (enter_in_slot_order) while at most one ray in kMissingShare of those traced so far in the
// batch hit anything and they took kMinSlotOrderSteps steps a ray or more. A ray that hits
// nothing visits the same boxes in any order, so the ordering only pays on the rays that
// hit: ambient occlusion rays off the closed meshes, 2-7 % of them blocked, and rays leaving
// a scene. Rays that take few steps enter few nodes with several children, where the
// ordering costs little, and the one-child path's branch, which the slot order does not
// take, is well predicted there: staircase's AO rays (2.4 steps a ray, 1.4 % blocked) ran
// at about 0.8 of their nearest-first speed in slot order (docs/wide-bvh.md). The choice
// depends on the hits and the counted steps alone, which are exact and the same on every ISA
// for the same order, so every ISA and thread count makes it alike (but for any-hit rays
// from the far end, whose order differs between the SSE kernel and the compacting ones; see
// order_children).
constexpr size_t kOrderRun = 32;
constexpr size_t kMissingShare = 8;
constexpr uint64_t kMinSlotOrderSteps = 4;

// Rays [begin, end) of the batch, one after the other, for the query the batch holds; how
// many hit. A function of its own for each order: with both traversals inlined into one
// loop, the closed meshes' AO rays lost what the slot order gains (one run: 7-11 % slower
// than the slot order throughout on beast, bunny, horse and nefertiti, whose AO rays hit
// 2-6 % of the time).
template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kCompact, bool kAny, bool kSlotOrder>
__attribute__((noinline)) size_t trace_run(const Batch& b, size_t begin, size_t end) {
  TraceCounters& c = *b.counters;
  const Stack stack{b.stack_words, b.stack_t};
  size_t hit = 0;
  if constexpr (kAny) {
    Hit unused;
    for (size_t i = begin; i < end; ++i) {
      const bool found =
          traverse<W, kTest, kOrder, true, kCompact, kSlotOrder>(b.arena, b.root, stack, b.rays[i], unused, c, b.any_octant_flip);
      b.any_hits[i] = found ? 1 : 0;
      hit += found;
    }
  } else {
    for (size_t i = begin; i < end; ++i)
      hit += traverse<W, kTest, kOrder, false, kCompact, kSlotOrder>(b.arena, b.root, stack, b.rays[i], b.hits[i], c, 0);
  }
  return hit;
}

// Rays [begin, end) in runs, each run's order chosen as above.
template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kCompact, bool kAny>
void trace_adaptive(const Batch& b, size_t begin, size_t end) {
  size_t hit = 0;
  uint64_t steps = 0;
  for (size_t run = begin; run < end; run += kOrderRun) {
    const size_t stop = end - run < kOrderRun ? end : run + kOrderRun;
    const uint64_t traced = run - begin;
    // The first run in the usual order: nothing is known yet.
    const bool slot_order = traced != 0 && hit * kMissingShare <= traced && steps >= kMinSlotOrderSteps * traced;
    const uint32_t steps_before = b.counters->steps;
    hit += slot_order ? trace_run<W, kTest, kOrder, kCompact, kAny, true>(b, run, stop)
                      : trace_run<W, kTest, kOrder, kCompact, kAny, false>(b, run, stop);
    steps += uint32_t(b.counters->steps - steps_before);
  }
}

// Rays [begin, end) of the batch, one after the other.
template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kCompact>
void trace_range(const Batch& b, size_t begin, size_t end) {
  TraceCounters& c = *b.counters;
  const Stack stack{b.stack_words, b.stack_t};
  if (b.slot_order_when_missing && !b.coherent && kOrder == NearFirst::octant_order) {
    if (b.hits)
      trace_adaptive<W, kTest, kOrder, kCompact, false>(b, begin, end);
    else
      trace_adaptive<W, kTest, kOrder, kCompact, true>(b, begin, end);
    return;
  }
  if (b.hits) {
    for (size_t i = begin; i < end; ++i)
      traverse<W, kTest, kOrder, false, kCompact>(b.arena, b.root, stack, b.rays[i], b.hits[i], c, 0);
  } else {
    Hit h;
    for (size_t i = begin; i < end; ++i)
      b.any_hits[i] =
          traverse<W, kTest, kOrder, true, kCompact>(b.arena, b.root, stack, b.rays[i], h, c, b.any_octant_flip) ? 1 : 0;
  }
}

// More lanes, more fetches in flight: against 4 lanes, 16 traced random rays 2-5 % faster
// (bvh8, 1 thread: bunny, ogre, staircase, Sponza, Conference; classroom level).
template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kCompact, bool kAny>
void trace_lanes(const Batch& b) {
  trace_interleaved<W, kTest, kOrder, kAny, kCompact>(b);
}

// Rays of a scattered batch that take only a few steps each gain nothing from being traced
// side by side and pay for the lanes' bookkeeping (random rays, 1 thread, 4 lanes:
// classroom's, 1.7 steps each, mostly starting outside the building, 7 % slower;
// Conference's, 4.5 steps, 1-4 % slower; the scanned meshes' and Sponza's, 6-10 steps, 9-31 %
// faster). The batch's first rays, traced one at a time, tell which kind it holds. With 16
// lanes batches of 3 steps a ray and more gain too: against the 5 needed with 4 lanes,
// Conference +3.5 %, staircase +4 %, classroom level (2 steps: classroom -2 %).
constexpr size_t kProbeRays = 16;
constexpr uint32_t kMinStepsSideBySide = 3;

template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kCompact>
void trace_each(const Batch& b) {
  if (b.lanes < 2) {
    trace_range<W, kTest, kOrder, kCompact>(b, 0, b.count);
    return;
  }
  const size_t probe = b.count < kProbeRays ? b.count : kProbeRays;
  const uint32_t steps_before = b.counters->steps;
  trace_range<W, kTest, kOrder, kCompact>(b, 0, probe);
  if (uint32_t(b.counters->steps - steps_before) < kMinStepsSideBySide * uint32_t(probe)) {
    trace_range<W, kTest, kOrder, kCompact>(b, probe, b.count);
    return;
  }
  Batch rest = b;
  rest.rays += probe;
  rest.count -= probe;
  if (rest.hits) {
    rest.hits += probe;
    trace_lanes<W, kTest, kOrder, kCompact, false>(rest);
  } else {
    rest.any_hits += probe;
    trace_lanes<W, kTest, kOrder, kCompact, true>(rest);
  }
}

template <uint32_t W, TriangleTest kTest, NearFirst kOrder>
void trace_all(const Batch& b) {
#if defined(__AVX2__)
  // Compaction only where it pays: octant order, 8 wide, incoherent rays.
  if constexpr (W == 8 && kOrder == NearFirst::octant_order) {
    if (!b.coherent) {
      trace_each<W, kTest, kOrder, true>(b);
      return;
    }
  }
#endif
  trace_each<W, kTest, kOrder, false>(b);
}

template <uint32_t W, TriangleTest kTest>
void trace_order(const Batch& b) {
  if (b.near_first == NearFirst::distance_sort)
    trace_all<W, kTest, NearFirst::distance_sort>(b);
  else
    trace_all<W, kTest, NearFirst::octant_order>(b);
}

template <uint32_t W>
void trace_test(const Batch& b) {
  if (b.test == TriangleTest::watertight)
    trace_order<W, TriangleTest::watertight>(b);
  else
    trace_order<W, TriangleTest::moller_trumbore>(b);
}

inline void trace_batch(const Batch& b) {
  if (b.width == 4)
    trace_test<4>(b);
  else
    trace_test<8>(b);
}

// One ray on its own, the per-ray entry points' path: no batch to set up and no choice to
// make per call (the tracer picks this instantiation once), the stack in this frame. A batch
// of one ray takes the same path through the tree (the walk in the octant's order, as for a
// coherent batch), so hits and counted work are the same; it only skips the batch's set-up,
// which cost about 20 ns a call (staircase's ambient occlusion rays, bvh8, 1 thread: 24
// Mrays/s traced one call a ray against 46 in calls of thousands).
template <uint32_t W, TriangleTest kTest, NearFirst kOrder, bool kAny>
bool trace_one(const std::byte* arena, uint32_t root, const Ray& ray, Hit& hit, TraceCounters& counters,
               uint32_t any_octant_flip) {
  alignas(64) uint32_t words[kOneRayStackEntries];
  alignas(64) float t[kOneRayStackEntries];
  return traverse<W, kTest, kOrder, kAny, false>(arena, root, Stack{words, t}, ray, hit, counters, any_octant_flip);
}

template <uint32_t W, TriangleTest kTest, NearFirst kOrder>
OneRayFn pick_one(bool any) {
  return any ? &trace_one<W, kTest, kOrder, true> : &trace_one<W, kTest, kOrder, false>;
}

template <uint32_t W, TriangleTest kTest>
OneRayFn pick_one(NearFirst order, bool any) {
  return order == NearFirst::distance_sort ? pick_one<W, kTest, NearFirst::distance_sort>(any)
                                           : pick_one<W, kTest, NearFirst::octant_order>(any);
}

template <uint32_t W>
OneRayFn pick_one(TriangleTest test, NearFirst order, bool any) {
  return test == TriangleTest::watertight ? pick_one<W, TriangleTest::watertight>(order, any)
                                          : pick_one<W, TriangleTest::moller_trumbore>(order, any);
}

inline OneRayFn one_ray_kernel(uint32_t width, TriangleTest test, NearFirst order, bool any) {
  return width == 4 ? pick_one<4>(test, order, any) : pick_one<8>(test, order, any);
}

}  // namespace
}  // namespace bvhopt::wide_kernels
