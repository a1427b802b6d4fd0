// The watertight ray-triangle test (Woop, Benthin and Wald 2013).
#include "bvhopt/ray_triangle.h"

#include <cmath>
#include <utility>

#include "trace/watertight_test.h"

namespace bvhopt {

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

bool intersect_triangle(const WatertightRay& r, const float* v0, const float* v1, const float* v2, Hit& hit) {
  return detail::watertight_test(r, v0, v1, v2, hit);
}

bool intersect_triangle(const Ray& ray, const Triangle& tri, Hit& hit) {
  const WatertightRay r(ray);
  const float a[3] = {tri.v0.x, tri.v0.y, tri.v0.z};
  const float b[3] = {tri.v1.x, tri.v1.y, tri.v1.z};
  const float c[3] = {tri.v2.x, tri.v2.y, tri.v2.z};
  return intersect_triangle(r, a, b, c, hit);
}

}  // namespace bvhopt
