// A triangle by value: what a builder never sees and a ray tracer always does.
#pragma once

#include "bvhopt/box.h"

namespace bvhopt {

struct Triangle {
  Vec3 v0, v1, v2;

  Box bounds() const {
    Box b;
    b.extend(v0);
    b.extend(v1);
    b.extend(v2);
    return b;
  }
  Vec3 centroid() const { return (v0 + v1 + v2) * (1.0f / 3.0f); }
  float area() const { return 0.5f * length(cross(v1 - v0, v2 - v0)); }
  // Zero area (coincident or collinear vertices). Such triangles are valid input.
  bool is_degenerate() const { return !(area() > 0.0f); }
};

}  // namespace bvhopt
