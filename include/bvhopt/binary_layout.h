// The binary layout: a finalized tree as traversal reads it, two child boxes per node.
// Wider layouts (four or eight children per node) sit beside it in src/layout/.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"

namespace bvhopt {

// One inner node of the tree holding both children's boxes, so one 64-byte cache line
// answers "which children does the ray enter" for a pair of boxes with SIMD. Boxes per axis
// as [lo child 0, lo child 1, hi child 0, hi child 1]. A child is an inner node
// (count & kCountMask == kInnerChild, child = its BinaryNode) or a leaf (that many entries
// from `child` in the entry arrays; 0 is an empty slot). count[0] >> 24 is the split axis
// finalize recorded (child 0 lies lower on it).
struct alignas(64) BinaryNode {
  static constexpr uint32_t kCountMask = 0x00ffffffu;
  static constexpr uint32_t kInnerChild = 0x00ffffffu;
  float x[4], y[4], z[4];
  uint32_t child[2];
  uint32_t count[2];
};
static_assert(sizeof(BinaryNode) == 64);

// A tree ready to trace: its inner nodes as BinaryNodes (boxes padded, see
// binary_layout.cpp) and, per leaf entry, the triangle's nine vertex coordinates in leaf
// order. Trees of any leaf size (up to 65535) and with repeated triangle ids (subdivided
// references) are laid out; a triangle met twice is stored twice.
struct BinaryLayout {
  std::vector<BinaryNode> nodes;       // inner nodes, depth-first; nodes[0] is the root (at least 1)
  std::vector<float> vertices;         // 9 floats per leaf entry
  std::vector<uint32_t> triangle_ids;  // per leaf entry, the mesh triangle
  size_t mesh_triangles = 0;           // triangle count of the mesh
  size_t depth = 0;                    // deepest node (the root is 0)
};

// Throws Error when the tree has no nodes, a child or leaf entry lies out of range, or a
// triangle id is not one of the mesh's.
BinaryLayout make_binary_layout(const FlatBvh& bvh, const Mesh& mesh);

}  // namespace bvhopt
