// The tests' oracle for the reinsertion search: every node tried, each total computed the
// way the branch and bound search computes it, so the two minima agree to the last bit.
#include <limits>
#include <vector>

#include "bvhopt/testing/insertion_hooks.h"
#include "optimize/reinsertion_search.h"

namespace bvhopt::testing {

ReinsertionCandidate find_reinsertion_brute_force(const Bvh& bvh, const Box& box, uint32_t skip,
                                                  uint32_t pass_through) {
  ReinsertionCandidate best{kInvalidNode, std::numeric_limits<double>::infinity()};
  if (bvh.empty()) return best;
  std::vector<detail::SearchEntry> stack{{0.0, bvh.root}};
  while (!stack.empty()) {
    const detail::SearchEntry e = stack.back();
    stack.pop_back();
    if (e.node == skip) continue;
    const BvhNode& x = bvh[e.node];
    const double direct = merge(x.box, box).area();
    const double total = e.induced + direct;
    if (total < best.cost && e.node != pass_through) best = {e.node, total};
    if (x.is_leaf()) continue;
    const double child_induced = e.induced + (direct - static_cast<double>(x.area()));
    stack.push_back({child_induced, x.right()});
    stack.push_back({child_induced, x.left()});
  }
  return best;
}

}  // namespace bvhopt::testing
