// Algorithm 1 of Bittner et al. 2013 (best-first branch and bound), shared by the optimizer
// and the public find_reinsertion.
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/insertion_optimizer.h"

namespace bvhopt::detail {

// Asks for node i's cache lines (a 36-byte node may straddle two) ahead of its use: the
// searches are bound by misses on the node array, and a queued node's children are read
// only when it is popped, several pops later.
inline void prefetch_node(const BvhNode* nodes, uint32_t i) {
  const char* p = reinterpret_cast<const char*>(nodes + i);
  __builtin_prefetch(p);
  __builtin_prefetch(p + sizeof(BvhNode) - 1);
}
inline void prefetch_children(const BvhNode* nodes, const BvhNode& n) {
  prefetch_node(nodes, n.left());
  prefetch_node(nodes, n.right());
}

struct SearchEntry {
  double induced;  // C_I: growth of every box above the node
  uint32_t node;
};

// placement_cost with x's ancestors already in `path` (bottom-up, x's parent first).
inline double placement_cost_along(const Bvh& bvh, const Box& box, uint32_t x, const std::vector<uint32_t>& path) {
  double induced = 0.0;
  for (size_t i = path.size(); i-- > 0;) {
    const BvhNode& a = bvh[path[i]];
    induced = induced + (merge(a.box, box).area() - a.area());
  }
  return induced + merge(bvh[x].box, box).area();
}

// The cost of placing `box` above node x, computed exactly as the searches compute it (the
// induced cost summed from the root down, each term a growth), so that it compares to their
// totals to the last bit. `path` is scratch.
inline double placement_cost(const Bvh& bvh, const Box& box, uint32_t x, std::vector<uint32_t>& path) {
  path.clear();
  for (uint32_t a = bvh[x].parent; a != kInvalidNode; a = bvh[a].parent) path.push_back(a);
  return placement_cost_along(bvh, box, x, path);
}

// placement_cost, walking x's ancestors only up to the first whose box already contains
// `box`: from there up every growth is exactly zero (the box of a node contains its
// children's), and so is the sum of those terms, added first from the root down. The same
// cost to the last bit, without the chain of cache misses to the root.
inline double placement_cost_near(const Bvh& bvh, const Box& box, uint32_t x, std::vector<uint32_t>& path) {
  path.clear();
  for (uint32_t a = bvh[x].parent; a != kInvalidNode && !bvh[a].box.contains(box); a = bvh[a].parent) path.push_back(a);
  return placement_cost_along(bvh, box, x, path);
}

// A min-heap on the induced cost; `heap` is scratch space reused between searches so a hot
// loop allocates nothing. `start`, if given, is a place near where the subtree was (the
// first candidate, not restricted by skip or pass_through): its cost bounds the search from
// the first step, so far fewer nodes are queued; the minimum found is the same (on a tie
// the start is kept). `from`, if given, searches only its subtree, as if it were the whole
// tree: the search of a regional pass, where `box` came from that subtree, so that nothing
// above `from` grows wherever it goes inside (pass `from` as pass_through too, to keep it).
inline ReinsertionCandidate search_reinsertion(const Bvh& bvh, const Box& box, uint32_t skip, uint32_t pass_through,
                                               std::vector<SearchEntry>& heap,
                                               ReinsertionCandidate start = {kInvalidNode, 0.0},
                                               uint32_t from = kInvalidNode) {
  ReinsertionCandidate best{kInvalidNode, std::numeric_limits<double>::infinity()};
  if (bvh.empty()) return best;
  if (start.node != kInvalidNode) best = start;
  const double l_area = box.area();
  const BvhNode* nodes = bvh.nodes.data();
  auto later = [](const SearchEntry& a, const SearchEntry& b) { return a.induced > b.induced; };
  heap.clear();
  // The root is the only node evaluated on its own; every other node is evaluated when its
  // parent is expanded, so a good C_best is known before anything is queued and leaves
  // never enter the queue.
  const uint32_t root = from == kInvalidNode ? bvh.root : from;
  {
    const BvhNode& r = nodes[root];
    if (root != skip) {
      const double direct = merge(r.box, box).area();
      if (root != pass_through && (start.node == kInvalidNode || direct < best.cost)) best = {root, direct};
      if (!r.is_leaf()) heap.push_back({direct - static_cast<double>(r.area()), root});
    }
  }
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    const SearchEntry e = heap.back();
    heap.pop_back();
    // Here `induced` is the induced cost of e.node's children. Every node left in the queue
    // costs at least its induced cost plus SA(L): none can win.
    if (e.induced + l_area >= best.cost) break;
    const BvhNode& x = nodes[e.node];
    for (int side = 0; side < 2; ++side) {
      const uint32_t c = x.child(side);
      if (c == skip) continue;
      const BvhNode& cn = nodes[c];
      const double direct = merge(cn.box, box).area();
      const double total = e.induced + direct;
      if (total < best.cost && c != pass_through) best = {c, total};
      if (cn.is_leaf()) continue;
      // Written as induced + growth (never (induced + direct) - area): a sum of non-negative
      // terms rounds monotonically, so the bound never exceeds a true cost in the subtree
      // and the search stays exact to the last bit.
      const double child_induced = e.induced + (direct - static_cast<double>(cn.area()));
      if (child_induced + l_area < best.cost) {
        prefetch_children(nodes, cn);
        heap.push_back({child_induced, c});
        std::push_heap(heap.begin(), heap.end(), later);
      }
    }
  }
  return best;
}

