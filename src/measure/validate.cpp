#include "bvhopt/validate.h"

#include <algorithm>

#include <cmath>
#include <cstdio>
#include <string>

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

// Relative 1e-6: the cached area is a float computed from the same box, so it should
// match bit for bit; the tolerance only forgives a different evaluation order.
bool area_matches(float cached, float actual) {
  if (cached == actual) return true;
  double a = cached, b = actual;
  if (!std::isfinite(a) || !std::isfinite(b)) return false;
  return std::fabs(a - b) <= 1e-6 * std::max(std::fabs(a), std::fabs(b));
}

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

ValidationReport validate(const Bvh& bvh, const PrimitiveRefs& refs, const ValidationOptions& options) {
  ValidationReport report;
  Collector out(report);
  const size_t node_count = bvh.nodes.size();
  const size_t slot_count = bvh.ref_indices.size();
  const size_t ref_count = refs.boxes.size();

  if (refs.centroids.size() != ref_count || refs.triangle_ids.size() != ref_count) {
    out.add("references: array sizes differ (" + num(ref_count) + " boxes, " + num(refs.centroids.size()) +
            " centroids, " + num(refs.triangle_ids.size()) + " triangle ids)");
  }

  // Who owns each slot and each reference, so a duplicate can name both leaves.
  std::vector<uint32_t> slot_owner(slot_count, kInvalidNode);
  std::vector<uint32_t> ref_slot(ref_count, kInvalidNode);
  std::vector<uint8_t> reached(node_count, 0);

  if (bvh.root == kInvalidNode) {
    if (ref_count > 0) out.add("tree is empty (no root) but there are " + num(ref_count) + " references");
  } else if (bvh.root >= node_count) {
    out.add("root: index " + num(bvh.root) + " out of range (" + num(node_count) + " nodes)");
  } else {
    if (bvh.nodes[bvh.root].parent != kInvalidNode)
      out.add("node " + num(bvh.root) + " (root): has parent link " + num(bvh.nodes[bvh.root].parent) +
              ", expected none");

    // Each node is pushed at most once (marked when pushed), so the walk ends after at
    // most node_count steps whatever the links say: cycles and shared subtrees show up
    // as a child that is already marked.
    //
    // The walk visits a compacted tree in index order and reads each node once, when it
    // is popped; validating a 10M-triangle tree is bound by memory traffic, not by the
    // checks. So a node's parent link is checked when the node is popped, and the union
    // test of an inner node waits for its right child (far away in depth-first order):
    // the right child's visit carries the parent's box and the left child's box (the
    // left child is the parent's neighbour, cheap to read at once).
    struct Visit {
      uint32_t node, parent;
      int side;
      bool check_union;
      Box parent_box, sibling_box;
    };
    std::vector<Visit> stack{{bvh.root, kInvalidNode, 0, false, {}, {}}};
    reached[bvh.root] = 1;
    auto union_problem = [&](uint32_t p, const Box& pbox, const Box& u) {
      out.add("node " + num(p) + ": box is not the union of its children (children " + num(bvh.nodes[p].left()) +
              " and " + num(bvh.nodes[p].right()) + "): box " + fmt_box(pbox) + ", union " + fmt_box(u));
    };
    while (!stack.empty()) {
      const Visit v = stack.back();
      stack.pop_back();
      const uint32_t n = v.node;
      const BvhNode& nd = bvh.nodes[n];
      // Built only when there is something to report: formatting per node would dominate.
      auto name = [n] { return "node " + num(n); };

      if (v.parent != kInvalidNode && nd.parent != v.parent)
        out.add(name() + ": parent link is " + (nd.parent == kInvalidNode ? std::string("none") : num(nd.parent)) +
                ", but it is the " + (v.side == 0 ? "left" : "right") + " child of node " + num(v.parent));
      if (v.check_union) {
        const Box u = merge(v.sibling_box, nd.box);
        if (!(u == v.parent_box)) union_problem(v.parent, v.parent_box, u);
      }
      if (!area_matches(nd.area, nd.box.area())) {
        char buf[128];
        std::snprintf(buf, sizeof buf, ": cached area %.9g differs from its box's area %.9g", nd.area, nd.box.area());
        out.add(name() + buf);
      }

      if (!nd.is_leaf()) {
        const uint32_t l = nd.left(), r = nd.right();
        bool push[2] = {false, false};
        for (int i = 0; i < 2; ++i) {
          const uint32_t c = nd.child(i);
          const char* side = i == 0 ? "left" : "right";
          if (c >= node_count) {
            out.add(name() + ": " + side + " child index " + num(c) + " out of range (" + num(node_count) + " nodes)");
            continue;
          }
          if (reached[c]) {
            out.add(name() + ": " + side + " child " + num(c) +
                    (c == n ? " is the node itself" : " is already reached from elsewhere (cycle or shared subtree)"));
            continue;
          }
          reached[c] = 1;
          push[i] = true;
        }
        if (l == r && l < node_count) out.add(name() + ": both children are node " + num(l));
        const bool both_in_range = l < node_count && r < node_count;
        // Right first, so the left subtree is walked next, in index order.
        if (push[1]) stack.push_back({r, n, 1, both_in_range, nd.box, both_in_range ? bvh.nodes[l].box : Box{}});
        if (push[0]) stack.push_back({l, n, 0, false, {}, {}});
        if (both_in_range && !push[1]) {
          const Box u = merge(bvh.nodes[l].box, bvh.nodes[r].box);
          if (!(u == nd.box)) union_problem(n, nd.box, u);
        }
        continue;
      }

      const uint64_t first = nd.first_ref(), count = nd.ref_count();
      if (count == 0) {
        out.add(name() + ": leaf holds no references");
        continue;
      }
      if (first + count > slot_count) {
        out.add(name() + ": leaf slots [" + num(first) + ", " + num(first + count) + ") out of range (" +
                num(slot_count) + " slots)");
        continue;
      }
      for (uint64_t s = first; s < first + count; ++s) {
        if (slot_owner[s] != kInvalidNode) {
          out.add(name() + ": slot " + num(s) + " is also used by leaf node " + num(slot_owner[s]));
          continue;
        }
        slot_owner[s] = n;
      }
    }
  }

  // The references are checked in slot order rather than during the walk: slots are
  // contiguous, while reference ids are in no particular order, so each reference costs
  // a cache miss or two that prefetching a few slots ahead hides.
  constexpr size_t kAhead = 16;
  for (size_t s = 0; s < slot_count; ++s) {
    if (s + kAhead < slot_count) {
      const uint32_t ahead = bvh.ref_indices[s + kAhead];
      if (ahead < ref_count) {
        __builtin_prefetch(&refs.boxes[ahead]);
        __builtin_prefetch(&ref_slot[ahead]);
      }
    }
    const uint32_t r = bvh.ref_indices[s];
    const uint32_t owner = slot_owner[s];
    if (owner == kInvalidNode) {
      out.add("slot " + num(s) + " (reference " + num(r) + ") is in no leaf");
      continue;
    }
    if (r >= ref_count) {
      out.add("node " + num(owner) + ": slot " + num(s) + " holds reference " + num(r) + ", out of range (" +
              num(ref_count) + " references)");
      continue;
    }
    if (ref_slot[r] != kInvalidNode) {
      out.add("node " + num(owner) + ": reference " + num(r) + " (slot " + num(s) + ") is also in leaf node " +
              num(slot_owner[ref_slot[r]]) + " (slot " + num(ref_slot[r]) + ")");
      continue;
    }
    ref_slot[r] = static_cast<uint32_t>(s);
    const Box& leaf_box = bvh.nodes[owner].box;
    if (!leaf_box.contains(refs.boxes[r]))
      out.add("node " + num(owner) + ": leaf box " + fmt_box(leaf_box) + " does not contain the box of reference " +
              num(r) + " (slot " + num(s) + ") " + fmt_box(refs.boxes[r]));
  }
  if (!options.allow_dropped_duplicates) {
    for (size_t r = 0; r < ref_count; ++r)
      if (ref_slot[r] == kInvalidNode) out.add("reference " + num(r) + " is in no leaf");
  } else if (refs.triangle_ids.size() == ref_count) {
    // A reference may be missing only where a leaf still holds its triangle.
    uint32_t max_triangle = 0;
    for (uint32_t t : refs.triangle_ids) max_triangle = std::max(max_triangle, t);
    std::vector<uint8_t> triangle_present(ref_count == 0 ? 0 : size_t(max_triangle) + 1, 0);
    for (size_t r = 0; r < ref_count; ++r)
      if (ref_slot[r] != kInvalidNode) triangle_present[refs.triangle_ids[r]] = 1;
    for (size_t r = 0; r < ref_count; ++r)
      if (ref_slot[r] == kInvalidNode && !triangle_present[refs.triangle_ids[r]])
        out.add("reference " + num(r) + " is in no leaf, and neither is any other reference to triangle " +
                num(refs.triangle_ids[r]));
  }
  out.finish();
  return report;
}

}  // namespace bvhopt
