// Primitive references: what builders and optimizers see instead of triangles.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/mesh.h"

namespace bvhopt {

// One entry per reference, as parallel arrays. A reference is a box, a centroid and the
// id of the triangle it stands for; subdivision gives one triangle several references,
// each with a smaller box and the same triangle id.
struct PrimitiveRefs {
  std::vector<Box> boxes;
  std::vector<Vec3> centroids;
  std::vector<uint32_t> triangle_ids;

  size_t size() const { return boxes.size(); }
  bool empty() const { return boxes.empty(); }
  void resize(size_t n) {
    boxes.resize(n);
    centroids.resize(n);
    triangle_ids.resize(n);
  }
};

// One reference per triangle: its box and the centroid of its box. (The box centre
// rather than the vertex average, so a subdivided reference and a whole triangle are
// treated alike.) Parallel; the result does not depend on the thread count.
PrimitiveRefs make_references(const Mesh& mesh);

// References made directly from boxes, for users with their own primitives.
PrimitiveRefs make_references(const std::vector<Box>& boxes);

}  // namespace bvhopt
