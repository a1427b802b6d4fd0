// Mesh summaries, validation and rotation.
#include <cmath>
#include <string>
#include <utility>

#include "bvhopt/error.h"
#include "bvhopt/mesh.h"

namespace bvhopt {

Box mesh_bounds(const Mesh& mesh) {
  Box b;
  for (size_t v = 0; v < mesh.vertex_count(); ++v) b.extend(mesh.vertex(v));
  return b;
}

MeshInfo describe(const Mesh& mesh) {
  MeshInfo info;
  info.triangles = mesh.triangle_count();
  info.vertices = mesh.vertex_count();
  const size_t n = mesh.vertex_count();
  const float* p = mesh.positions.data();
  for (size_t v = 0; v < n; ++v) info.bounds.extend(Vec3(p[3 * v], p[3 * v + 1], p[3 * v + 2]));
  // Only indices in range are looked at, so describe() is safe on a mesh that check_mesh
  // would reject; a triangle with a bad index simply counts as not degenerate.
  const uint32_t* idx = mesh.indices.data();
  for (size_t t = 0; t < info.triangles; ++t) {
    if (idx[3 * t] >= n || idx[3 * t + 1] >= n || idx[3 * t + 2] >= n) continue;
    const Triangle tri = mesh.triangle(t);
    if (tri.is_degenerate()) {
      ++info.degenerate_triangles;
      if (tri.v0 == tri.v1 || tri.v1 == tri.v2 || tri.v2 == tri.v0) ++info.coincident_triangles;
    }
  }
  return info;
}

void check_mesh(const Mesh& mesh) {
  const std::string& name = mesh.name.empty() ? std::string("mesh") : mesh.name;
  if (mesh.positions.size() % 3 != 0)
    throw Error(name + ": position array holds " + std::to_string(mesh.positions.size()) +
                " floats, not a multiple of three");
  if (mesh.indices.size() % 3 != 0)
    throw Error(name + ": index array holds " + std::to_string(mesh.indices.size()) +
                " indices, not a multiple of three");
  if (mesh.indices.empty()) throw Error(name + ": no triangles");
  const size_t n = mesh.vertex_count();
  for (size_t v = 0; v < n; ++v) {
    for (int axis = 0; axis < 3; ++axis) {
      float c = mesh.positions[3 * v + axis];
      if (!std::isfinite(c))
        throw Error(name + ": vertex " + std::to_string(v) + ": coordinate " + "xyz"[axis] + " is " +
                    (std::isnan(c) ? "NaN" : "infinite"));
    }
  }
  const size_t triangles = mesh.triangle_count();
  for (size_t t = 0; t < triangles; ++t) {
    for (int k = 0; k < 3; ++k) {
      uint32_t i = mesh.indices[3 * t + k];
      if (i >= n)
        throw Error(name + ": triangle " + std::to_string(t) + ": vertex index " + std::to_string(i) +
                    " out of range (" + std::to_string(n) + " vertices)");
    }
  }
}

namespace {

// Exact values at multiples of 90 degrees, so that a quarter turn maps axes onto axes
// without a stray 1e-8 from cos(pi/2).
void sin_cos_degrees(double degrees, double& s, double& c) {
  double r = std::fmod(degrees, 360.0);
  if (r < 0) r += 360.0;
  if (r == 0.0) { s = 0; c = 1; return; }
  if (r == 90.0) { s = 1; c = 0; return; }
  if (r == 180.0) { s = 0; c = -1; return; }
  if (r == 270.0) { s = -1; c = 0; return; }
  const double rad = r * (3.14159265358979323846 / 180.0);
  s = std::sin(rad);
  c = std::cos(rad);
}

// p = centre + m (p - centre), in double.
void rotate_point(const double m[3][3], const double centre[3], float* p) {
  const double d[3] = {p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]};
  for (int r = 0; r < 3; ++r) p[r] = static_cast<float>(centre[r] + m[r][0] * d[0] + m[r][1] * d[1] + m[r][2] * d[2]);
}

}  // namespace

void rotate_mesh(Mesh& mesh, const Vec3& degrees) {
  if (degrees.x == 0.0f && degrees.y == 0.0f && degrees.z == 0.0f) return;
  const size_t n = mesh.vertex_count();
  if (n == 0) return;
  Box bounds;
  for (size_t v = 0; v < n; ++v) bounds.extend(mesh.vertex(v));
  double sx, cx, sy, cy, sz, cz;
  sin_cos_degrees(degrees.x, sx, cx);
  sin_cos_degrees(degrees.y, sy, cy);
  sin_cos_degrees(degrees.z, sz, cz);
  // R = Rz * Ry * Rx (x first), in double so that large scenes far from the origin keep
  // their float precision after the round trip through the centre.
  const double m[3][3] = {
      {cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx},
      {sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx},
      {-sy, cy * sx, cy * cx},
  };
  const double centre[3] = {0.5 * (double(bounds.min.x) + bounds.max.x), 0.5 * (double(bounds.min.y) + bounds.max.y),
                            0.5 * (double(bounds.min.z) + bounds.max.z)};
  float* p = mesh.positions.data();
  for (size_t v = 0; v < n; ++v) rotate_point(m, centre, p + 3 * v);
  if (mesh.camera) {
    Camera& cam = *mesh.camera;
    const double origin[3] = {0.0, 0.0, 0.0};
    for (auto [point, about] : {std::pair{&cam.position, centre}, {&cam.target, centre}, {&cam.up, origin}}) {
      float xyz[3] = {point->x, point->y, point->z};
      rotate_point(m, about, xyz);
      *point = Vec3(xyz[0], xyz[1], xyz[2]);
    }
  }
}

}  // namespace bvhopt
