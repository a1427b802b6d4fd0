// One reference per triangle in each leaf: see include/bvhopt/leaf_dedup.h.
#include "bvhopt/leaf_dedup.h"

#include <algorithm>
#include <string>
#include <vector>

namespace bvhopt {
namespace {

// Leaves beyond this size are deduplicated by sorting a copy; smaller ones by a scan of
// the kept prefix, which beats sorting for the handful of slots a SAH leaf holds.
constexpr uint32_t kScanLimit = 32;

std::string num(uint64_t v) { return std::to_string(v); }

}  // namespace

LeafDedupStats dedup_leaf_references(Bvh& bvh, const PrimitiveRefs& refs) {
  LeafDedupStats stats;
  if (bvh.empty()) return stats;
  const uint32_t* tri = refs.triangle_ids.data();
  std::vector<uint32_t> sorted;  // big leaves: triangle ids already kept, sorted
  for (uint32_t n : bvh.depth_first_order()) {
    BvhNode& node = bvh.nodes[n];
    if (!node.is_leaf()) continue;
    ++stats.leaves;
    const uint32_t first = node.first_ref(), count = node.ref_count();
    uint32_t* slots = bvh.ref_indices.data() + first;
    stats.slots_before += count;
    uint32_t kept = 0;
    if (count <= kScanLimit) {
      for (uint32_t i = 0; i < count; ++i) {
        const uint32_t id = tri[slots[i]];
        bool seen = false;
        for (uint32_t k = 0; k < kept; ++k) seen |= tri[slots[k]] == id;
        if (!seen) slots[kept++] = slots[i];
      }
    } else {
      sorted.clear();
      for (uint32_t i = 0; i < count; ++i) {
        const uint32_t id = tri[slots[i]];
        auto it = std::lower_bound(sorted.begin(), sorted.end(), id);
        if (it != sorted.end() && *it == id) continue;
        sorted.insert(it, id);
        slots[kept++] = slots[i];
      }
    }
    stats.slots_after += kept;
    stats.leaves_changed += kept != count;
    // The box stays: it still bounds the leaf's part of every triangle it held.
    node.make_leaf(first, kept);
  }
  // renumber_depth_first() copies only the slots leaves use, so the dropped ones disappear.
  bvh.renumber_depth_first();
  return stats;
}

ValidationReport validate_deduplicated(const Bvh& bvh, const PrimitiveRefs& refs) {
  ValidationReport report;
  auto add = [&](std::string line) {
    if (report.problems.size() < 1000) report.problems.push_back(std::move(line));
  };
  const size_t ref_count = refs.size();
  if (refs.triangle_ids.size() != ref_count || refs.centroids.size() != ref_count) {
    add("references: array sizes differ");
    return report;
  }
  uint32_t triangle_count = 0;
  for (uint32_t id : refs.triangle_ids) triangle_count = std::max(triangle_count, id + 1);

  // Slots: in range, and each reference in at most one slot.
  std::vector<uint8_t> in_slot(ref_count, 0);
  bool slots_ok = true;
  for (size_t s = 0; s < bvh.ref_indices.size(); ++s) {
    const uint32_t r = bvh.ref_indices[s];
    if (r >= ref_count) {
      add("slot " + num(s) + ": reference " + num(r) + " out of range (" + num(ref_count) + " references)");
      slots_ok = false;
    } else if (in_slot[r]++) {
      add("reference " + num(r) + " appears in more than one slot");
      slots_ok = false;
    }
  }
  if (!slots_ok) return report;

  // Leaves reachable from the root (a visited flag guards against cycles; validate()
  // below names them): no triangle twice in a leaf, every triangle in some leaf.
  std::vector<uint32_t> leaf_of(triangle_count, kInvalidNode);  // last leaf seen holding the triangle
  if (!bvh.empty() && bvh.root < bvh.nodes.size()) {
    std::vector<uint8_t> visited(bvh.nodes.size(), 0);
    std::vector<uint32_t> stack{bvh.root};
    while (!stack.empty()) {
      const uint32_t n = stack.back();
      stack.pop_back();
      if (n >= bvh.nodes.size() || visited[n]) continue;
      visited[n] = 1;
      const BvhNode& node = bvh.nodes[n];
      if (!node.is_leaf()) {
        stack.push_back(node.right());
        stack.push_back(node.left());
        continue;
      }
      if (static_cast<size_t>(node.first_ref()) + node.ref_count() > bvh.ref_indices.size()) continue;
      for (uint32_t k = 0; k < node.ref_count(); ++k) {
        const uint32_t id = refs.triangle_ids[bvh.ref_indices[node.first_ref() + k]];
        if (leaf_of[id] == n) add("leaf " + num(n) + " holds triangle " + num(id) + " more than once");
        leaf_of[id] = n;
      }
    }
  }
  std::vector<uint8_t> has_ref(triangle_count, 0);
  for (uint32_t id : refs.triangle_ids) has_ref[id] = 1;
  for (uint32_t id = 0; id < triangle_count; ++id)
    if (has_ref[id] && leaf_of[id] == kInvalidNode) add("triangle " + num(id) + " is in no leaf");

  // Everything else validate() checks, on the kept references renumbered 0..k-1.
  std::vector<uint32_t> new_id(ref_count, kInvalidNode);
  PrimitiveRefs kept;
  for (size_t r = 0; r < ref_count; ++r) {
    if (!in_slot[r]) continue;
    new_id[r] = static_cast<uint32_t>(kept.size());
    kept.boxes.push_back(refs.boxes[r]);
    kept.centroids.push_back(refs.centroids[r]);
    kept.triangle_ids.push_back(refs.triangle_ids[r]);
  }
  Bvh copy = bvh;
  for (uint32_t& r : copy.ref_indices) r = new_id[r];
  for (std::string& line : validate(copy, kept).problems)
    add("(references renumbered to the kept ones) " + line);
  return report;
}

}  // namespace bvhopt
