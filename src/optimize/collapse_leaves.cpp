#include "bvhopt/collapse_leaves.h"

#include <vector>

#include "bvhopt/cost.h"

namespace bvhopt {

CollapseResult collapse_leaves(Bvh& bvh, const CollapseConfig& config) {
  CollapseResult result;
  if (bvh.empty()) return result;
  const CostModel& m = config.cost;
  result.cost_before = sah_cost(bvh, m);

  // The recurrence of optimal_collapse_cost, so the collapsed tree's cost equals the `ocost`
  // computed on the tree before.
  const std::vector<uint8_t> collapse = collapse_costs(bvh, m, config.max_leaf_size).collapse;
  for (uint32_t n : bvh.post_order()) {
    result.nodes_before++;
    result.leaves_before += bvh[n].is_leaf();
  }

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

  for (const BvhNode& nd : bvh.nodes) result.leaves_after += nd.is_leaf();
  result.nodes_after = bvh.nodes.size();
  result.cost_after = sah_cost(bvh, m);
  return result;
}

}  // namespace bvhopt
