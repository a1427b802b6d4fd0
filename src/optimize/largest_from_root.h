// The inner nodes with the largest keys, found from the root down instead of by a scan of
// the node array, for keys that never grow from a node to its children (the insertion
// optimizer's area measure). Private to the library.
//
// Why: the insertion optimizer selects its candidates by area on every pass of its first
// stages and of its last, 1 % of the inner nodes. LargestKeys reads every node for that, the
// whole array (288 MB at 4M triangles) on every pass: at 1M the first stage's passes took
// 15.5 ms with that scan, 9 ms with this walk. A node's box contains its children's, and
// rounding is monotone, so its area is at least
// theirs: the nodes with keys at or above any threshold hang together from the root, and a
// best-first walk from there meets them in order, reading about three nodes per candidate.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "bvhopt/bvh.h"
#include "optimize/reinsertion_search.h"

namespace bvhopt::detail {

class LargestFromRoot {
 public:
  // Whether the walk is worth it over a scan: it reads about 3k nodes at random, a scan
  // reads them all in order.
  static bool pays(size_t node_count, size_t k) { return 32 * k <= node_count; }

  // The k largest keys of the inner nodes below the root (key_of(i); the root itself is
  // left out), largest first, in `out`: exactly what LargestKeys::largest gives over the
  // inner nodes when the root's key is the smallest of all. key_of's upper 32 bits must never
  // grow from a node to a child (the lower ones break ties: they may, which is why every node
  // tied with the k-th is gathered before the sort). Returns false, with `out` unspecified,
  // where the walk would read much of the tree: so many nodes tied with the k-th (zero-area
  // boxes, all tied at 0) that a scan is cheaper, and 0 itself, where the root's key ties.
  template <class KeyOf>
  bool largest(const Bvh& bvh, size_t k, const KeyOf& key_of, std::vector<uint64_t>& out) {
    out.clear();
    heap_.clear();
    if (k == 0 || bvh.empty()) return true;
    const BvhNode* nodes = bvh.nodes.data();
    auto push_children = [&](const BvhNode& n) {
      for (int side = 0; side < 2; ++side) {
        const uint32_t c = n.child(side);
        const BvhNode& cn = nodes[c];
        if (cn.is_leaf()) continue;
        // Its children are read when it is popped, usually several pops later.
        prefetch_children(nodes, cn);
        heap_.push_back({key_of(c), c});
        std::push_heap(heap_.begin(), heap_.end());
      }
    };
    const BvhNode& root = nodes[bvh.root];
    if (root.is_leaf()) return true;
    push_children(root);
    // Past this many, ties at the k-th key are taking over: a scan does better.
    const size_t most = 2 * k + 1024;
    uint32_t threshold = 0;  // the k-th key's upper bits, once k are out
    while (!heap_.empty()) {
      std::pop_heap(heap_.begin(), heap_.end());
      const auto [key, node] = heap_.back();
      heap_.pop_back();
      const uint32_t upper = static_cast<uint32_t>(key >> 32);
      if (out.size() >= k && upper < threshold) break;
      out.push_back(key);
      if (out.size() == k) {
        threshold = upper;
        if (threshold == 0) return false;
      }
      if (out.size() > most) return false;
      push_children(nodes[node]);
    }
    if (out.empty()) return true;
    k = std::min(k, out.size());
    // The keys came out largest first, but for a child tied with its parent and numbered
    // before it (a larger key, met later): rare, so the sort is mostly skipped.
    if (!std::is_sorted(out.begin(), out.end(), std::greater<uint64_t>())) {
      std::nth_element(out.begin(), out.begin() + (k - 1), out.end(), std::greater<uint64_t>());
      std::sort(out.begin(), out.begin() + k, std::greater<uint64_t>());
    }
    out.resize(k);
    return true;
  }

 private:
  std::vector<std::pair<uint64_t, uint32_t>> heap_;  // the frontier's keys and nodes, a max-heap
};

}  // namespace bvhopt::detail
