// The SAH cost constants used everywhere.
#pragma once

namespace bvhopt {

// C = [c_T * sum_inner SA(N) + c_I * sum_leaves SA(N) * t_N] / SA(root)
// (a root of zero area: see CostWeights in cost.h and docs/cost.md)
// Defaults c_T = 3, c_I = 2 as in Bittner, Hapala and Havran's tables.
struct CostModel {
  double traversal = 3.0;     // c_T, per inner node visited
  double intersection = 2.0;  // c_I, per reference tested
};

}  // namespace bvhopt
