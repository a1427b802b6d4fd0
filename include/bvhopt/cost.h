// The SAH cost of a tree and of its subtrees.
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"

namespace bvhopt {

// Cost of one leaf, not normalized: c_I * SA(N) * t_N.
inline double leaf_cost(double area, uint32_t ref_count, const CostModel& m) {
  return m.intersection * area * ref_count;
}

// Per node, the subtree's cost not normalized: c_T * SA(N) + C(L) + C(R) for an inner node,
// c_I * SA(N) * t_N for a leaf. Indexed by node; unreachable nodes get 0. Double sums.
std::vector<double> subtree_costs(const Bvh& bvh, const CostModel& model = {});

// The tree's SAH cost: C(root) / SA(root). 0 for an empty tree.
double sah_cost(const Bvh& bvh, const CostModel& model = {});

// The one recurrence behind optimal_collapse_cost and collapse_leaves: bottom-up, per node,
// `best` is the subtree's cost (not normalized) after the best collapse at and below it, and
// `collapse` says whether the node itself becomes a leaf: c_I * SA(N) * t(N) is no more than
// c_T * SA(N) + best(L) + best(R) and the subtree holds at most max_leaf_size references
// (0 = no limit). Indexed by node; unreachable nodes get 0; leaves never "collapse".
struct CollapseCosts {
  std::vector<double> best;
  std::vector<uint8_t> collapse;
};
CollapseCosts collapse_costs(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size);
// The same recurrence with t(N) given per node (`count`, indexed by node): the leaves'
// and subtrees' triangle counts of triangle_cost.h instead of their reference counts.
CollapseCosts collapse_costs(const Bvh& bvh, const CostModel& model, uint32_t max_leaf_size,
                             const std::vector<uint64_t>& count);

// The cost after the best collapse of subtrees into leaves (Bittner's `ocost`), without
// changing the tree: bottom-up, a subtree becomes a leaf wherever c_I * SA(N) * t(N) is no
// more than its cost as a tree. A subtree holding more than max_leaf_size references is
// never collapsed (0 = no limit).
double optimal_collapse_cost(const Bvh& bvh, const CostModel& model = {}, uint32_t max_leaf_size = 0);

}  // namespace bvhopt
