// The compressed 8-wide BVH of GPU tracers (Ylitie, Karras and Laine 2017, "Efficient
// Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", section 3.2): 80-byte nodes
// whose eight child boxes are quantized to 8 bits per plane relative to the node's origin,
// with a power-of-two scale per axis. Built from a finalized binary tree by the SAH-optimal
// collapse (bvhopt/wide_bvh.h) with leaves of at most 3 triangles; `bvhopt export --format
// cwbvh` writes it (docs/wide-export-format.md has every field).
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {

// Child slot i of a node: meta[i] == 0 is an empty slot. An inner child has bit i of
// inner_mask set and meta[i] = 0b001'00000 | (24 + i); its node is nodes[child_base + the
// number of inner children in slots below i]. A leaf child has meta[i] = (triangle count in
// unary in bits 5-7: 0b001, 0b011 or 0b111 for 1, 2, 3) | (offset of its first triangle from
// triangle_base, 0..23, in bits 0-4); its triangles are consecutive.
//
// Child box i on axis a is origin[a] + q_lo[a][i] * 2^(exponent[a] - 127) ..
// origin[a] + q_hi[a][i] * 2^(exponent[a] - 127), each bound one binary32 addition of an
// exact product (so a fused multiply-add decodes it the same). The quantized box contains
// the child's real box padded as the other layouts pad (src/layout/box_padding.h).
struct CwbvhNode {
  float origin[3];
  uint8_t exponent[3];  // biased by 127: the binary32 exponent field of the scale
  uint8_t inner_mask;
  uint32_t child_base;
  uint32_t triangle_base;
  uint8_t meta[8];
  uint8_t q_lo[3][8];  // per axis x, y, z, per child slot
  uint8_t q_hi[3][8];
};
static_assert(sizeof(CwbvhNode) == 80);

// A leaf triangle: its three vertices and its index in the mesh (16-byte rows, as GPUs load).
struct CwbvhTriangle {
  float v0[3];
  uint32_t id;
  float v1[3];
  uint32_t pad1;
  float v2[3];
  uint32_t pad2;
};
static_assert(sizeof(CwbvhTriangle) == 48);

inline constexpr uint32_t kCwbvhMaxLeafTriangles = 3;

struct CompressedWideBvh {
  std::vector<CwbvhNode> nodes;          // breadth-first per node: a node's inner children are consecutive
  std::vector<CwbvhTriangle> triangles;  // a node's leaf triangles are consecutive
  // The real child boxes (padded) that were quantized, 8 per node, empty boxes for unused
  // slots: what the quantized boxes are checked to contain.
  std::vector<Box> exact_child_boxes;
  uint32_t stack_entries = 0;  // enough for a traversal pushing all entered children but one per node
  double sah_cost = 0.0;       // wide SAH cost of the collapse (leaves of at most 3 triangles)
};

// Collapses `bvh` into 8-wide nodes (leaves of more than 3 distinct triangles are first
// split at their centroid median, so every binary tree can be exported) and quantizes it.
CompressedWideBvh build_compressed_wide_bvh(const FlatBvh& bvh, const Mesh& mesh, const WideCostModel& cost = {});

// Child box `slot` of a node as a reader decodes it (empty for an unused slot).
Box cwbvh_child_box(const CwbvhNode& node, uint32_t slot);

}  // namespace bvhopt
