// Internal: how far every layout pads its boxes outward.
#pragma once

#include <algorithm>
#include <cmath>

#include "bvhopt/finalize.h"

namespace bvhopt::detail {

// The slab tests are exact up to their rounding (with a fused origin * rdir term, an ulp of
// |org * rdir|), but the triangle tests are watertight or Moller-Trumbore, not exact: they
// may accept a ray that passes a few ulps (of the vertex-to-origin distance) outside a
// triangle, e.g. through the far side of a shared vertex, whose box the exact ray then
// misses. Boxes grow by 2^-17 of the largest coordinate (about 64 ulps), which covers both
// for origins up to about ten scene sizes away; the cost is a few more box hits at grazing
// angles. Every layout pads alike, so they all hit the same triangles.
inline float box_padding(const FlatBvh& bvh) {
  float largest = 0.0f;
  for (const FlatNode& f : bvh.nodes)
    for (float c : {f.box.min.x, f.box.min.y, f.box.min.z, f.box.max.x, f.box.max.y, f.box.max.z})
      if (std::isfinite(c)) largest = std::max(largest, std::fabs(c));
  return largest * 0x1p-17f;
}

}  // namespace bvhopt::detail
