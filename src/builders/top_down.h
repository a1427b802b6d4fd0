// Internal: the one top-down recursion every builder runs; each builder only supplies
// its split search (a "heuristic", as in Embree's builder kernels).
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <stdexcept>
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
  uint32_t slot = 0;  // with leaves in place: where the node is built (TopDownTree::place_leaves_in_place)
  size_t count() const { return end - begin; }
};

inline Box bounds_of(const Box* boxes, const uint32_t* ids, size_t count) {
  Box b;
  for (size_t i = 0; i < count; ++i) b.extend(boxes[ids[i]]);
  return b;
}

inline Box bounds_of(const PrimitiveRefs& refs, const uint32_t* ids, size_t count) {
  return bounds_of(refs.boxes.data(), ids, count);
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

  // Leaves in place, for leaves of one reference: the caller keeps the references' boxes
  // inside the node array, in its last 24 n bytes, which no inner node reaches while the
  // tree grows, so that a build over one reference per triangle needs no array of boxes
  // beside the tree (24 bytes per reference, a quarter of the sweep builder's peak). The
  // tree is numbered as without
  // (links name the nodes' places in that numbering), but only inner nodes are written
  // while it grows, and elsewhere: in [0, n - 1), where the subtree over [begin, end)
  // takes [slot, slot + (end - begin) - 1), its left child over [begin, mid) from slot + 1,
  // its right child from slot + (mid - begin); a node's parent field holds its place until
  // finish() moves it there. finish() then makes the leaves, each from `leaf_box(i)`,
  // reference i's box made anew (the boxes kept in the array are overwritten by then).
  // The heuristic must split every node of two or more references.
  void place_leaves_in_place(std::function<Box(uint32_t)> leaf_box) {
    in_place_ = true;
    leaf_box_ = std::move(leaf_box);
  }

  // Builds the subtree over `r` below `parent`. Nodes of at least `parallel_threshold`
  // references hand their smaller child to another task.
  template <class H>
  void build(H& h, NodeRange r, uint32_t parent, typename H::Node state, size_t parallel_threshold) {
    for (;;) {
      const size_t count = r.count();
      if (in_place_ && count == 1) {  // made by finish()
        leaves_.fetch_add(1, std::memory_order_relaxed);
        return;
      }
      BvhNode& node = bvh_.nodes[in_place_ ? r.slot : r.base];
      node.parent = in_place_ ? r.base : parent;
      node.set_box(state.box);
      if constexpr (requires { h.build_subtree(*this, r, parent, state); }) {
        if (count > 1 && h.build_subtree(*this, r, parent, state)) return;
      }
      typename H::Node left_state, right_state;
      const size_t left_count = count > 1 ? h.split(r, node, state, left_state, right_state) : 0;
      if (left_count == 0 || left_count >= count) {
        h.leaf(r);
        if (in_place_) throw std::logic_error("a build with leaves in place made a leaf of several references");
        node.make_leaf(static_cast<uint32_t>(r.begin), static_cast<uint32_t>(count));
        leaves_.fetch_add(1, std::memory_order_relaxed);
        return;
      }
      const size_t mid = r.begin + left_count;
      const uint32_t me = r.base;
      node.make_inner(me + 1, me + static_cast<uint32_t>(2 * left_count));
      const NodeRange lr{r.begin, mid, me + 1, r.slot + 1},
          rr{mid, r.end, me + static_cast<uint32_t>(2 * left_count), r.slot + static_cast<uint32_t>(left_count)};
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

  // Waits for every task (finish() does too; a heuristic that frees its scratch first
  // calls this, so that the renumbering's own arrays never meet the scratch).
  void wait() { tasks_.wait(); }

  // Waits for every task. The numbering is already depth-first; only leaves of several
  // references leave unused nodes behind, which renumbering removes. With leaves in place,
  // the inner nodes go to their places and the leaves are made.
  void finish() {
    tasks_.wait();
    const bool complete = 2 * leaves_.load() - 1 == bvh_.nodes.size();
    if (in_place_) place_complete_tree();
    if (!complete) bvh_.renumber_depth_first();
  }

 private:
  // Leaves of one: inner node s goes to its place p(s) = s + the leaves before it >= s, and
  // the places rise with s (the inner nodes are numbered in depth-first order), so moving
  // them last first never overwrites one not yet moved: one pass, streaming. Between p(s)
  // and p(s + 1) lie the leaves of the slots that follow, in slot order.
  void place_complete_tree() {
    std::vector<BvhNode>& nodes = bvh_.nodes;
    const uint32_t total = static_cast<uint32_t>(nodes.size()), inner = total / 2;
    if (inner > 0) {
      std::vector<uint32_t> place(inner);
      tbb::parallel_for(tbb::blocked_range<uint32_t>(0, inner, 16384), [&](const tbb::blocked_range<uint32_t>& r) {
        for (uint32_t i = r.begin(); i < r.end(); ++i) place[i] = nodes[i].parent;
      });
      for (uint32_t i = inner; i-- > 0;) nodes[place[i]] = nodes[i];
      tbb::parallel_for(tbb::blocked_range<uint32_t>(0, inner, 4096), [&](const tbb::blocked_range<uint32_t>& r) {
        for (uint32_t i = r.begin(); i < r.end(); ++i) {
          const uint32_t end = i + 1 < inner ? place[i + 1] : total;
          for (uint32_t p = place[i] + 1; p < end; ++p) {
            const uint32_t slot = p - (i + 1);  // p less the inner nodes before it
            BvhNode& leaf = nodes[p];
            leaf.set_box(leaf_box_(bvh_.ref_indices[slot]));
            leaf.make_leaf(slot, 1);
          }
        }
      });
    } else {
      nodes[0].set_box(leaf_box_(bvh_.ref_indices[0]));
      nodes[0].make_leaf(0, 1);
    }
    mend_parents();
  }

  // Parent fields from the children links, the root at 0 (every place holds a node).
  void mend_parents() {
    std::vector<BvhNode>& nodes = bvh_.nodes;
    bvh_.root = 0;
    nodes[0].parent = kInvalidNode;
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, static_cast<uint32_t>(nodes.size()), 16384),
                      [&](const tbb::blocked_range<uint32_t>& r) {
                        for (uint32_t i = r.begin(); i < r.end(); ++i) {
                          if (nodes[i].is_leaf()) continue;
                          nodes[nodes[i].left()].parent = i;
                          nodes[nodes[i].right()].parent = i;
                        }
                      });
  }

  Bvh& bvh_;
  bool in_place_ = false;
  std::function<Box(uint32_t)> leaf_box_;
  std::atomic<size_t> leaves_{0};
  tbb::task_group tasks_;
};

}  // namespace bvhopt::detail
