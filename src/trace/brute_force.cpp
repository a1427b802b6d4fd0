// The brute-force oracle: every triangle, in id order, through the same watertight test.
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

}  // namespace bvhopt
