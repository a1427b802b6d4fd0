// The watertight ray-triangle test every tracer and oracle uses.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "bvhopt/ray.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

// The power of two that brings a direction's largest component to [0.5, 1) (1 for a zero
// or non-finite one). The Moller-Trumbore tests run on the direction times it and multiply
// the distance back: exact, and their products then stay within float range for any
// direction length (wide_kernel.h says why).
// Inlined by force: the wide kernels call it once per ray, compiled for AVX2 or AVX-512, and
// an out-of-line copy would be shared by every caller (the linker keeps one), so one compiled
// with AVX-512 could be the copy that a baseline caller runs (tests/check_isa_confinement.py
// catches that). It was not inlined once the side-by-side kernels grew, and the call cost
// camera rays 3-5 %.
inline __attribute__((always_inline)) float mt_direction_scale(float largest_component) {
  // Every ray pays this once, so no library calls (frexp/ldexp were 3-4 % of a wide traversal
  // of cheap random rays) and no branch (a branch here moved the kernels' code enough to cost
  // camera or AO rays 2-3 %): the answer is read from the exponent bits. x = m * 2^(b - 127)
  // with m in [1, 2) is 0.5m * 2^(b - 126), so frexp's exponent is b - 126 and the result
  // 2^(126 - b), whose biased exponent is 253 - b. That holds for biased exponents b from 0
  // (subnormals: frexp's exponent is then below -126 and clamped to it, giving 2^126) to 252;
  // 253 and 254 clamp to 2^-127, a subnormal; zero, infinities, NaN and negative values
  // (whose sign bit makes b 256 or more) give 1.
  const uint32_t bits = __builtin_bit_cast(uint32_t, largest_component);
  const uint32_t biased = bits >> 23;
  uint32_t result = (253u - (biased < 252u ? biased : 252u)) << 23;
  result = biased == 253u || biased == 254u ? 0x00400000u : result;
  result = bits == 0u || biased >= 255u ? 0x3f800000u : result;
  return __builtin_bit_cast(float, result);
}

// Woop, Benthin and Wald (2013), "Watertight ray/triangle intersection": the triangle is
// sheared into the ray's space and tested with edge functions that are exact for shared
// edges (recomputed in double when one is zero), so a ray through an edge or vertex shared
// by two triangles never slips between them. On success fills t, u, v of `hit` (not the
// id) and returns true; hits only with t in [ray.tmin, ray.tmax] and t < hit.t.
// Triangles with coincident corners are never hit; a collinear one only by a ray through
// its segment (the shear rounds), with t only roughly the segment's distance.
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

}  // namespace bvhopt
