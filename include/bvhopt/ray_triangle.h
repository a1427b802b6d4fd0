// The watertight ray-triangle test every tracer and oracle uses.
#pragma once

#include <algorithm>
#include <cmath>

#include "bvhopt/ray.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

// The power of two that brings a direction's largest component to [0.5, 1) (1 for a zero
// or non-finite one). The Moller-Trumbore tests run on the direction times it and multiply
// the distance back: exact, and their products then stay within float range for any
// direction length (wide_kernel.h says why).
inline float mt_direction_scale(float largest_component) {
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
