// The part of a triangle inside an axis-aligned slab or box, bounded exactly: what the
// spatial-split builder (spatial_split_builder.h) gives each piece of a split reference.
#pragma once

#include "bvhopt/box.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

// A convex polygon in double precision: a triangle clipped by axis-aligned planes. Each
// plane adds at most one corner to a convex polygon, so six planes give at most nine; the
// room for sixteen covers polygons whose cut points rounding has made slightly non-convex.
struct ClipPolygon {
  static constexpr int kMaxCorners = 16;
  double p[kMaxCorners][3];
  int count = 0;

  explicit ClipPolygon(const Triangle& t);
  ClipPolygon() = default;
  bool empty() const { return count == 0; }
  // Bounds of the corners, rounded outward to float so the box contains the exact polygon.
  Box bounds() const;
};

// Sutherland-Hodgman against one plane: `below` gets the part with p[axis] <= pos, `above`
// the part with p[axis] >= pos. Corners on the plane go to both; new corners lie exactly on
// it. Degenerate polygons (zero area, collinear, a point) pass without NaN: an edge is cut
// only when its ends lie strictly on opposite sides.
void split_polygon(const ClipPolygon& in, int axis, double pos, ClipPolygon& below, ClipPolygon& above);

// The triangle cut by `count` planes on `axis` (non-decreasing positions): pieces[0] gets
// the bounds of the part below planes[0], pieces[k] of the part between planes[k - 1] and
// planes[k], pieces[count] of the part above planes[count - 1]; `pieces` holds count + 1
// boxes. Each piece is bounded as split_polygon would bound it (corners on a plane belong
// to both sides, the cut points of one plane computed the same way, rounded outward to
// float), but from the triangle's edges directly rather than by clipping a polygon plane
// after plane: the cost is a few binary searches and the cut points, not a polygon per
// piece. An empty box is a piece the triangle misses.
void slice_triangle(const Triangle& t, int axis, const float* planes, int count, Box* pieces);

// Bounds of t ∩ {lo <= p[axis] <= hi}; empty when the triangle misses the slab.
Box clip_triangle_to_slab(const Triangle& t, int axis, float lo, float hi);

// Bounds of t ∩ box; empty when they do not meet.
Box clip_triangle_to_box(const Triangle& t, const Box& box);

// Exact intersection of two boxes (empty when they do not overlap).
inline Box intersect(const Box& a, const Box& b) {
  Box r(max(a.min, b.min), min(a.max, b.max));
  return r.is_empty() ? Box() : r;
}

}  // namespace bvhopt
