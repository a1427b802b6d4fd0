#include "bvhopt/bvh.h"

#include <algorithm>
#include <string>
#include <utility>

#include "bvhopt/error.h"

namespace bvhopt {

void check_reference_count(size_t n, const char* who) {
  if (n > kMaxReferences)
    throw Error(std::string(who) + ": " + std::to_string(n) + " references, more than the 2^30 (" +
                std::to_string(kMaxReferences) + ") a tree can hold");
}

void Bvh::refit_upwards(uint32_t node, RefitScope scope, double* inner_area_sum) {
  for (uint32_t n = node; n != kInvalidNode; n = nodes[n].parent) {
    BvhNode& nd = nodes[n];
    if (nd.is_leaf()) continue;
    const Box b = merge(nodes[nd.left()].box, nodes[nd.right()].box);
    if (scope == RefitScope::until_unchanged && b == nd.box) return;
    const double old_area = nd.area();
    nd.set_box(b);
    if (inner_area_sum) *inner_area_sum += nd.area() - old_area;
  }
}

void Bvh::refit(const PrimitiveRefs& refs) {
  for (uint32_t n : post_order()) {
    BvhNode& nd = nodes[n];
    if (!nd.is_leaf()) {
      refit_node(n);
      continue;
    }
    Box b;
    for (uint32_t i = 0; i < nd.ref_count(); ++i) b.extend(refs.boxes[ref_indices[nd.first_ref() + i]]);
    nd.set_box(b);
  }
}

namespace {

// Pre-order from the root; `left_first` picks which child comes first.
std::vector<uint32_t> pre_order(const Bvh& bvh, bool left_first) {
  std::vector<uint32_t> order;
  if (bvh.empty()) return order;
  order.reserve(bvh.nodes.size());
  for_each_depth_first(
      bvh,
      [&](uint32_t n) {
        order.push_back(n);
        return true;
      },
      left_first);
  return order;
}

}  // namespace

std::vector<uint32_t> Bvh::depth_first_order() const { return pre_order(*this, true); }

std::vector<uint32_t> Bvh::post_order() const {
  // Reversed, a pre-order that visits right before left is a post-order visiting left first.
  // Reversed in place: a reversed copy had held two orders at once (8 bytes a node) at the
  // peak of bake's collapse.
  std::vector<uint32_t> order = pre_order(*this, false);
  std::reverse(order.begin(), order.end());
  return order;
}

bool Bvh::numbered_depth_first() const {
  if (empty() || root != 0) return false;
  uint32_t next = 0;
  // A number out of the array ends the walk before its node is read.
  const bool whole = for_each_depth_first(*this, [&](uint32_t n) { return n < nodes.size() && n == next++; });
  return whole && next == nodes.size();
}

namespace {
// In a tree numbered depth-first, whether each leaf's slots follow the previous leaf's and
// no slot is unused: then renumber_depth_first() would change nothing.
bool slots_in_leaf_order(const Bvh& bvh) {
  uint64_t slot = 0;
  for (const BvhNode& nd : bvh.nodes) {
    if (!nd.is_leaf()) continue;
    if (nd.first_ref() != slot) return false;
    slot += nd.ref_count();
  }
  return slot == bvh.ref_indices.size();
}
}  // namespace

// In place: the optimizers call it on trees of tens of millions of nodes, where a second
// node array would double the peak memory. Scratch: one index per node and the new slots.
void Bvh::renumber_depth_first() {
  if (empty()) {
    nodes.clear();
    return;
  }
  // Trees from the builders and the file reader are already so numbered, and an optimizer
  // renumbers on entry: checking walks the array front to back, where renumbering allocates
  // and writes it all (4M triangles: 0.14 s of the optimizer's start).
  if (numbered_depth_first() && slots_in_leaf_order(*this)) return;
  // New numbers in depth_first_order()'s order (left subtree first), and the leaves' slots in
  // that order, rewritten as the walk meets them.
  std::vector<uint32_t> new_index(nodes.size(), kInvalidNode);
  std::vector<uint32_t> new_refs;
  new_refs.reserve(ref_indices.size());
  uint32_t next = 0;
  std::vector<uint32_t> stack{root};
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    new_index[n] = next++;
    BvhNode& nd = nodes[n];
    if (nd.is_leaf()) {
      const uint32_t first = static_cast<uint32_t>(new_refs.size());
      for (uint32_t k = 0; k < nd.ref_count(); ++k) new_refs.push_back(ref_indices[nd.first_ref() + k]);
      nd.make_leaf(first, nd.ref_count());
    } else {
      stack.push_back(nd.right());
      stack.push_back(nd.left());
    }
  }
  const uint32_t reachable = next;
  for (uint32_t i = 0; i < nodes.size(); ++i) {
    if (new_index[i] == kInvalidNode) continue;  // unreachable: dropped
    BvhNode& nd = nodes[i];
    if (nd.parent != kInvalidNode) nd.parent = new_index[nd.parent];
    if (!nd.is_leaf()) nd.make_inner(new_index[nd.left()], new_index[nd.right()]);
  }
  // Each reachable node is carried to its place; the node found there is carried on in
  // turn, until the place held an unreachable node or one already carried away (a hole:
  // nothing to keep). Unreachable nodes are never moved: after a collapse, most of the
  // tree's nodes are unreachable and every reachable one moves down a little, so each chain
  // is one move and the pass streams through the array (sending the unreachable ones past
  // the end instead made every other move a jump across it: as long as the collapse itself
  // at 2M triangles). After an optimizer the places are scattered and every step of a chain
  // is a cache miss that the next step waits for, so kCarriers chains advance in turn, each
  // step asking for the next one's place ahead. That is safe: a place is the target of one
  // node only, so only its carrier writes it, and a chain that reaches a place whose node
  // another chain took away finds a hole there and ends.
  constexpr uint32_t kHole = kInvalidNode;
  constexpr int kCarriers = 8;
  struct Carrier {
    BvhNode node;
    uint32_t to = kHole;
  };
  Carrier carriers[kCarriers];
  const uint32_t count = static_cast<uint32_t>(nodes.size());
  uint32_t scan = 0;
  auto ask_for = [&](uint32_t i) {
    const char* p = reinterpret_cast<const char*>(nodes.data() + i);
    __builtin_prefetch(p, 1);
    __builtin_prefetch(p + sizeof(BvhNode) - 1, 1);
    __builtin_prefetch(new_index.data() + i, 1);
  };
  // Takes the next node not yet in place out of the array (its place becomes a hole).
  auto start = [&](Carrier& c) {
    while (scan < count && (new_index[scan] == kHole || new_index[scan] == scan)) ++scan;
    if (scan == count) return false;
    c.node = nodes[scan];
    c.to = new_index[scan];
    new_index[scan] = kHole;
    ++scan;
    ask_for(c.to);
    return true;
  };
  int active = 0;
  for (Carrier& c : carriers) active += start(c) ? 1 : 0;
  while (active > 0) {
    for (Carrier& c : carriers) {
      if (c.to == kHole) continue;
      const BvhNode found = nodes[c.to];
      const uint32_t next_to = new_index[c.to];
      nodes[c.to] = c.node;
      new_index[c.to] = c.to;
      if (next_to != kHole) {
        c.node = found;
        c.to = next_to;
        ask_for(c.to);
      } else if (!start(c)) {
        c.to = kHole;
        --active;
      }
    }
  }
  nodes.resize(reachable);
  ref_indices = std::move(new_refs);
  root = 0;
}

size_t Bvh::leaf_count() const {
  size_t count = 0;
  for (uint32_t n : depth_first_order()) count += nodes[n].is_leaf();
  return count;
}

size_t Bvh::inner_count() const {
  size_t count = 0;
  for (uint32_t n : depth_first_order()) count += !nodes[n].is_leaf();
  return count;
}

}  // namespace bvhopt
