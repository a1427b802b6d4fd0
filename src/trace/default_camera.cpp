// The default camera of a scene: the file's own, else from inside a room, else framing the
// geometry from outside (see default_camera in bvhopt/ray_sets.h).
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/ray_sets.h"

namespace bvhopt {
namespace {

// Only keeps a point-sized scene's camera off its target; any fixed length would move the
// camera of a scene smaller than it (a scene scaled by 2^-60 is 1e-18 across).
constexpr float kTiny = std::numeric_limits<float>::min();

// Triangles below this count are too few for percentiles to mean anything.
constexpr size_t kMinTrianglesForPercentiles = 100;
constexpr double kGeometryPercentile = 0.01;

// Pixels of the probe image that ranks the exterior views (64x48 at 4:3).
constexpr double kProbePixels = 64.0 * 48.0;
// Probe images hitting at least this much count as equal, so the first side wins among
// views that fill the frame (rather than the closest-up one).
constexpr double kFilledFrame = 0.9;

struct Axes {
  int up, long_axis, short_axis;  // the two horizontal axes by the box's extent along them
};

Axes horizontal_axes(const Vec3& ext, int up_axis) {
  const int h0 = up_axis == 0 ? 1 : 0;
  const int h1 = up_axis == 2 ? 1 : 2;
  const int long_axis = ext[h0] >= ext[h1] ? h0 : h1;
  return {up_axis, long_axis, long_axis == h0 ? h1 : h0};
}

// The interior test of default_camera from `centre`, with distances measured to the
// boundary of a box of extent `ext` around it: the median probe must reach `min_reach` of
// the way there.
bool enclosed_with_room_to_look(const Mesh& mesh, const Tracer& tracer, const Vec3& centre, const Vec3& ext,
                                float min_reach) {
  int hits = 0, front = 0;
  std::vector<float> reach;  // hit distance over the distance to the box boundary
  TraceCounters counters;
  // `dir` reaches the box boundary at t = boundary_t.
  auto probe = [&](const Vec3& dir, float boundary_t) {
    if (dir == Vec3(0.0f) || !(boundary_t > 0.0f)) return;
    Ray r;
    r.org = centre;
    r.dir = dir;
    const Hit h = tracer.closest(r, counters);
    if (!h.hit()) return;
    ++hits;
    reach.push_back(h.t / boundary_t);
    const Triangle t = mesh.triangle(h.triangle_id);
    // The unit direction: with `dir` (the box's size) the product is a cube of the scene's
    // scale, which overflows a float above coordinates of about 7e12.
    front += dot(cross(t.v1 - t.v0, t.v2 - t.v0), normalize(dir)) < 0.0f ? 1 : 0;
  };
  for (int a = 0; a < 3; ++a)
    for (float s : {-1.0f, 1.0f}) probe(axis_vector(a, s), 0.5f * ext[a]);
  for (int i = 0; i < 8; ++i)
    probe(Vec3((i & 1) ? ext.x : -ext.x, (i & 2) ? ext.y : -ext.y, (i & 4) ? ext.z : -ext.z), 0.5f);
  std::sort(reach.begin(), reach.end());
  const float median_reach = reach.empty() ? 0.0f : reach[reach.size() / 2];
  // Enclosed, by surfaces facing the centre (walls seen from inside a room, not the back
  // faces of a solid the centre lies in, such as a statue), and with room to look: the
  // median probe travels at least `min_reach` of the way to the box boundary (a solid
  // with inward-facing triangles is hit close to the centre).
  return hits >= 12 && 2 * front > hits && median_reach >= min_reach;
}

// The share of a small version of `cam`'s image whose rays hit something.
double hit_fraction(const Tracer& tracer, Camera cam) {
  const double aspect = double(cam.width) / double(cam.height);
  cam.height = uint32_t(std::max(1.0, std::round(std::sqrt(kProbePixels / aspect))));
  cam.width = uint32_t(std::max(1.0, std::round(kProbePixels / cam.height)));
  size_t hits = 0;
  TraceCounters counters;
  const std::vector<Ray> rays = camera_rays(cam);
  for (const Ray& r : rays) hits += tracer.closest(r, counters).hit();
  return double(hits) / double(rays.size());
}

// Looking at the centre of `box` along `axis` from the side `sign`, at the distance where
// the box's extent along up fills the height and the other horizontal extent the width,
// with a 5% margin, measured at the box's centre (models rarely fill their box's corners,
// so measuring at the near face left scanned models small in the frame); but at least 10%
// of that distance in front of the box.
Camera framing(Camera cam, const Box& box, const Axes& axes, int axis, float sign) {
  const Vec3 ext = box.extent();
  const int across = axis == axes.long_axis ? axes.short_axis : axes.long_axis;
  const float tan_half = std::tan(0.5f * cam.fov_degrees * std::numbers::pi_v<float> / 180.0f);
  const float aspect = float(cam.width) / float(cam.height);
  const float fit = std::max(0.5f * ext[axes.up] / tan_half, 0.5f * ext[across] / (tan_half * aspect));
  const float distance = std::max({1.05f * fit, 0.5f * ext[axis] + 0.1f * fit, kTiny});
  cam.target = box.center();
  cam.position = box.center() + axis_vector(axis, sign * distance);
  return cam;
}

}  // namespace

Box geometry_bounds(const Mesh& mesh) {
  const size_t n = mesh.triangle_count();
  if (n < kMinTrianglesForPercentiles) return mesh_bounds(mesh);
  const size_t lo = size_t(kGeometryPercentile * double(n));
  const size_t hi = n - 1 - lo;
  std::vector<float> centroid(n);
  Box out;
  for (int axis = 0; axis < 3; ++axis) {
    for (size_t t = 0; t < n; ++t) {
      const Triangle tri = mesh.triangle(t);
      centroid[t] = (tri.v0[axis] + tri.v1[axis] + tri.v2[axis]) / 3.0f;
    }
    std::nth_element(centroid.begin(), centroid.begin() + lo, centroid.end());
    out.min[axis] = centroid[lo];
    std::nth_element(centroid.begin() + lo, centroid.begin() + hi, centroid.end());
    out.max[axis] = centroid[hi];
  }
  return out;
}

Camera default_camera(const Mesh& mesh, const Tracer& tracer, uint32_t width, uint32_t height, int up_axis) {
  if (up_axis < 0 || up_axis > 2) throw Error("default camera: up axis " + std::to_string(up_axis) + " is not 0, 1 or 2");
  if (width == 0 || height == 0) throw Error("default camera: resolution must be at least 1x1");
  Camera cam;
  if (mesh.camera) cam = *mesh.camera;
  cam.width = width;
  cam.height = height;
  if (mesh.camera) return cam;
  cam.up = axis_vector(up_axis);

  // Inside: at the centre of the whole box (where the built-in hall and most rooms put
  // it), else at the centre of where the geometry is (a room on a huge ground plane). The
  // geometry box is tight around a room's walls, so from the room's centre the probes
  // reach at least half way to it; 0.5 keeps out the inside of a solid whose triangles
  // face inward (horse.ply: 0.33).
  const Box geometry = geometry_bounds(mesh);
  for (const auto& [box, min_reach] : {std::pair{mesh_bounds(mesh), 0.3f}, std::pair{geometry, 0.5f}}) {
    const Vec3 ext = box.extent();
    if (!enclosed_with_room_to_look(mesh, tracer, box.center(), ext, min_reach)) continue;
    const int long_axis = horizontal_axes(ext, up_axis).long_axis;
    cam.position = box.center();
    cam.target = box.center() + axis_vector(long_axis, std::max(ext[long_axis], kTiny));
    return cam;
  }

  // Outside: the side of the geometry's box whose view hits most.
  const Axes axes = horizontal_axes(geometry.extent(), up_axis);
  Camera best;
  double best_hits = -1.0;
  for (int axis : {axes.short_axis, axes.long_axis})
    for (float sign : {1.0f, -1.0f}) {
      const Camera candidate = framing(cam, geometry, axes, axis, sign);
      const double hits = std::min(hit_fraction(tracer, candidate), kFilledFrame);
      if (hits > best_hits) best = candidate, best_hits = hits;
    }
  return best;
}

}  // namespace bvhopt
