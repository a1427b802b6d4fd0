// The scalar Moller-Trumbore oracle of the wide leaf blocks' default test.
#include <cmath>
#include <limits>

#include "bvhopt/wide_tracer.h"

namespace bvhopt {

Hit brute_force_closest_mt(const Mesh& mesh, const Ray& ray) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  Hit hit;
  hit.t = ray.tmax < kInf ? std::nextafter(ray.tmax, kInf) : kInf;
  const Vec3 d = ray.dir;
  for (size_t i = 0; i < mesh.triangle_count(); ++i) {
    const Triangle tri = mesh.triangle(i);
    // Spelled out in the kernel's order of operations (wide_kernel.h), so both round alike.
    const Vec3 e1 = tri.v1 - tri.v0, e2 = tri.v2 - tri.v0;
    const Vec3 p{d.y * e2.z - d.z * e2.y, d.z * e2.x - d.x * e2.z, d.x * e2.y - d.y * e2.x};
    const float det = e1.x * p.x + e1.y * p.y + e1.z * p.z;
    // The numerators with det's sign flipped into them, against |det|: one division, and
    // only for a ray inside the triangle (see block_moller_trumbore).
    const float adet = std::fabs(det);
    const bool flip = std::signbit(det);
    const Vec3 s = ray.org - tri.v0;
    float uu = s.x * p.x + s.y * p.y + s.z * p.z;
    const Vec3 q{s.y * e1.z - s.z * e1.y, s.z * e1.x - s.x * e1.z, s.x * e1.y - s.y * e1.x};
    float vv = d.x * q.x + d.y * q.y + d.z * q.z;
    float tt = e2.x * q.x + e2.y * q.y + e2.z * q.z;
    if (flip) uu = -uu, vv = -vv, tt = -tt;
    if (!(det != 0.0f && uu >= 0.0f && vv >= 0.0f && uu + vv <= adet)) continue;
    const float inv = 1.0f / adet;
    const float u = uu * inv, v = vv * inv, t = tt * inv;
    if (t >= ray.tmin && t < hit.t) {
      hit.t = t;
      hit.u = u;
      hit.v = v;
      hit.triangle_id = uint32_t(i);
    }
  }
  if (!hit.hit()) hit.t = kInf;
  return hit;
}

}  // namespace bvhopt
