#include "bvhopt/validate.h"

#include <algorithm>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace bvhopt {
namespace {

// A corrupted tree can hold millions of problems; past this many lines only a count is
// kept, so validating a badly broken 10M-triangle tree does not build gigabytes of text.
constexpr size_t kMaxProblemLines = 1000;

std::string fmt_box(const Box& b) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "[(%.9g, %.9g, %.9g) - (%.9g, %.9g, %.9g)]", b.min.x, b.min.y, b.min.z, b.max.x,
                b.max.y, b.max.z);
  return buf;
}

std::string num(uint64_t v) { return std::to_string(v); }

class Collector {
 public:
  explicit Collector(ValidationReport& r) : report_(r) {}
  void add(std::string line) {
    ++total_;
    if (report_.problems.size() < kMaxProblemLines) report_.problems.push_back(std::move(line));
  }
  void finish() {
    if (total_ > report_.problems.size())
      report_.problems.push_back("... and " + num(total_ - report_.problems.size()) + " more problems");
  }

 private:
  ValidationReport& report_;
  size_t total_ = 0;
};

}  // namespace

std::string ValidationReport::summary() const {
  std::string s;
  const size_t shown = std::min<size_t>(problems.size(), 20);
  for (size_t i = 0; i < shown; ++i) {
    if (i) s += "; ";
    s += problems[i];
  }
  if (problems.size() > shown) s += "; and " + num(problems.size() - shown) + " more";
  return s;
}

namespace {

// One validation's inputs, its problem list, and who owns each slot and each reference
// (so a duplicate can name both leaves).
struct Validation {
  const Bvh& bvh;
  const PrimitiveRefs& refs;
  Collector& out;
  size_t node_count = 0, slot_count = 0, ref_count = 0;
  std::vector<uint32_t> slot_owner;  // per slot, the leaf node holding it
  std::vector<uint32_t> ref_slot;    // per reference, the slot holding it