// P's ancestors bottom-up (P's parent first), each with its child off the path up from P:
// the path the search after removing a child of P walks (search_reinsertion_after_removal).
struct AncestorLink {
  uint32_t node;
  uint32_t off_path;
};
inline void ancestors_of(const Bvh& bvh, uint32_t p, std::vector<AncestorLink>& chain) {
  const BvhNode* nodes = bvh.nodes.data();
  chain.clear();
  uint32_t from = p;
  for (uint32_t a = nodes[p].parent; a != kInvalidNode; a = nodes[a].parent) {
    chain.push_back({a, nodes[a].left() == from ? nodes[a].right() : nodes[a].left()});
    from = a;
  }
}

// An ancestor's shrunk box, as the search after removal needs it: its area, and its area
// once merged with the box being placed.
struct ShrunkArea {
  double area;
  double merged;
};

// The same search in the tree as it would be after Figure 3's removal of `n` and its parent
// P (P's other child S in P's place, the boxes above shrunk), without changing the tree:
// the path from the root down to P's parent is walked first with the shrunk boxes, and the
// subtrees hanging off it (none of which contains n) are searched as usual. `chain` is P's
// ancestors (ancestors_of), found apart so that a caller can walk several paths at once;
// `heap` and `shrunk` are scratch. `gain` receives the area the removal frees. Exact: it
// equals find_reinsertion on the removed tree.
inline ReinsertionCandidate search_reinsertion_after_removal(const Bvh& bvh, const Box& box, uint32_t n,
                                                             const std::vector<AncestorLink>& chain,
                                                             std::vector<SearchEntry>& heap,
                                                             std::vector<ShrunkArea>& shrunk, double* gain) {
  ReinsertionCandidate best{kInvalidNode, std::numeric_limits<double>::infinity()};
  const BvhNode* nodes = bvh.nodes.data();
  const uint32_t p = nodes[n].parent;
  const uint32_t s = nodes[p].left() == n ? nodes[p].right() : nodes[p].left();
  const double l_area = box.area();
  auto later = [](const SearchEntry& a, const SearchEntry& b) { return a.induced > b.induced; };
  heap.clear();
  shrunk.resize(chain.size());
  // Shrunk boxes bottom-up: each ancestor of P without n's subtree.
  double freed = static_cast<double>(nodes[n].area()) + nodes[p].area();
  Box below = nodes[s].box;
  for (size_t i = 0; i < chain.size(); ++i) {
    below = merge(below, nodes[chain[i].off_path].box);
    shrunk[i] = {below.area(), merge(below, box).area()};
    freed += static_cast<double>(nodes[chain[i].node].area()) - shrunk[i].area;
  }
  if (gain) *gain = freed;

  auto consider = [&](uint32_t c, double induced) {
    const BvhNode& cn = nodes[c];
    const double direct = merge(cn.box, box).area();
    const double total = induced + direct;
    if (total < best.cost) best = {c, total};
    if (cn.is_leaf()) return;
    const double child_induced = induced + (direct - static_cast<double>(cn.area()));
    if (child_induced + l_area < best.cost) {
      prefetch_children(nodes, cn);
      heap.push_back({child_induced, c});
      std::push_heap(heap.begin(), heap.end(), later);
    }
  };
  // The search starts where the subtree was: S in P's place is evaluated first (and its
  // subtree queued), so its cost bounds everything after; then the path top-down, each
  // off-path subtree opened only if its bound beats the best so far. `chain` is bottom-up.
  // Ties keep the first found, so the minimum is the exhaustive search's.
  double induced = 0.0;
  for (size_t i = chain.size(); i-- > 0;) induced = induced + (shrunk[i].merged - shrunk[i].area);
  consider(s, induced);
  induced = 0.0;
  for (size_t i = chain.size(); i-- > 0;) {
    const double shrunk_area = shrunk[i].area;
    const double direct = shrunk[i].merged;
    const double total = induced + direct;
    if (total < best.cost) best = {chain[i].node, total};
    const double child_induced = induced + (direct - shrunk_area);
    // The path is short; an off-path subtree whose bound already loses is never opened.
    if (child_induced + l_area < best.cost) consider(chain[i].off_path, child_induced);
    induced = child_induced;
  }

  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    const SearchEntry e = heap.back();
    heap.pop_back();
    if (e.induced + l_area >= best.cost) break;
    const BvhNode& x = nodes[e.node];
    consider(x.left(), e.induced);
    consider(x.right(), e.induced);
  }
  return best;
}

}  // namespace bvhopt::detail
