// The watertight ray-triangle test on its own: shared edges and vertices, rays in or parallel
// to a triangle's plane, zero-area triangles.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "bvhopt/ray_triangle.h"

namespace bvhopt {
namespace {

Vec3 lerp(const Vec3& a, const Vec3& b, float s) { return a + (b - a) * s; }

Ray ray_towards(const Vec3& from, const Vec3& to) {
  Ray r;
  r.org = from;
  r.dir = to - from;
  return r;
}

bool hits(const Ray& ray, const Triangle& tri) {
  Hit h;
  return intersect_triangle(ray, tri, h);
}

// The scale is read from the float's bits on the fast path; it must be the power of two
// frexp and ldexp give, for every exponent (subnormal, the two ends of the range) and for
// the values that take no scale at all.
TEST(RayTriangle, DirectionScaleIsThePowerOfTwoFrexpGives) {
  const auto reference = [](float x) {
    if (!(x > 0.0f) || !std::isfinite(x)) return 1.0f;
    int e = 0;
    std::frexp(x, &e);
    return std::ldexp(1.0f, -std::clamp(e, -126, 127));
  };
  std::mt19937 rng(7);
  size_t checked = 0;
  for (uint32_t biased = 0; biased < 256; ++biased)
    for (uint32_t mantissa : {0u, 1u, 0x400000u, 0x7fffffu, uint32_t(rng() & 0x7fffffu), uint32_t(rng() & 0x7fffffu)})
      for (uint32_t sign : {0u, 1u}) {
        const float x = __builtin_bit_cast(float, (sign << 31) | (biased << 23) | mantissa);
        const float got = mt_direction_scale(x), want = reference(x);
        ASSERT_EQ(__builtin_bit_cast(uint32_t, got), __builtin_bit_cast(uint32_t, want)) << "x = " << x;
        if (x > 0.0f && std::isnormal(x) && std::isnormal(got)) {
          // The scaled value lands in [0.5, 1), the range the tests rely on.
          EXPECT_GE(x * got, 0.5f) << x;
          EXPECT_LT(x * got, 1.0f) << x;
        }
        ++checked;
      }
  EXPECT_EQ(checked, 256u * 6u * 2u);
}

TEST(RayTriangle, HitFillsDistanceAndBarycentrics) {
  const Triangle tri{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  Ray r = ray_towards({0.25f, 0.5f, 2.0f}, {0.25f, 0.5f, 0.0f});
  Hit h;
  ASSERT_TRUE(intersect_triangle(r, tri, h));
  EXPECT_FLOAT_EQ(h.t, 1.0f);
  EXPECT_FLOAT_EQ(h.u, 0.25f);
  EXPECT_FLOAT_EQ(h.v, 0.5f);
  EXPECT_FALSE(h.hit());  // the id is the caller's
  // Outside [tmin, tmax], or not closer than the hit so far: no hit, `hit` untouched.
  r.tmax = 0.99f;
  EXPECT_FALSE(hits(r, tri));
  r.tmax = 1.0f;
  EXPECT_TRUE(hits(r, tri));
  r.tmin = 1.01f;
  r.tmax = 10.0f;
  EXPECT_FALSE(hits(r, tri));
  r.tmin = 0.0f;
  Hit closer;
  closer.t = 0.5f;
  EXPECT_FALSE(intersect_triangle(r, tri, closer));
  EXPECT_EQ(closer.t, 0.5f);
  // From behind: both windings are hit.
  EXPECT_TRUE(hits(ray_towards({0.25f, 0.5f, -2.0f}, {0.25f, 0.5f, 0.0f}), tri));
}

// A closed fan of triangles around a centre, in a tilted plane in general position: every ray
// aimed at a shared edge, at the shared centre, or a few ulps beside an edge hits at least one
// of them, from origins on both sides and at grazing angles.
TEST(RayTriangle, SharedEdgesAndVerticesAreNeverMissed) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int rays = 0, misses = 0;
  for (int fan_seed = 0; fan_seed < 20; ++fan_seed) {
    const Vec3 centre{u(rng) * 10, u(rng) * 10, u(rng) * 10};
    const Vec3 e1 = Vec3{1.0f, 0.3f * u(rng), 0.7f * u(rng)} * (0.5f + u(rng) * u(rng) * 4);
    const Vec3 e2 = Vec3{0.4f * u(rng), 1.0f, 0.6f * u(rng)} * (0.5f + u(rng) * u(rng) * 4);
    const int sides = 3 + fan_seed % 6;
    std::vector<Vec3> ring;
    for (int k = 0; k < sides; ++k) {
      const float a = 6.2831853f * (float(k) + 0.3f * u(rng)) / float(sides);
      ring.push_back(centre + e1 * std::cos(a) + e2 * std::sin(a));
    }
    std::vector<Triangle> fan;
    for (int k = 0; k < sides; ++k) fan.push_back({centre, ring[k], ring[(k + 1) % sides]});
    auto any_hit = [&](const Ray& r) {
      for (const Triangle& t : fan)
        if (hits(r, t)) return true;
      return false;
    };
    for (int i = 0; i < 400; ++i) {
      const int k = i % sides;
      Vec3 target;
      switch (i % 4) {
        case 0: target = centre; break;
        case 1: target = lerp(centre, ring[k], 0.05f + 0.9f * (0.5f + 0.5f * u(rng))); break;
        case 2: target = lerp(ring[k], ring[(k + 1) % sides], 0.5f + 0.45f * u(rng));
                target = lerp(centre, target, 0.5f + 0.45f * u(rng)); break;
        default: {
          Vec3 p = lerp(centre, ring[k], 0.1f + 0.8f * (0.5f + 0.5f * u(rng)));
          for (int a = 0; a < 3; ++a) p[a] = std::nextafter(p[a], u(rng) < 0 ? -INFINITY : INFINITY);
          target = p;
        }
      }
      // Directions from steep to nearly in the plane, from both sides.
      const Vec3 normal = cross(e1, e2);
      const float lift = (i % 3 == 0 ? 0.02f : 1.0f) * (u(rng) < 0 ? -1.0f : 1.0f);
      const Vec3 from = target + normal * lift + e1 * (3 * u(rng)) + e2 * (3 * u(rng));
      ++rays;
      misses += !any_hit(ray_towards(from, target));
    }
  }
  EXPECT_EQ(misses, 0) << "of " << rays << " rays";
}

TEST(RayTriangle, RaysParallelToTheTriangleMiss) {
  const Triangle tri{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  for (const Vec3 dir : {Vec3{1, 0, 0}, Vec3{0, 1, 0}, Vec3{1, 1, 0}, Vec3{-1, 0.3f, 0}}) {
    for (const float z : {0.0f, 1e-7f, 1.0f, -1.0f}) {
      Ray r;
      r.org = Vec3{0.2f, 0.2f, z} - dir * 5.0f;  // passes through (or over) the interior
      r.dir = dir;
      EXPECT_FALSE(hits(r, tri)) << dir.x << "," << dir.y << " z " << z;
    }
  }
}

// Two coincident corners (or all three): never hit, whatever the ray.
TEST(RayTriangle, TrianglesWithCoincidentCornersAreNeverHit) {
  const Vec3 a{0.5f, -1.0f, 2.0f}, b{1.5f, 2.0f, -1.0f};
  const std::vector<Triangle> flat = {{a, a, b}, {a, b, b}, {b, a, b}, {a, a, a}};
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (size_t k = 0; k < flat.size(); ++k) {
    const Triangle& t = flat[k];
    for (int i = 0; i < 500; ++i) {
      const Vec3 target = i % 5 == 0 ? t.v0 : lerp(a, b, 0.5f + 0.5f * u(rng));
      const Vec3 from = target + Vec3{u(rng), u(rng), u(rng)} * 10.0f;
      EXPECT_FALSE(hits(ray_towards(from, target), t)) << "triangle " << k << " ray " << i;
    }
  }
}

// Three collinear corners (exactly, in float): the shear rounds, so a ray through the
// segment itself may be reported as a hit (t then within a few percent of the segment's
// distance: rounding decides it), but a ray that
// passes beside the segment or beyond its ends is never hit.
TEST(RayTriangle, CollinearTrianglesAreHitOnlyOnTheirSegment) {
  const Vec3 a{0.5f, -1.0f, 2.0f}, b{1.5f, 2.0f, -1.0f};
  const std::vector<Triangle> flat = {{a, b, lerp(a, b, 0.5f)}, {b, lerp(a, b, 0.25f), a}};
  const Vec3 side = normalize(cross(b - a, Vec3{0.3f, 1.0f, 0.2f})) * (1e-3f * length(b - a));
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int on_segment_hits = 0;
  for (size_t k = 0; k < flat.size(); ++k) {
    const Triangle& t = flat[k];
    for (int i = 0; i < 500; ++i) {
      const Vec3 on = lerp(a, b, 0.5f + 0.45f * u(rng));
      const Vec3 offset = Vec3{u(rng), u(rng), u(rng)} * 10.0f;
      Hit h;
      if (intersect_triangle(ray_towards(on + offset, on), t, h)) {
        ++on_segment_hits;
        EXPECT_NEAR(h.t, 1.0f, 0.1f) << "triangle " << k << " ray " << i;
      }
      const Vec3 beside = on + side * (u(rng) < 0 ? -1.0f : 1.0f);
      EXPECT_FALSE(hits(ray_towards(beside + offset, beside), t)) << "beside: triangle " << k << " ray " << i;
      const Vec3 beyond = lerp(a, b, u(rng) < 0 ? -0.01f - 0.5f * (1 + u(rng)) : 1.01f + 0.5f * (1 + u(rng)));
      EXPECT_FALSE(hits(ray_towards(beyond + offset, beyond), t)) << "beyond: triangle " << k << " ray " << i;
    }
  }
  EXPECT_LT(on_segment_hits, 1000);  // not every ray: these are rounding artefacts
}

}  // namespace
}  // namespace bvhopt
