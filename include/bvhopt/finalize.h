// Finalize: the compact depth-first node array that traversal reads and files store.
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

// 32 bytes, two to a cache line. In depth-first order the left child of an inner node is
// the next node, so only the right child's index is stored.
struct FlatNode {
  Box box;
  uint32_t index;  // inner: right child; leaf: first entry in FlatBvh::triangle_ids
  uint16_t count;  // 0 for inner nodes; leaf: number of entries
  uint8_t axis;    // inner: split axis recorded by finalize (0, 1, 2)
  uint8_t flags;   // reserved

  bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(FlatNode) == 32);

struct FlatBvh {
  std::vector<FlatNode> nodes;
  std::vector<uint32_t> triangle_ids;  // per leaf entry, the original triangle
};

struct FinalizeOptions {
  // Record per inner node the axis that best separates its children and put the child
  // lower on that axis first (Kensler, section 5), so traversal can pick the near child
  // from the ray's sign on that axis.
  bool order_children_by_split_axis = true;
};

// The largest leaf a traced tree holds: FlatNode::count is 16 bits. finalize and
// flatten_for_tracing refuse larger leaves (Error), and the CLI's --leaf-size stops there.
inline constexpr uint32_t kMaxTracedLeafSize = 0xffff;

// Leaves with more than kMaxTracedLeafSize references are rejected (Error): finalize is for traversal.
FlatBvh finalize(const Bvh& bvh, const PrimitiveRefs& refs, const FinalizeOptions& options = {});

// The split axis of section 5 for two child boxes: the axis with the largest gap between
// them, or failing any gap, the one on which they overlap least.
int separating_axis(const Box& a, const Box& b);

}  // namespace bvhopt
