#include "bvhopt/finalize.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <string>

#include "bvhopt/error.h"

namespace bvhopt {

// Kensler's section 5 asks for "the greatest separation between the end of one child's
// extent and the beginning of the other's", or failing that "the least overlap".
//  - gap on an axis: max(a.min - b.max, b.min - a.max); positive when a plane
//    perpendicular to the axis separates the boxes with room to spare. The largest
//    positive gap wins (absolute: a wide gap is what lets traversal skip the far child).
//  - no positive gap (touching counts as none): the overlap on an axis is the length of
//    the intersection of the two extents divided by the length of their union, so a
//    short axis is not favoured just because its numbers are small. A union of length
//    zero (both boxes flat in the same plane) counts as full overlap, 1. The smallest
//    relative overlap wins.
// Ties go to the lowest axis, so the result is a pure function of the two boxes.
int separating_axis(const Box& a, const Box& b) {
  int best_gap_axis = -1;
  double best_gap = 0.0;
  for (int axis = 0; axis < 3; ++axis) {
    const double gap = std::max(static_cast<double>(a.min[axis]) - b.max[axis],
                                static_cast<double>(b.min[axis]) - a.max[axis]);
    if (gap > best_gap) {
      best_gap = gap;
      best_gap_axis = axis;
    }
  }
  if (best_gap_axis >= 0) return best_gap_axis;

  int best_axis = 0;
  double best_overlap = 2.0;  // above any relative overlap, so axis 0 is taken at worst
  for (int axis = 0; axis < 3; ++axis) {
    const double lo = std::max(a.min[axis], b.min[axis]), hi = std::min(a.max[axis], b.max[axis]);
    const double span = static_cast<double>(std::max(a.max[axis], b.max[axis])) - std::min(a.min[axis], b.min[axis]);
    const double overlap = span > 0.0 ? std::max(0.0, hi - lo) / span : 1.0;
    if (overlap < best_overlap) {
      best_overlap = overlap;
      best_axis = axis;
    }
  }
  return best_axis;
}

namespace {

// True when b should come before a on the axis: a smaller centre (sum of min and max,
// the same order without the halving), then a smaller min. Equal boxes keep their order.
bool goes_first(const Box& b, const Box& a, int axis) {
  const double cb = static_cast<double>(b.min[axis]) + b.max[axis];
  const double ca = static_cast<double>(a.min[axis]) + a.max[axis];
  if (cb != ca) return cb < ca;
  return b.min[axis] < a.min[axis];
}

// Without reordering, the axis that best tells the children apart is the one on which
// their centres lie farthest apart.
int centre_axis(const Box& a, const Box& b) {
  int best = 0;
  double best_d = -1.0;
  for (int axis = 0; axis < 3; ++axis) {
    const double d = std::abs((static_cast<double>(a.min[axis]) + a.max[axis]) -
                              (static_cast<double>(b.min[axis]) + b.max[axis]));
    if (d > best_d) {
      best_d = d;
      best = axis;
    }
  }
  return best;
}

[[noreturn]] void fail(uint32_t node, const std::string& what) {
  throw Error("finalize: node " + std::to_string(node) + ": " + what);
}

// In a child decision: the right child goes first (bits 0-1 are the axis).
constexpr uint8_t kSwap = 4;

// Per inner node, the axis and whether to swap the children, in index order:
// that needs both children's boxes, and the right child lies far from its parent in a
// depth-first tree, so reading it during the walk (place_nodes) cost a cache miss per node.
// Here the iterations are independent: the far box is prefetched a few nodes ahead and
// the range is split across threads. Unreachable nodes may hold garbage; they are
// skipped if their indices are out of range, and their results are never read.
std::vector<uint8_t> child_decisions(const Bvh& bvh, bool reorder) {
  const size_t node_count = bvh.nodes.size();
  std::vector<uint8_t> decision(node_count, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, node_count, 8192), [&](const tbb::blocked_range<size_t>& range) {
    constexpr size_t kAhead = 16;
    for (size_t n = range.begin(); n < range.end(); ++n) {
      if (n + kAhead < node_count) {
        const BvhNode& ahead = bvh.nodes[n + kAhead];
        if (!ahead.is_leaf() && ahead.right() < node_count) __builtin_prefetch(&bvh.nodes[ahead.right()]);
      }
      const BvhNode& nd = bvh.nodes[n];
      if (nd.is_leaf() || nd.left() >= node_count || nd.right() >= node_count) continue;
      const Box& a = bvh.nodes[nd.left()].box;
      const Box& b = bvh.nodes[nd.right()].box;
      if (reorder) {
        const int axis = separating_axis(a, b);
        decision[n] = static_cast<uint8_t>(axis | (goes_first(b, a, axis) ? kSwap : 0));
      } else {
        decision[n] = static_cast<uint8_t>(centre_axis(a, b));
      }
    }
  });
  return decision;
}

// The depth-first walk that places every node; returns, per leaf entry, its slot in
// bvh.ref_indices. Throws Error on cycles, empty or oversized leaves, and indices out of range.
std::vector<uint32_t> place_nodes(const Bvh& bvh, const std::vector<uint8_t>& decision, FlatBvh& flat) {
  const size_t node_count = bvh.nodes.size();
  // The left child is always the next node, so only right children need their flat
  // index patched into the parent once they are placed.
  struct Pending {
    uint32_t node;
    uint32_t patch;  // flat index of the parent whose `index` is this node's, or kInvalidNode
  };
  std::vector<Pending> stack{{bvh.root, kInvalidNode}};
  // Leaf entries are resolved to triangle ids after the walk: reference ids are in no
  // particular order, so the lookups are cache misses that a separate pass can prefetch
  // and spread over threads. Here only the slot of each entry is recorded.
  std::vector<uint32_t> entry_slot;
  entry_slot.reserve(bvh.ref_indices.size());
  while (!stack.empty()) {
    const Pending p = stack.back();
    stack.pop_back();
    // A valid tree places each node once; more than node_count placements means a cycle.
    if (flat.nodes.size() >= node_count) fail(p.node, "reached more often than there are nodes (cycle)");
    const uint32_t idx = static_cast<uint32_t>(flat.nodes.size());
    if (p.patch != kInvalidNode) flat.nodes[p.patch].index = idx;
    const BvhNode& nd = bvh.nodes[p.node];
    FlatNode f{};
    f.box = nd.box;
    if (nd.is_leaf()) {
      const uint64_t first = nd.first_ref(), count = nd.ref_count();
      if (count == 0) fail(p.node, "leaf holds no references");
      if (count > kMaxTracedLeafSize)
        fail(p.node, "leaf holds " + std::to_string(count) + " references, more than " +
                         std::to_string(kMaxTracedLeafSize));
      if (first + count > bvh.ref_indices.size())
        fail(p.node, "leaf slots out of range (" + std::to_string(bvh.ref_indices.size()) + " slots)");
      f.index = static_cast<uint32_t>(entry_slot.size());
      f.count = static_cast<uint16_t>(count);
      for (uint64_t s = first; s < first + count; ++s) entry_slot.push_back(static_cast<uint32_t>(s));
      flat.nodes.push_back(f);
      continue;
    }
    uint32_t first = nd.left(), second = nd.right();
    if (first >= node_count || second >= node_count) fail(p.node, "child index out of range");
    const uint8_t d = decision[p.node];
    if (d & kSwap) std::swap(first, second);
    f.axis = static_cast<uint8_t>(d & 3);
    f.index = kInvalidNode;  // patched when the second child is placed
    flat.nodes.push_back(f);
    stack.push_back({second, idx});
    stack.push_back({first, kInvalidNode});
  }
  return entry_slot;
}

// Leaf entries resolved to triangle ids in parallel, after the walk.
void resolve_triangle_ids(const Bvh& bvh, const PrimitiveRefs& refs, const std::vector<uint32_t>& entry_slot,
                          FlatBvh& flat) {
  const size_t entries = entry_slot.size();
  const size_t ref_count = refs.triangle_ids.size();
  flat.triangle_ids.resize(entries);
  std::vector<uint8_t> bad(entries, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, entries, 8192), [&](const tbb::blocked_range<size_t>& range) {
    constexpr size_t kAhead = 16;
    for (size_t e = range.begin(); e < range.end(); ++e) {
      if (e + kAhead < entries) {
        const uint32_t ahead = bvh.ref_indices[entry_slot[e + kAhead]];
        if (ahead < ref_count) __builtin_prefetch(&refs.triangle_ids[ahead]);
      }
      const uint32_t r = bvh.ref_indices[entry_slot[e]];
      if (r < ref_count) {
        flat.triangle_ids[e] = refs.triangle_ids[r];
      } else {
        bad[e] = 1;
      }
    }
  });
  // Reported after the parallel pass, the first bad entry, so the message does not
  // depend on thread timing.
  for (size_t e = 0; e < entries; ++e)
    if (bad[e])
      throw Error("finalize: leaf slot " + std::to_string(entry_slot[e]) + " holds reference " +
                  std::to_string(bvh.ref_indices[entry_slot[e]]) + ", out of range (" + std::to_string(ref_count) +
                  " references)");
}

}  // namespace

FlatBvh finalize(const Bvh& bvh, const PrimitiveRefs& refs, const FinalizeOptions& options) {
  FlatBvh flat;
  if (bvh.empty()) return flat;
  if (bvh.root >= bvh.nodes.size())
    throw Error("finalize: root " + std::to_string(bvh.root) + " out of range (" + std::to_string(bvh.nodes.size()) +
                " nodes)");
  flat.nodes.reserve(bvh.nodes.size());
  flat.triangle_ids.reserve(bvh.ref_indices.size());
  const std::vector<uint8_t> decision = child_decisions(bvh, options.order_children_by_split_axis);
  const std::vector<uint32_t> entry_slot = place_nodes(bvh, decision, flat);
  resolve_triangle_ids(bvh, refs, entry_slot, flat);
  return flat;
}


}  // namespace bvhopt
