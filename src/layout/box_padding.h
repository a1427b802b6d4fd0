// Internal: how far every layout pads its boxes outward.
#pragma once

#include <algorithm>
#include <cmath>

#include "bvhopt/finalize.h"

namespace bvhopt::detail {

// The slab tests are exact up to their rounding, but the triangle tests are watertight or
// Moller-Trumbore, not exact: they may accept a ray that passes a few ulps (of the
// vertex-to-origin distance, and of the vertices' own coordinates) outside a triangle, e.g.
// through the far side of a shared vertex, whose box the exact ray then misses. Each box
// coordinate x therefore moves outward by
//   2^-17 of the scene's largest extent, for errors of distances within the scene (origins
//   up to about ten scene sizes away): moving the scene does not change it, and
//   2^-21 of |x| (2 to 4 ulps of x), for the rounding of x itself and of x - origin,
// so a scene far from the origin (georeferenced, at 1e6) is padded by a few ulps of its own
// coordinates, not by a fraction of its distance from the origin. Every layout pads alike,
// so they all hit the same triangles.
class BoxPadding {
 public:
  explicit BoxPadding(const FlatBvh& bvh) {
    if (bvh.nodes.empty()) return;
    const Box& root = bvh.nodes[0].box;
    if (root.is_empty()) return;
    const Vec3 e = root.extent();
    const float largest = std::max({e.x, e.y, e.z});
    if (std::isfinite(largest)) base_ = largest * 0x1p-17f;
  }
  // Non-finite coordinates (an empty slot's +-inf) stay as they are.
  float below(float x) const { return std::isfinite(x) ? x - (base_ + std::fabs(x) * 0x1p-21f) : x; }
  float above(float x) const { return std::isfinite(x) ? x + (base_ + std::fabs(x) * 0x1p-21f) : x; }
  float base() const { return base_; }

 private:
  float base_ = 0.0f;
};

}  // namespace bvhopt::detail
