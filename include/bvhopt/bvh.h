// The binary BVH that builders produce and optimizers change in place.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/references.h"

namespace bvhopt {

inline constexpr uint32_t kInvalidNode = 0xffffffffu;

// 40 bytes. Inner nodes hold two child indices; leaves hold a range of slots in
// Bvh::ref_indices. The box's surface area is cached because every optimizer reads
// areas far more often than it changes boxes.
struct BvhNode {
  static constexpr uint32_t kLeafFlag = 0x80000000u;

  Box box;
  float area = 0.0f;
  uint32_t parent = kInvalidNode;
  uint32_t left_or_first = kInvalidNode;  // inner: left child; leaf: first slot in ref_indices
  uint32_t right_or_count = 0;            // inner: right child; leaf: count | kLeafFlag

  bool is_leaf() const { return (right_or_count & kLeafFlag) != 0; }
  uint32_t left() const { return left_or_first; }
  uint32_t right() const { return right_or_count; }
  uint32_t child(int i) const { return i == 0 ? left_or_first : right_or_count; }
  void set_child(int i, uint32_t c) { (i == 0 ? left_or_first : right_or_count) = c; }
  uint32_t first_ref() const { return left_or_first; }
  uint32_t ref_count() const { return right_or_count & ~kLeafFlag; }

  void make_leaf(uint32_t first, uint32_t count) {
    left_or_first = first;
    right_or_count = count | kLeafFlag;
  }
  void make_inner(uint32_t l, uint32_t r) {
    left_or_first = l;
    right_or_count = r;
  }
  void set_box(const Box& b) {
    box = b;
    area = b.area();
  }
};

struct Bvh {
  std::vector<BvhNode> nodes;
  std::vector<uint32_t> ref_indices;  // leaf slots -> reference ids (indices into PrimitiveRefs)
  uint32_t root = kInvalidNode;

  bool empty() const { return root == kInvalidNode; }
  BvhNode& operator[](uint32_t n) { return nodes[n]; }
  const BvhNode& operator[](uint32_t n) const { return nodes[n]; }

  // The other child of n's parent. n must not be the root.
  uint32_t sibling(uint32_t n) const {
    const BvhNode& p = nodes[nodes[n].parent];
    return p.left() == n ? p.right() : p.left();
  }
  // Which child slot (0 or 1) n occupies in its parent.
  int child_slot(uint32_t n) const { return nodes[nodes[n].parent].left() == n ? 0 : 1; }

  // Sets inner node n's box (and area) to the union of its children's.
  void refit_node(uint32_t n) {
    BvhNode& nd = nodes[n];
    nd.set_box(merge(nodes[nd.left()].box, nodes[nd.right()].box));
  }
  enum class RefitScope {
    // Stop at the first box that does not change: in a tree whose every box is the union of
    // its children, the boxes above it cannot change either.
    until_unchanged,
    // Every node up to the root, for trees where boxes above may be stale.
    to_root,
  };
  // Refits every inner node from `node` (leaves are skipped) up to the root, each as the
  // union of its children. `inner_area_sum`, if given, receives each node's change of area,
  // added one at a time from the bottom (so a running sum stays exactly what it would be
  // if the caller added them itself).
  void refit_upwards(uint32_t node, RefitScope scope = RefitScope::until_unchanged, double* inner_area_sum = nullptr);
  // Recomputes every box bottom-up: leaves from their references, inner nodes from children.
  void refit(const PrimitiveRefs& refs);

  // Nodes reachable from the root, parents before children, left subtree first.
  std::vector<uint32_t> depth_first_order() const;
  // Nodes reachable from the root, children before parents.
  std::vector<uint32_t> post_order() const;

  // Renumbers the reachable nodes in depth-first order (root 0, left child next) and
  // drops unreachable ones; leaf reference ranges are rewritten in the same order, so
  // each leaf's slots follow the previous leaf's. Optimizers call it when done.
  void renumber_depth_first();

  size_t leaf_count() const;
  size_t inner_count() const;
};

}  // namespace bvhopt
