// Internal: the recursion shared by the partition-based builders (binned SAH, medians).
#pragma once

#include <tbb/task_group.h>

#include <atomic>
#include <cstdint>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt::detail {

// Node numbering that needs no shared counter, so the tree is the same on any number of
// threads: the subtree over ids[begin, end) owns nodes [base, base + 2(end - begin) - 1);
// its left child over [begin, mid) starts at base + 1, its right child at
// base + 2(mid - begin). With leaves of several references some of those nodes stay
// unused; the caller compacts the tree afterwards.
struct NodeRange {
  size_t begin, end;
  uint32_t base;
};

inline Box bounds_of(const PrimitiveRefs& refs, const uint32_t* ids, size_t count) {
  Box b;
  for (size_t i = 0; i < count; ++i) b.extend(refs.boxes[ids[i]]);
  return b;
}

inline Box centroid_bounds_of(const PrimitiveRefs& refs, const uint32_t* ids, size_t count) {
  Box b;
  for (size_t i = 0; i < count; ++i) b.extend(refs.centroids[ids[i]]);
  return b;
}

// `split(ids, count, node_box)` reorders ids[0, count) and returns the size of the left
// part, or 0 to make the node a leaf. It must be a pure function of its input.
template <class SplitFn>
void build_top_down(Bvh& bvh, const PrimitiveRefs& refs, const SplitFn& split, uint32_t parallel_threshold) {
  const size_t n = refs.size();
  bvh.nodes.assign(n == 0 ? 0 : 2 * n - 1, BvhNode{});
  bvh.ref_indices.resize(n);
  for (size_t i = 0; i < n; ++i) bvh.ref_indices[i] = static_cast<uint32_t>(i);
  bvh.root = n == 0 ? kInvalidNode : 0;
  if (n == 0) return;

  tbb::task_group tasks;
  std::atomic<size_t> leaves{0};
  auto recurse = [&](auto&& self, NodeRange r, uint32_t parent) -> void {
    for (;;) {
      uint32_t* ids = bvh.ref_indices.data() + r.begin;
      size_t count = r.end - r.begin;
      BvhNode& node = bvh.nodes[r.base];
      node.parent = parent;
      node.set_box(bounds_of(refs, ids, count));
      size_t left_count = count > 1 ? split(ids, count, node.box) : 0;
      if (left_count == 0 || left_count >= count) {
        node.make_leaf(static_cast<uint32_t>(r.begin), static_cast<uint32_t>(count));
        leaves.fetch_add(1, std::memory_order_relaxed);
        return;
      }
      size_t mid = r.begin + left_count;
      uint32_t left = r.base + 1;
      uint32_t right = r.base + static_cast<uint32_t>(2 * left_count);
      node.make_inner(left, right);
      NodeRange lr{r.begin, mid, left}, rr{mid, r.end, right};
      uint32_t me = r.base;
      // Hand the smaller side to another task and keep the larger one here.
      if (count >= parallel_threshold) {
        NodeRange spawned = left_count < count - left_count ? lr : rr;
        tasks.run([&self, spawned, me] { self(self, spawned, me); });
        r = left_count < count - left_count ? rr : lr;
      } else {
        self(self, lr, me);
        r = rr;
      }
      parent = me;
    }
  };
  recurse(recurse, NodeRange{0, n, 0}, kInvalidNode);
  tasks.wait();
  // Boxes were set top-down from the references; inner boxes are already exact unions.
  // The numbering is already depth-first; only leaves of several references leave
  // unused nodes behind that compacting removes.
  if (2 * leaves.load() - 1 != bvh.nodes.size()) bvh.renumber_depth_first();
}

}  // namespace bvhopt::detail
