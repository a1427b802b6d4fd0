// A triangle mesh: float vertex positions and 32-bit indices, all meshes of a scene merged.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/camera.h"
#include "bvhopt/triangle.h"

namespace bvhopt {

struct Mesh {
  std::string name;                // where it came from: a file name or a built-in scene spec
  std::vector<float> positions;    // x, y, z per vertex
  std::vector<uint32_t> indices;   // three vertex indices per triangle
  // A camera stored in the scene file (glTF, FBX, ...), in the positions' space; its
  // width and height are not the file's (default_camera sets them).
  std::optional<Camera> camera;

  size_t vertex_count() const { return positions.size() / 3; }
  size_t triangle_count() const { return indices.size() / 3; }

  Vec3 vertex(size_t v) const { return {positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]}; }
  Triangle triangle(size_t t) const {
    return {vertex(indices[3 * t]), vertex(indices[3 * t + 1]), vertex(indices[3 * t + 2])};
  }

  void add_vertex(const Vec3& p) {
    positions.push_back(p.x);
    positions.push_back(p.y);
    positions.push_back(p.z);
  }
  void add_triangle(uint32_t a, uint32_t b, uint32_t c) {
    indices.push_back(a);
    indices.push_back(b);
    indices.push_back(c);
  }
};

// Summary for `bvhopt info`.
struct MeshInfo {
  size_t triangles = 0;
  size_t vertices = 0;
  size_t degenerate_triangles = 0;  // zero area; kept, only counted
  // The part of degenerate_triangles with two corners at the same point (the rest are
  // collinear); scene READMEs usually count only these.
  size_t coincident_triangles = 0;
  Box bounds;
};

MeshInfo describe(const Mesh& mesh);

// The box of every vertex (an empty box for no vertices).
Box mesh_bounds(const Mesh& mesh);

// Throws Error naming `mesh.name`, the element and the problem when the mesh is unusable:
// no triangles, an index list not a multiple of three, an index out of range, a NaN or
// infinite coordinate. Degenerate triangles pass.
void check_mesh(const Mesh& mesh);

// Rotates the mesh in place by the given angles in degrees about x, then y, then z,
// around the centre of its bounding box; the stored camera, if any, turns with it.
void rotate_mesh(Mesh& mesh, const Vec3& degrees);

}  // namespace bvhopt
