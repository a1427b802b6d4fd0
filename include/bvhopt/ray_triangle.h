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
inline float mt_direction_scale(float largest_component) {
  // Every ray pays this once, and frexp/ldexp are library calls (3-4 % of a wide traversal
  // of cheap random rays): a normal float whose result is normal too is answered from its
  // exponent bits. x = m * 2^(b - 127) with m in [1, 2) is 0.5m * 2^(b - 126), so frexp's
  // exponent is b - 126 and the result 2^(126 - b), whose biased exponent is 253 - b.
  const uint32_t bits = __builtin_bit_cast(uint32_t, largest_component);
  const uint32_t biased = bits >> 23;  // the sign bit is above: negative values fail the range
  if (biased >= 2 && biased <= 252) return __builtin_bit_cast(float, (253u - biased) << 23);
  if (!(largest_component > 0.0f) || !std::isfinite(largest_component)) return 1.0f;
  int e = 0;
  std::frexp(largest_component, &e);
  return std::ldexp(1.0f, -std::clamp(e, -126, 127));
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