  Validation(const Bvh& b, const PrimitiveRefs& r, Collector& o)
      : bvh(b), refs(r), out(o), node_count(b.nodes.size()), slot_count(b.ref_indices.size()),
        ref_count(r.boxes.size()), slot_owner(slot_count, kInvalidNode), ref_slot(ref_count, kInvalidNode) {}
};

void check_reference_arrays(Validation& v) {
  if (v.refs.centroids.size() != v.ref_count || v.refs.triangle_ids.size() != v.ref_count) {
    v.out.add("references: array sizes differ (" + num(v.ref_count) + " boxes, " + num(v.refs.centroids.size()) +
              " centroids, " + num(v.refs.triangle_ids.size()) + " triangle ids)");
  }
  // Box::contains accepts an empty box anywhere, so an inverted or NaN reference box would pass
  // every containment test; it stands for no triangle and is refused here.
  for (size_t r = 0; r < v.ref_count; ++r) {
    const Box& b = v.refs.boxes[r];
    if (!(b.min.x <= b.max.x && b.min.y <= b.max.y && b.min.z <= b.max.z))
      v.out.add("reference " + num(r) + ": box " + fmt_box(b) + " is inverted or not a number");
  }
}

// A node on the walk's stack. The walk visits a compacted tree in index order and reads each
// node once, when it is popped; validating a 10M-triangle tree is bound by memory traffic,
// not by the checks. So a node's parent link is checked when the node is popped, and the
// union test of an inner node waits for its right child (far away in depth-first order):
// the right child's visit carries the parent's box and the left child's box (the left
// child is the parent's neighbour, cheap to read at once).
struct Visit {
  uint32_t node, parent;
  int side;
  bool check_union;
  Box parent_box, sibling_box;
};

void union_problem(Validation& v, uint32_t p, const Box& pbox, const Box& u) {
  v.out.add("node " + num(p) + ": box is not the union of its children (children " + num(v.bvh.nodes[p].left()) +
            " and " + num(v.bvh.nodes[p].right()) + "): box " + fmt_box(pbox) + ", union " + fmt_box(u));
}

// What every node is checked for when popped: its parent link, the union its parent's
// visit deferred to it.
void check_node(Validation& v, const Visit& visit) {
  const uint32_t n = visit.node;
  const BvhNode& nd = v.bvh.nodes[n];
  if (visit.parent != kInvalidNode && nd.parent != visit.parent)
    v.out.add("node " + num(n) + ": parent link is " + (nd.parent == kInvalidNode ? std::string("none") : num(nd.parent)) +
              ", but it is the " + (visit.side == 0 ? "left" : "right") + " child of node " + num(visit.parent));
  if (visit.check_union) {
    const Box u = merge(visit.sibling_box, nd.box);
    if (!(u == visit.parent_box)) union_problem(v, visit.parent, visit.parent_box, u);
  }
}

// Pushes the children not reached before (marking them), reports the others, and tests the
// union here when the right child's visit cannot carry it.
void visit_inner(Validation& v, uint32_t n, std::vector<uint8_t>& reached, std::vector<Visit>& stack) {
  const BvhNode& nd = v.bvh.nodes[n];
  const uint32_t l = nd.left(), r = nd.right();
  bool push[2] = {false, false};
  for (int i = 0; i < 2; ++i) {
    const uint32_t c = nd.child(i);
    const char* side = i == 0 ? "left" : "right";
    if (c >= v.node_count) {
      v.out.add("node " + num(n) + ": " + side + " child index " + num(c) + " out of range (" + num(v.node_count) +
                " nodes)");
      continue;
    }
    if (reached[c]) {
      v.out.add("node " + num(n) + ": " + side + " child " + num(c) +
                (c == n ? " is the node itself" : " is already reached from elsewhere (cycle or shared subtree)"));
      continue;
    }
    reached[c] = 1;
    push[i] = true;
  }
  if (l == r && l < v.node_count) v.out.add("node " + num(n) + ": both children are node " + num(l));
  const bool both_in_range = l < v.node_count && r < v.node_count;
  // Right first, so the left subtree is walked next, in index order.
  if (push[1]) stack.push_back({r, n, 1, both_in_range, nd.box, both_in_range ? v.bvh.nodes[l].box : Box{}});
  if (push[0]) stack.push_back({l, n, 0, false, {}, {}});
  if (both_in_range && !push[1]) {
    const Box u = merge(v.bvh.nodes[l].box, v.bvh.nodes[r].box);
    if (!(u == nd.box)) union_problem(v, n, nd.box, u);
  }
}

// A leaf's slots: non-empty, in range, and used by no other leaf.
void claim_leaf_slots(Validation& v, uint32_t n) {
  const BvhNode& nd = v.bvh.nodes[n];
  const uint64_t first = nd.first_ref(), count = nd.ref_count();
  if (count == 0) {
    v.out.add("node " + num(n) + ": leaf holds no references");
    return;
  }
  if (first + count > v.slot_count) {
    v.out.add("node " + num(n) + ": leaf slots [" + num(first) + ", " + num(first + count) + ") out of range (" +
              num(v.slot_count) + " slots)");
    return;
  }
  for (uint64_t s = first; s < first + count; ++s) {
    if (v.slot_owner[s] != kInvalidNode) {
      v.out.add("node " + num(n) + ": slot " + num(s) + " is also used by leaf node " + num(v.slot_owner[s]));
      continue;
    }
    v.slot_owner[s] = n;
  }
}

// Each node is pushed at most once (marked when pushed), so the walk ends after at most
// node_count steps whatever the links say: cycles and shared subtrees show up as a child
// that is already marked.
void walk_tree(Validation& v) {
  const Bvh& bvh = v.bvh;
  if (bvh.root == kInvalidNode) {
    if (v.ref_count > 0) v.out.add("tree is empty (no root) but there are " + num(v.ref_count) + " references");
    return;
  }
  if (bvh.root >= v.node_count) {
    v.out.add("root: index " + num(bvh.root) + " out of range (" + num(v.node_count) + " nodes)");
    return;
  }
  if (bvh.nodes[bvh.root].parent != kInvalidNode)
    v.out.add("node " + num(bvh.root) + " (root): has parent link " + num(bvh.nodes[bvh.root].parent) +
              ", expected none");
  std::vector<uint8_t> reached(v.node_count, 0);
  std::vector<Visit> stack{{bvh.root, kInvalidNode, 0, false, {}, {}}};
  reached[bvh.root] = 1;
  while (!stack.empty()) {
    const Visit visit = stack.back();
    stack.pop_back();
    check_node(v, visit);
    if (bvh.nodes[visit.node].is_leaf())
      claim_leaf_slots(v, visit.node);
    else
      visit_inner(v, visit.node, reached, stack);
  }
}

// The references are checked in slot order rather than during the walk: slots are
// contiguous, while reference ids are in no particular order, so each reference costs a
// cache miss or two that prefetching a few slots ahead hides.
void check_slots(Validation& v) {
  const Bvh& bvh = v.bvh;
  const PrimitiveRefs& refs = v.refs;
  constexpr size_t kAhead = 16;
  for (size_t s = 0; s < v.slot_count; ++s) {
    if (s + kAhead < v.slot_count) {
      const uint32_t ahead = bvh.ref_indices[s + kAhead];
      if (ahead < v.ref_count) {
        __builtin_prefetch(&refs.boxes[ahead]);
        __builtin_prefetch(&v.ref_slot[ahead]);
      }
    }
    const uint32_t r = bvh.ref_indices[s];
    const uint32_t owner = v.slot_owner[s];
    if (owner == kInvalidNode) {
      v.out.add("slot " + num(s) + " (reference " + num(r) + ") is in no leaf");
      continue;
    }
    if (r >= v.ref_count) {
      v.out.add("node " + num(owner) + ": slot " + num(s) + " holds reference " + num(r) + ", out of range (" +
                num(v.ref_count) + " references)");
      continue;
    }
    if (v.ref_slot[r] != kInvalidNode) {
      v.out.add("node " + num(owner) + ": reference " + num(r) + " (slot " + num(s) + ") is also in leaf node " +
                num(v.slot_owner[v.ref_slot[r]]) + " (slot " + num(v.ref_slot[r]) + ")");
      continue;
    }
    v.ref_slot[r] = static_cast<uint32_t>(s);
    const Box& leaf_box = bvh.nodes[owner].box;
    if (!leaf_box.contains(refs.boxes[r]))
      v.out.add("node " + num(owner) + ": leaf box " + fmt_box(leaf_box) + " does not contain the box of reference " +
                num(r) + " (slot " + num(s) + ") " + fmt_box(refs.boxes[r]));
  }
}

void check_every_reference_in_a_leaf(Validation& v, const ValidationOptions& options) {
  const PrimitiveRefs& refs = v.refs;
  const size_t ref_count = v.ref_count;
  if (!options.allow_dropped_duplicates) {
    for (size_t r = 0; r < ref_count; ++r)
      if (v.ref_slot[r] == kInvalidNode) v.out.add("reference " + num(r) + " is in no leaf");
  } else if (refs.triangle_ids.size() == ref_count) {
    // A reference may be missing only where a leaf still holds its triangle.
    uint32_t max_triangle = 0;
    for (uint32_t t : refs.triangle_ids) max_triangle = std::max(max_triangle, t);
    std::vector<uint8_t> triangle_present(ref_count == 0 ? 0 : size_t(max_triangle) + 1, 0);
    for (size_t r = 0; r < ref_count; ++r)
      if (v.ref_slot[r] != kInvalidNode) triangle_present[refs.triangle_ids[r]] = 1;
    for (size_t r = 0; r < ref_count; ++r)
      if (v.ref_slot[r] == kInvalidNode && !triangle_present[refs.triangle_ids[r]])
        v.out.add("reference " + num(r) + " is in no leaf, and neither is any other reference to triangle " +
                  num(refs.triangle_ids[r]));
  }
}

}  // namespace

ValidationReport validate(const Bvh& bvh, const PrimitiveRefs& refs, const ValidationOptions& options) {
  ValidationReport report;
  Collector out(report);
  Validation v(bvh, refs, out);
  check_reference_arrays(v);
  walk_tree(v);
  check_slots(v);
  check_every_reference_in_a_leaf(v, options);
  out.finish();
  return report;
}

}  // namespace bvhopt
