// The binary BVH that builders produce and optimizers change in place.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/references.h"

namespace bvhopt {

inline constexpr uint32_t kInvalidNode = 0xffffffffu;

// The most references a Bvh can hold. An inner node keeps its right child's index where a
// leaf keeps count | kLeafFlag (bit 31), so every node index must stay below 2^31; a tree
// over n references has up to 2n - 1 nodes, numbered from 0, so n <= 2^30.
inline constexpr size_t kMaxReferences = size_t(1) << 30;
// Throws Error ("<who>: N references, more than the 2^30 a tree can hold") above that; every
// builder calls it before allocating.
void check_reference_count(size_t n, const char* who);

// 36 bytes. Inner nodes hold two child indices; leaves hold a range of slots in
// Bvh::ref_indices. (It had 4 bytes of padding to 40 until December 2026: without them the
// optimizer's searches touch fewer cache lines, insertion at 1M triangles ran about 5 %
// faster with the same trees, and every tree takes 8 bytes per triangle less.)
//
// The node used to cache its box's area as a float. A float cannot hold the areas of a
// scene's boxes over the float range of its coordinates (they overflow above extents of
// about 1.3e19 and lose all precision below 1e-19), and a scaled cache needs the tree's
// scale wherever a box's area is compared with a cached one. area() now computes it from
// the box, in double, on the cache line the box is read from anyway: every area in every
// stage is then the same function of the box, exact under scaling by powers of two.
struct BvhNode {
  static constexpr uint32_t kLeafFlag = 0x80000000u;

  Box box;
  uint32_t parent = kInvalidNode;
  uint32_t left_or_first = kInvalidNode;  // inner: left child; leaf: first slot in ref_indices
  uint32_t right_or_count = 0;            // inner: right child; leaf: count | kLeafFlag

  [[gnu::always_inline]] double area() const { return box.area(); }
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
  void set_box(const Box& b) { box = b; }
};

static_assert(sizeof(BvhNode) == 36, "the node's size is part of the memory per triangle");

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

  // Sets inner node n's box to the union of its children's.
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
  // Whether every node is reachable and numbered in depth_first_order() (root 0, left child
  // next): as every builder, optimizer and the file reader leave a tree. One walk.
  bool numbered_depth_first() const;

  // Renumbers the reachable nodes in depth-first order (root 0, left child next) and
  // drops unreachable ones; leaf reference ranges are rewritten in the same order, so
  // each leaf's slots follow the previous leaf's. Optimizers call it when done. A tree
  // already so numbered is only checked (one walk), not rewritten.
  void renumber_depth_first();

  size_t leaf_count() const;
  size_t inner_count() const;
};

// Calls visit(n) for every node reachable from the root, depth-first: each node before its
// subtrees, the left one first (the right one if !left_first). The walk holds a stack, not an
// order of every node. visit returns false to end the walk at n, before n's children are
// read (a check of n itself may stop it); then this returns false.
template <class F>
bool for_each_depth_first(const Bvh& bvh, F&& visit, bool left_first = true) {
  if (bvh.empty()) return true;
  std::vector<uint32_t> stack{bvh.root};
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    if (!visit(n)) return false;
    const BvhNode& nd = bvh[n];
    if (nd.is_leaf()) continue;
    stack.push_back(left_first ? nd.right() : nd.left());
    stack.push_back(left_first ? nd.left() : nd.right());
  }
  return true;
}

// Calls f(n) for every node reachable from the root, each after its children. On a tree
// numbered depth-first that is the array from its end, with no order of every node to
// allocate (8 bytes a triangle at the peak of bake's collapse); otherwise post_order().
template <class F>
void for_each_children_first(const Bvh& bvh, F&& f) {
  if (bvh.numbered_depth_first()) {
    for (size_t i = bvh.nodes.size(); i-- > 0;) f(static_cast<uint32_t>(i));
    return;
  }
  for (uint32_t n : bvh.post_order()) f(n);
}

}  // namespace bvhopt
