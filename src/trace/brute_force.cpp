// The brute-force oracles: every triangle, in id order, through the same triangle test as the
// tracer checked against (watertight for the binary tracer and wide option, Moller-Trumbore
// for the wide default).
#include "bvhopt/testing/brute_force.h"

#include <cmath>
#include <limits>

#include "bvhopt/ray_triangle.h"

namespace bvhopt {
namespace {
constexpr float kInf = std::numeric_limits<float>::infinity();
}  // namespace

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

bool intersect_triangle_mt(const Ray& ray, const Triangle& tri, Hit& hit) {
  const float t_scale =
      mt_direction_scale(std::max(std::fabs(ray.dir.x), std::max(std::fabs(ray.dir.y), std::fabs(ray.dir.z))));
  const Vec3 d = ray.dir * t_scale;
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
  if (flip) uu = -uu, vv = -vv;
  if (!(det != 0.0f && uu >= 0.0f && vv >= 0.0f && uu + vv <= adet)) return false;
  const float inv = 1.0f / adet;
  // e2 . (q / det), not (e2 . q) / det: e2 . q is a cube of the scene's scale and overflows
  // a float above coordinates of about 7e12.
  const float sinv = flip ? -inv : inv;
  const float t = (e2.x * (q.x * sinv) + e2.y * (q.y * sinv) + e2.z * (q.z * sinv)) * t_scale;
  if (!(t >= ray.tmin && t <= ray.tmax && t < hit.t)) return false;
  hit.t = t;
  hit.u = uu * inv;
  hit.v = vv * inv;
  return true;
}

namespace {

struct D3 {
  double x, y, z;
};
D3 widen(const Vec3& v) { return {v.x, v.y, v.z}; }
D3 operator-(const D3& a, const D3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
double dot(const D3& a, const D3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
D3 cross(const D3& a, const D3& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

// Sets t (in double) when the ray meets the triangle inside or on its edges.
bool intersect_double(const D3& org, const D3& dir, const Triangle& tri, double& t) {
  const D3 v0 = widen(tri.v0), e1 = widen(tri.v1) - v0, e2 = widen(tri.v2) - v0;
  const D3 p = cross(dir, e2);
  const double det = dot(e1, p);
  if (det == 0.0 || !std::isfinite(det)) return false;  // parallel, or a zero-area triangle
  const D3 s = org - v0;
  const double u = dot(s, p) / det;
  const D3 q = cross(s, e1);
  const double v = dot(dir, q) / det;
  if (!(u >= 0.0 && v >= 0.0 && u + v <= 1.0)) return false;
  t = dot(e2, q) / det;
  return true;
}

}  // namespace

Hit brute_force_closest_double(const Mesh& mesh, const Ray& ray) {
  const D3 org = widen(ray.org), dir = widen(ray.dir);
  double best = std::numeric_limits<double>::infinity();
  Hit hit;
  for (size_t i = 0; i < mesh.triangle_count(); ++i) {
    double t;
    if (!intersect_double(org, dir, mesh.triangle(i), t)) continue;
    if (!(t >= ray.tmin && t <= ray.tmax && t < best)) continue;
    best = t;
    hit.triangle_id = uint32_t(i);
  }
  hit.t = hit.hit() ? float(best) : kInf;
  return hit;
}

Hit brute_force_closest_mt(const Mesh& mesh, const Ray& ray) {
  Hit hit;
  hit.t = ray.tmax < kInf ? std::nextafter(ray.tmax, kInf) : kInf;
  for (size_t i = 0; i < mesh.triangle_count(); ++i)
    if (intersect_triangle_mt(ray, mesh.triangle(i), hit)) hit.triangle_id = uint32_t(i);
  if (!hit.hit()) hit.t = kInf;
  return hit;
}

}  // namespace bvhopt
