#include "bvhopt/cost.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "bvhopt/error.h"

namespace bvhopt {

namespace {

double extent_sum(const Box& b) {
  if (b.is_empty()) return 0.0;
  return (double(b.max.x) - b.min.x) + (double(b.max.y) - b.min.y) + (double(b.max.z) - b.min.z);
}

}  // namespace

CostWeights::CostWeights(const Bvh& bvh) {
  if (bvh.empty()) return;
  const Box& root = bvh[bvh.root].box;
  root_area_ = root.area();
  if (root_area_ > 0.0) return;
  // Every box lies on one axis-parallel segment (or is one point): see the header.
  flat_ = true;
  const double s = extent_sum(root);
  per_extent_ = s > 0.0 ? 1.0 / s : 0.0;
}

double CostWeights::operator()(const BvhNode& n) const {
  if (!flat_) return n.area();
  return per_extent_ > 0.0 ? extent_sum(n.box) * per_extent_ : 1.0;
}

void check_finite_cost(double cost, const char* what) {
  if (!std::isfinite(cost))
    throw Error(std::string(what) + ": the SAH cost is " + (std::isnan(cost) ? "NaN" : "infinite") +
                " (a box or a cost constant is not finite)");
}

std::vector<double> subtree_costs(const Bvh& bvh, const CostModel& model) {
  std::vector<double> cost(bvh.nodes.size(), 0.0);
  const CostWeights w(bvh);
  for_each_children_first(bvh, [&](uint32_t n) {
    const BvhNode& nd = bvh[n];
    cost[n] = nd.is_leaf() ? leaf_cost(w(nd), nd.ref_count(), model)
                           : model.traversal * w(nd) + cost[nd.left()] + cost[nd.right()];
  });
  return cost;
}

double sah_cost(const Bvh& bvh, const CostModel& model) {
  if (bvh.empty()) return 0.0;
  const double c = subtree_costs(bvh, model)[bvh.root] / CostWeights(bvh).root();
  check_finite_cost(c, "cost");
  return c;
}

namespace {

// The collapse's dynamic program in post order; count(n) gives the references under n, once
// per node, children before parents.
template <class Count>
CollapseCosts collapse_costs_by(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size, Count&& count) {
  CollapseCosts out;
  out.best.assign(bvh.nodes.size(), 0.0);
  out.collapse.assign(bvh.nodes.size(), 0);
  if (bvh.empty()) return out;
  const CostWeights w(bvh);
  for_each_children_first(bvh, [&](uint32_t n) {
    const BvhNode& nd = bvh[n];
    const uint64_t c = count(n);
    if (nd.is_leaf()) {
      out.best[n] = leaf_cost(w(nd), static_cast<uint32_t>(c), model);
      return;
    }
    const double as_tree = model.traversal * w(nd) + out.best[nd.left()] + out.best[nd.right()];
    const bool may_collapse = max_leaf_size == 0 || c <= max_leaf_size;
    const double as_leaf = model.intersection * w(nd) * static_cast<double>(c);
    out.collapse[n] = may_collapse && as_leaf <= as_tree;
    out.best[n] = out.collapse[n] ? as_leaf : as_tree;
  });
  return out;
}

}  // namespace

CollapseCosts collapse_costs(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size) {
  // Counted in the same walk, in 32 bits (a tree holds at most 2^30 references): no array of
  // 64-bit counts beside the costs, which had made the collapse bake's peak of memory.
  std::vector<uint32_t> count(bvh.nodes.size(), 0);
  return collapse_costs_by(bvh, model, max_leaf_size, [&](uint32_t n) {
    const BvhNode& nd = bvh[n];
    return count[n] = nd.is_leaf() ? nd.ref_count() : count[nd.left()] + count[nd.right()];
  });
}

CollapseCosts collapse_costs(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size,
                             const std::vector<uint64_t>& count) {
  return collapse_costs_by(bvh, model, max_leaf_size, [&](uint32_t n) { return count[n]; });
}

double optimal_collapse_cost(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size) {
  if (bvh.empty()) return 0.0;
  const double c = collapse_costs(bvh, model, max_leaf_size).best[bvh.root] / CostWeights(bvh).root();
  check_finite_cost(c, "ocost");
  return c;
}

}  // namespace bvhopt
