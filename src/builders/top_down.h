// Internal: the one top-down recursion every builder runs; each builder only supplies
// its split search (a "heuristic", as in Embree's builder kernels).
#pragma once

#include <tbb/task_group.h>

#include <atomic>
#include <cstdint>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt::detail {

// Node numbering that needs no shared counter, so the tree is the same on any number of
// threads: the subtree over slots [begin, end) owns nodes [base, base + 2(end - begin) - 1);
// its left child over [begin, mid) starts at base + 1, its right child at
// base + 2(mid - begin). With leaves of several references some of those nodes stay
// unused; TopDownTree::finish removes them.
struct NodeRange {
  size_t begin, end;
  uint32_t base;
  size_t count() const { return end - begin; }
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

// A heuristic H provides
//   struct Node { Box box; ... };  what a node receives from its parent: at least its box
//   size_t split(const NodeRange&, const BvhNode&, const Node&, Node& left, Node& right);
//       reorders the node's slots and returns how many go left, or 0 for a leaf; the
//       children's Node states must be filled when it splits
//   void leaf(const NodeRange&);    puts a leaf's references into its slots of ref_indices
// and optionally
//   bool build_subtree(TopDownTree&, const NodeRange&, uint32_t parent, const Node&);
//       builds the whole subtree itself (for instance with another heuristic), or
//       returns false to let split() decide.
// Everything a heuristic computes must depend only on the node's references, so that the
// tree is the same whichever task builds which node.
class TopDownTree {
 public:
  // `bvh.nodes` must already hold 2n - 1 nodes and `bvh.ref_indices` n slots.
  explicit TopDownTree(Bvh& bvh) : bvh_(bvh) {}

  // Builds the subtree over `r` below `parent`. Nodes of at least `parallel_threshold`
  // references hand their smaller child to another task.
  template <class H>
  void build(H& h, NodeRange r, uint32_t parent, typename H::Node state, size_t parallel_threshold) {
    for (;;) {
      const size_t count = r.count();
      BvhNode& node = bvh_.nodes[r.base];
      node.parent = parent;
      node.set_box(state.box);
      if constexpr (requires { h.build_subtree(*this, r, parent, state); }) {
        if (count > 1 && h.build_subtree(*this, r, parent, state)) return;
      }
      typename H::Node left_state, right_state;
      const size_t left_count = count > 1 ? h.split(r, node, state, left_state, right_state) : 0;
      if (left_count == 0 || left_count >= count) {
        h.leaf(r);
        node.make_leaf(static_cast<uint32_t>(r.begin), static_cast<uint32_t>(count));
        leaves_.fetch_add(1, std::memory_order_relaxed);
        return;
      }
      const size_t mid = r.begin + left_count;
      const uint32_t me = r.base;
      node.make_inner(me + 1, me + static_cast<uint32_t>(2 * left_count));
      const NodeRange lr{r.begin, mid, me + 1}, rr{mid, r.end, me + static_cast<uint32_t>(2 * left_count)};
      // The smaller side goes to another task (or is built first); this one keeps the larger.
      const bool left_smaller = left_count < count - left_count;
      const NodeRange small_range = left_smaller ? lr : rr;
      const typename H::Node& small_state = left_smaller ? left_state : right_state;
      if (count >= parallel_threshold)
        tasks_.run([this, &h, small_range, me, small_state, parallel_threshold] {
          build(h, small_range, me, small_state, parallel_threshold);
        });
      else
        build(h, small_range, me, small_state, parallel_threshold);
      r = left_smaller ? rr : lr;
      state = left_smaller ? right_state : left_state;
      parent = me;
    }
  }

  // Waits for every task. The numbering is already depth-first; only leaves of several
  // references leave unused nodes behind, which renumbering removes.
  void finish() {
    tasks_.wait();
    if (2 * leaves_.load() - 1 != bvh_.nodes.size()) bvh_.renumber_depth_first();
  }

 private:
  Bvh& bvh_;
  std::atomic<size_t> leaves_{0};
  tbb::task_group tasks_;
};

}  // namespace bvhopt::detail
