// Rays and hits: what every ray set holds and every traversal returns.
#pragma once

#include <cstdint>
#include <limits>

#include "bvhopt/vec3.h"

namespace bvhopt {

inline constexpr uint32_t kNoHit = 0xffffffffu;

// A ray segment org + t * dir for t in [tmin, tmax]. dir need not be normalized but must
// be finite and non-zero; t is measured in units of dir. 32 bytes, the layout of ray files.
struct Ray {
  Vec3 org;
  float tmin = 0.0f;
  Vec3 dir{0.0f, 0.0f, 1.0f};
  float tmax = std::numeric_limits<float>::infinity();

  Vec3 at(float t) const { return org + dir * t; }
};
static_assert(sizeof(Ray) == 32);

// The closest hit: the triangle id (index into the Mesh) and its distance and barycentrics
// (the hit point is (1-u-v) v0 + u v1 + v v2). triangle_id == kNoHit for a miss.
struct Hit {
  float t = std::numeric_limits<float>::infinity();
  float u = 0.0f, v = 0.0f;
  uint32_t triangle_id = kNoHit;

  bool hit() const { return triangle_id != kNoHit; }
};

// What a ray asks: the closest hit along the segment, or only whether anything is hit.
enum class RayQuery : uint32_t { closest = 0, any = 1 };

}  // namespace bvhopt
