// The watertight ray-triangle test every tracer and oracle uses.
#pragma once

#include "bvhopt/ray.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

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
