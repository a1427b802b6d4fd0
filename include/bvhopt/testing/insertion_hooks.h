// Test hooks and oracles of the insertion optimizer: not for production use (the hook slows
// the optimizer down, the oracle is quadratic).
#pragma once

#include <cstdint>
#include <functional>

#include "bvhopt/box.h"
#include "bvhopt/bvh.h"
#include "bvhopt/insertion_optimizer.h"

namespace bvhopt::testing {

// Called after every complete move (sequential: both children reinserted; parallel: a
// subtree moved, or a move undone) with the tree and the cost the optimizer tracks.
using AfterMove = std::function<void(const Bvh&, double tracked_cost)>;

// optimize_insertion, calling `after_move` after every move.
OptimizeReport optimize_insertion_observed(Bvh& bvh, const InsertionConfig& config, const AfterMove& after_move);

// find_reinsertion by trying every node: the same minimum, computed the same way.
ReinsertionCandidate find_reinsertion_brute_force(const Bvh& bvh, const Box& box, uint32_t skip = kInvalidNode,
                                                  uint32_t pass_through = kInvalidNode);

}  // namespace bvhopt::testing
