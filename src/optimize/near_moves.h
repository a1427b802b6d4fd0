// Candidates around the last pass's moves (private to the library).
//
// Why: once a parallel pass selects at random, few of its random candidates still find a
// move, but many more of the nodes a move has just changed do, with their parents and
// grandparents: a move changes the boxes, and with them the best places, of the nodes
// around its old and new place. In the polish of the hall, 1.5 % of the random candidates
// found a move at 4M triangles (2.1 % at 1M), against 7.5 % (6.9 %) of the nodes around
// the last pass's moves. A pass that takes those first and fills up with random ones
// converged in 143 polish passes instead of 174 at 4M (docs/optimization-at-scale.md).
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/bvh.h"
#include "optimize/node_set.h"

namespace bvhopt::detail {

// Appends to `out`, each at most once and until `out` holds `limit` ids, the nodes in `moved`
// and their parents and grandparents as the tree is now, in that order, leaving out the root
// and every node not in `inner`. `seen`: scratch, emptied first.
inline void append_near_moves(const Bvh& bvh, const std::vector<uint32_t>& moved, const NodeBits& inner,
                              size_t limit, NodeSet& seen, std::vector<uint32_t>& out) {
  seen.reset(bvh.nodes.size());
  const auto add = [&](uint32_t v) {
    if (out.size() < limit && v != kInvalidNode && v != bvh.root && inner.contains(v) && seen.insert(v))
      out.push_back(v);
  };
  for (uint32_t v : moved) {
    if (out.size() >= limit) return;
    add(v);
    const uint32_t parent = bvh[v].parent;
    add(parent);
    if (parent != kInvalidNode) add(bvh[parent].parent);
  }
}

}  // namespace bvhopt::detail
