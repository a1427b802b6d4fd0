// Sutherland-Hodgman clipping in double precision (a float triangle's corners are exact in
// double, and a cut point is then far more accurate than the float box that bounds it).
#include "bvhopt/triangle_clipping.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

namespace bvhopt {
namespace {

// The float nearest below (above) a double, so a box rounded this way never loses any of
// the polygon it bounds. The step to the neighbouring float is taken on the bits: the
// builder's hot loop rounds millions of points, and the step only ever goes toward d (an
// infinity that overflowed steps to the largest float, never past infinity).
float float_below(float f) {
  if (f == 0.0f) return -std::numeric_limits<float>::denorm_min();
  uint32_t bits = std::bit_cast<uint32_t>(f);
  bits = f > 0.0f ? bits - 1 : bits + 1;
  return std::bit_cast<float>(bits);
}
float float_above(float f) { return -float_below(-f); }
float round_down(double d) {
  const float f = static_cast<float>(d);
  return static_cast<double>(f) > d ? float_below(f) : f;
}
float round_up(double d) {
  const float f = static_cast<float>(d);
  return static_cast<double>(f) < d ? float_above(f) : f;
}

void push(ClipPolygon& poly, const double* q) {
  if (poly.count == ClipPolygon::kMaxCorners) return;  // unreachable for a clipped triangle (see the header)
  double* out = poly.p[poly.count++];
  out[0] = q[0], out[1] = q[1], out[2] = q[2];
}

// The point where edge a-b meets the plane; only called with a and b strictly on opposite
// sides, so the denominator is never zero. The plane coordinate is set exactly.
void push_cut(ClipPolygon& poly, const double* a, const double* b, int axis, double pos) {
  const double t = (pos - a[axis]) / (b[axis] - a[axis]);
  double q[3];
  for (int k = 0; k < 3; ++k) q[k] = a[k] + t * (b[k] - a[k]);
  q[axis] = pos;
  push(poly, q);
}

}  // namespace

void slice_triangle(const Triangle& t, int axis, const float* planes, int count, Box* pieces) {
  const Vec3 v[3] = {t.v0, t.v1, t.v2};
  for (int k = 0; k <= count; ++k) pieces[k] = Box();
  const float* end = planes + count;
  // A corner lies in each piece whose slab holds it: two or more when it is on a plane.
  for (const Vec3& c : v) {
    const long first = std::lower_bound(planes, end, c[axis]) - planes;
    const long last = std::upper_bound(planes, end, c[axis]) - planes;
    for (long k = first; k <= last; ++k) pieces[k].extend(c);
  }
  // Each edge crossing a plane strictly gives the point where it does to the pieces on both
  // sides of that plane, computed as split_polygon computes it on the whole triangle.
  for (int e = 0; e < 3; ++e) {
    const Vec3& a = v[e];
    const Vec3& b = v[e == 2 ? 0 : e + 1];
    const float lo = std::min(a[axis], b[axis]), hi = std::max(a[axis], b[axis]);
    const long first = std::upper_bound(planes, end, lo) - planes;
    const long last = std::lower_bound(planes, end, hi) - planes;  // one past
    if (first >= last) continue;
    const double pa[3] = {a.x, a.y, a.z}, pb[3] = {b.x, b.y, b.z};
    for (long j = first; j < last; ++j) {
      const double pos = planes[j];
      const double s = (pos - pa[axis]) / (pb[axis] - pa[axis]);
      Vec3 lo_q, hi_q;
      for (int k = 0; k < 3; ++k) {
        const double q = k == axis ? pos : pa[k] + s * (pb[k] - pa[k]);
        lo_q[k] = round_down(q);
        hi_q[k] = round_up(q);
      }
      const Box q(lo_q, hi_q);
      pieces[j].extend(q);
      pieces[j + 1].extend(q);
    }
  }
}

ClipPolygon::ClipPolygon(const Triangle& t) : count(3) {
  const Vec3* v[3] = {&t.v0, &t.v1, &t.v2};
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) p[i][k] = (*v[i])[k];
}

Box ClipPolygon::bounds() const {
  if (count == 0) return Box();
  double lo[3], hi[3];
  for (int k = 0; k < 3; ++k) lo[k] = hi[k] = p[0][k];
  for (int i = 1; i < count; ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], p[i][k]);
      hi[k] = std::max(hi[k], p[i][k]);
    }
  return Box(Vec3(round_down(lo[0]), round_down(lo[1]), round_down(lo[2])),
             Vec3(round_up(hi[0]), round_up(hi[1]), round_up(hi[2])));
}

void split_polygon(const ClipPolygon& in, int axis, double pos, ClipPolygon& below, ClipPolygon& above) {
  below.count = above.count = 0;
  for (int i = 0; i < in.count; ++i) {
    const double* a = in.p[i];
    const double* b = in.p[i + 1 == in.count ? 0 : i + 1];
    const double da = a[axis] - pos, db = b[axis] - pos;
    if (da <= 0.0) push(below, a);
    if (da >= 0.0) push(above, a);
    if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
      push_cut(below, a, b, axis, pos);
      push_cut(above, a, b, axis, pos);
    }
  }
}

Box clip_triangle_to_slab(const Triangle& t, int axis, float lo, float hi) {
  ClipPolygon poly(t), below, above, inside;
  split_polygon(poly, axis, lo, below, above);
  split_polygon(above, axis, hi, inside, below);
  return inside.bounds();
}

Box clip_triangle_to_box(const Triangle& t, const Box& box) {
  if (box.is_empty()) return Box();
  ClipPolygon a(t), below, above;
  for (int axis = 0; axis < 3 && !a.empty(); ++axis) {
    split_polygon(a, axis, box.min[axis], below, above);
    split_polygon(above, axis, box.max[axis], a, below);
  }
  return a.bounds();
}

}  // namespace bvhopt
