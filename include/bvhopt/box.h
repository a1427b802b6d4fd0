// Axis-aligned bounding box and its surface area, the currency of every cost here.
#pragma once

#include <limits>

#include "bvhopt/vec3.h"

namespace bvhopt {

struct Box {
  // The default box is empty: min above max, so extending it by anything gives that thing.
  Vec3 min{std::numeric_limits<float>::infinity()};
  Vec3 max{-std::numeric_limits<float>::infinity()};

  constexpr Box() = default;
  constexpr Box(const Vec3& lo, const Vec3& hi) : min(lo), max(hi) {}

  static constexpr Box empty() { return Box(); }

  void extend(const Vec3& p) {
    min = bvhopt::min(min, p);
    max = bvhopt::max(max, p);
  }
  void extend(const Box& b) {
    min = bvhopt::min(min, b.min);
    max = bvhopt::max(max, b.max);
  }

  constexpr bool is_empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  constexpr Vec3 extent() const { return max - min; }
  constexpr Vec3 center() const { return (min + max) * 0.5f; }

  // Full surface area 2(xy + yz + zx), in double: a float overflows for extents above
  // about 1.3e19 and underflows for extents below about 1e-19, and in double scaling the
  // box by 2^k scales its area by exactly 4^k, so trees and costs do not depend on the
  // scene's scale. An empty box has area 0, never a negative value.
  [[gnu::always_inline]] double area() const {
    if (is_empty()) return 0.0;
    return area_unchecked();
  }
  // Same as area() for a box known to be non-empty; the hot loops use this one. The
  // extents are differences taken in double, so they do not overflow either.
  constexpr double area_unchecked() const {
    const double x = double(max.x) - double(min.x), y = double(max.y) - double(min.y),
                 z = double(max.z) - double(min.z);
    return 2.0 * (x * y + y * z + z * x);
  }
  float volume() const {
    if (is_empty()) return 0.0f;
    Vec3 e = extent();
    return e.x * e.y * e.z;
  }

  int largest_axis() const {
    Vec3 e = extent();
    if (e.x >= e.y && e.x >= e.z) return 0;
    return e.y >= e.z ? 1 : 2;
  }

  constexpr bool contains(const Vec3& p) const {
    return p.x >= min.x && p.y >= min.y && p.z >= min.z && p.x <= max.x && p.y <= max.y && p.z <= max.z;
  }
  constexpr bool contains(const Box& b) const { return b.is_empty() || (contains(b.min) && contains(b.max)); }
  constexpr bool operator==(const Box& o) const = default;
};

[[gnu::always_inline]] inline Box merge(const Box& a, const Box& b) {
  return Box(bvhopt::min(a.min, b.min), bvhopt::max(a.max, b.max));
}

}  // namespace bvhopt
