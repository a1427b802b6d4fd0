#include "bvhopt/cost.h"

#include <algorithm>

namespace bvhopt {

std::vector<double> subtree_costs(const Bvh& bvh, const CostModel& model) {
  std::vector<double> cost(bvh.nodes.size(), 0.0);
  for (uint32_t n : bvh.post_order()) {
    const BvhNode& nd = bvh[n];
    cost[n] = nd.is_leaf() ? leaf_cost(nd.area, nd.ref_count(), model)
                           : model.traversal * nd.area + cost[nd.left()] + cost[nd.right()];
  }
  return cost;
}

double sah_cost(const Bvh& bvh, const CostModel& model) {
  if (bvh.empty()) return 0.0;
  double root_area = bvh[bvh.root].area;
  std::vector<double> cost = subtree_costs(bvh, model);
  // A tree over one point (or coincident points) has a zero-area root: its cost is the
  // leaf count times c_I, the limit of the formula as the box shrinks uniformly.
  if (!(root_area > 0.0)) {
    double refs = 0.0;
    for (uint32_t n : bvh.post_order())
      if (bvh[n].is_leaf()) refs += bvh[n].ref_count();
    return model.intersection * refs;
  }
  return cost[bvh.root] / root_area;
}

CollapseCosts collapse_costs(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size) {
  std::vector<uint64_t> count(bvh.nodes.size(), 0);
  if (!bvh.empty())
    for (uint32_t n : bvh.post_order()) {
      const BvhNode& nd = bvh[n];
      count[n] = nd.is_leaf() ? nd.ref_count() : count[nd.left()] + count[nd.right()];
    }
  return collapse_costs(bvh, model, max_leaf_size, count);
}

CollapseCosts collapse_costs(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size,
                             const std::vector<uint64_t>& count) {
  CollapseCosts out;
  out.best.assign(bvh.nodes.size(), 0.0);
  out.collapse.assign(bvh.nodes.size(), 0);
  if (bvh.empty()) return out;
  for (uint32_t n : bvh.post_order()) {
    const BvhNode& nd = bvh[n];
    if (nd.is_leaf()) {
      out.best[n] = leaf_cost(nd.area, static_cast<uint32_t>(count[n]), model);
      continue;
    }
    const double as_tree = model.traversal * nd.area + out.best[nd.left()] + out.best[nd.right()];
    const bool may_collapse = max_leaf_size == 0 || count[n] <= max_leaf_size;
    const double as_leaf = model.intersection * nd.area * static_cast<double>(count[n]);
    out.collapse[n] = may_collapse && as_leaf <= as_tree;
    out.best[n] = out.collapse[n] ? as_leaf : as_tree;
  }
  return out;
}

double optimal_collapse_cost(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size) {
  if (bvh.empty()) return 0.0;
  double root_area = bvh[bvh.root].area;
  if (!(root_area > 0.0)) return sah_cost(bvh, model);
  return collapse_costs(bvh, model, max_leaf_size).best[bvh.root] / root_area;
}

}  // namespace bvhopt
