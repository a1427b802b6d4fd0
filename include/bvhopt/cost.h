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

// What each node's term is weighed by: its box's surface area SA(N), so that the cost is
// sum / SA(root). A tree whose root has zero area (every reference on one axis-parallel
// segment, or all at one point) has no such ratio; its cost is defined as the limit of the
// formula when every box grows by d on every side and d -> 0:
//   SA(N + d) / SA(root + d) -> E(N) / E(root), E = the sum of the box's three extents,
//   or 1 for every node when the root is a single point.
// So n coincident points under a tree with i inner nodes cost c_T * i + c_I * n (9 points
// in 9 leaves: 3 * 8 + 2 * 9 = 42 with the default constants), and as one leaf c_I * n (18).
// Every cost here, and every optimizer's report, uses these weights.
class CostWeights {
 public:
  explicit CostWeights(const Bvh& bvh);
  double operator()(const BvhNode& n) const;
  // The root's weight: the divisor of the normalized cost (1 for a flat root).
  double root() const { return flat_ ? 1.0 : root_area_; }
  bool flat() const { return flat_; }

 private:
  double root_area_ = 1.0;
  bool flat_ = false;
  double per_extent_ = 0.0;  // 1 / E(root) for a segment, 0 for a point
};

// Throws Error naming `what` when `cost` is NaN or infinite: a cost is never an output
// unless it is a number.
void check_finite_cost(double cost, const char* what);

// Per node, the subtree's cost not normalized: c_T * SA(N) + C(L) + C(R) for an inner node,
// c_I * SA(N) * t_N for a leaf. Indexed by node; unreachable nodes get 0. Double sums.
std::vector<double> subtree_costs(const Bvh& bvh, const CostModel& model = {});

// The tree's SAH cost: C(root) / SA(root) (see CostWeights for a zero-area root). 0 for an
// empty tree; Error if it is not finite.
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
