// Whether a node lies in another's subtree, for a tree whose every box is the union of its
// children's (private to the library).
#pragma once

#include <cstdint>

#include "bvhopt/bvh.h"

namespace bvhopt::detail {

// Whether x is subtree_root or one of its descendants. The walk up from x stops at the first
// node whose box leaves subtree_root's: no node of the subtree has such a box, since each
// box holds its children's, and no ancestor of a node outside the subtree is inside it.
//
// Why: a parallel pass checks each move's target this way before linking it (an earlier
// move of the pass may have carried it into the moved subtree, and linking there would
// make a cycle). The target is usually beside the subtree, not in it, so the walk ends
// within a level or two, where walking to the root took 25 levels at 4M triangles.
inline bool in_subtree(const Bvh& bvh, uint32_t x, uint32_t subtree_root) {
  const Box& bounds = bvh[subtree_root].box;
  for (; x != kInvalidNode && bounds.contains(bvh[x].box); x = bvh[x].parent)
    if (x == subtree_root) return true;
  return false;
}

}  // namespace bvhopt::detail
