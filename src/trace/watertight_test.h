// The body of intersect_triangle, inline so the tracers' leaf loops have no call in them.
#pragma once

#include "bvhopt/ray.h"
#include "bvhopt/ray_triangle.h"

namespace bvhopt::detail {

inline __attribute__((always_inline)) bool watertight_test(const WatertightRay& r, const float* v0, const float* v1,
                                                           const float* v2, Hit& hit) {
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
  // The distance from the normalized barycentrics: U * az is a cube of the scene's scale,
  // which overflows a float above coordinates of about 7e12 (and underflows below 1e-13).
  const float inv_det = 1.0f / det;
  const float u = U * inv_det, v = V * inv_det, w = W * inv_det;
  const float t = u * (r.shear_z * az) + v * (r.shear_z * bz) + w * (r.shear_z * cz);
  if (!(t >= r.tmin && t <= r.tmax && t < hit.t)) return false;
  hit.t = t;
  hit.u = v;
  hit.v = w;
  return true;
}

}  // namespace bvhopt::detail
