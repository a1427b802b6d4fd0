#include "bvhopt/collapse_leaves.h"

#include <utility>
#include <vector>

#include "bvhopt/cost.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/triangle_cost.h"

namespace bvhopt {
namespace {

// Collapses the nodes `collapse` marks (the recurrence of optimal_collapse_cost, so the
// collapsed tree's cost equals the `ocost` computed on the tree before); fills the counts.
void collapse_marked(Bvh& bvh, const std::vector<uint8_t>& collapse, CollapseResult& result) {
  // Counted in a walk with no order of every node to hold.
  for_each_depth_first(bvh, [&](uint32_t n) {
    result.nodes_before++;
    result.leaves_before += bvh[n].is_leaf();
    return true;
  });

  // Top-down: the first collapsible node on each path becomes a leaf holding, in
  // depth-first order, the references of every leaf below it.
  std::vector<uint32_t> new_refs;
  new_refs.reserve(bvh.ref_indices.size());
  std::vector<uint32_t> stack{bvh.root}, inner;
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    BvhNode& nd = bvh[n];
    if (nd.is_leaf()) {
      const uint32_t first = static_cast<uint32_t>(new_refs.size());
      for (uint32_t k = 0; k < nd.ref_count(); ++k) new_refs.push_back(bvh.ref_indices[nd.first_ref() + k]);
      nd.make_leaf(first, nd.ref_count());
      continue;
    }
    if (collapse[n]) {
      const uint32_t first = static_cast<uint32_t>(new_refs.size());
      inner.assign(1, n);
      while (!inner.empty()) {
        const uint32_t c = inner.back();
        inner.pop_back();
        const BvhNode& cd = bvh[c];
        if (cd.is_leaf()) {
          for (uint32_t k = 0; k < cd.ref_count(); ++k) new_refs.push_back(bvh.ref_indices[cd.first_ref() + k]);
        } else {
          inner.push_back(cd.right());
          inner.push_back(cd.left());
        }
      }
      // The box stays: it already is the union of everything below.
      nd.make_leaf(first, static_cast<uint32_t>(new_refs.size()) - first);
      continue;
    }
    stack.push_back(nd.right());
    stack.push_back(nd.left());
  }
  bvh.ref_indices = std::move(new_refs);
  bvh.renumber_depth_first();
}

void count_after(const Bvh& bvh, CollapseResult& result) {
  for (const BvhNode& nd : bvh.nodes) result.leaves_after += nd.is_leaf();
  result.nodes_after = bvh.nodes.size();
}

}  // namespace

CollapseResult collapse_leaves(Bvh& bvh, const CollapseConfig& config) {
  CollapseResult result;
  if (bvh.empty()) return result;
  result.cost_before = sah_cost(bvh, config.cost);
  // Only the marks outlive the costs: the per-node costs (8 bytes a node) are freed before
  // the collapse, which is bake's peak of memory.
  const std::vector<uint8_t> marked = std::move(collapse_costs(bvh, config.cost, config.max_leaf_size).collapse);
  collapse_marked(bvh, marked, result);
  count_after(bvh, result);
  result.cost_after = sah_cost(bvh, config.cost);
  return result;
}

CollapseResult collapse_leaves(Bvh& bvh, const PrimitiveRefs& refs, const CollapseConfig& config) {
  CollapseResult result;
  if (bvh.empty()) return result;
  // Unsplit references: no leaf can gain a second slot of a triangle, so the plain
  // collapse is this one, without its per-triangle counts and the deduplicating pass (at
  // 2M triangles those were most of bake's collapse time).
  if (one_slot_per_triangle(bvh, refs)) return collapse_leaves(bvh, config);
  result.cost_before = sah_cost(bvh, refs, config.cost);
  std::vector<uint64_t> triangles = subtree_triangle_counts(bvh, refs);
  const std::vector<uint8_t> marked =
      std::move(collapse_costs(bvh, config.cost, config.max_leaf_size, triangles).collapse);
  triangles = {};
  collapse_marked(bvh, marked, result);
  // Only a leaf holding one triangle twice changes, so on trees without split references
  // this is the plain collapse.
  const LeafDedupStats dedup = dedup_leaf_references(bvh, refs);
  result.dropped_references = dedup.slots_before - dedup.slots_after;
  count_after(bvh, result);
  result.cost_after = sah_cost(bvh, refs, config.cost);
  return result;
}

}  // namespace bvhopt
