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

double optimal_collapse_cost(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size) {
  if (bvh.empty()) return 0.0;
  std::vector<double> best(bvh.nodes.size(), 0.0);
  std::vector<uint64_t> count(bvh.nodes.size(), 0);
  for (uint32_t n : bvh.post_order()) {
    const BvhNode& nd = bvh[n];
    if (nd.is_leaf()) {
      count[n] = nd.ref_count();
      best[n] = leaf_cost(nd.area, nd.ref_count(), model);
      continue;
    }
    count[n] = count[nd.left()] + count[nd.right()];
    double as_tree = model.traversal * nd.area + best[nd.left()] + best[nd.right()];
    bool may_collapse = max_leaf_size == 0 || count[n] <= max_leaf_size;
    double as_leaf = model.intersection * nd.area * static_cast<double>(count[n]);
    best[n] = may_collapse ? std::min(as_tree, as_leaf) : as_tree;
  }
  double root_area = bvh[bvh.root].area;
  if (!(root_area > 0.0)) return sah_cost(bvh, model);
  return best[bvh.root] / root_area;
}

}  // namespace bvhopt
