#include "bvhopt/triangle_cost.h"

#include <algorithm>

namespace bvhopt {
namespace {

uint32_t common_ancestor(const Bvh& bvh, const std::vector<uint32_t>& depth, uint32_t a, uint32_t b) {
  while (depth[a] > depth[b]) a = bvh[a].parent;
  while (depth[b] > depth[a]) b = bvh[b].parent;
  while (a != b) {
    a = bvh[a].parent;
    b = bvh[b].parent;
  }
  return a;
}

}  // namespace

bool one_slot_per_triangle(const Bvh& bvh, const PrimitiveRefs& refs) {
  uint32_t triangles = 0;
  for (uint32_t t : refs.triangle_ids) triangles = std::max(triangles, t + 1);
  std::vector<bool> seen(triangles, false);
  for (uint32_t r : bvh.ref_indices) {
    const uint32_t t = refs.triangle_ids[r];
    if (seen[t]) return false;
    seen[t] = true;
  }
  return true;
}

// Visiting the leaves in depth-first order, each triangle adds 1 at every leaf holding it
// and -1 at the deepest common ancestor of each two leaves that hold it one after the
// other (the same leaf twice included). Summed over a subtree, the triangles with a
// reference inside then count exactly once: the leaves of one triangle inside a subtree
// form a run in depth-first order, and all but the first of the run's +1 are cancelled by
// ancestors inside the subtree.
std::vector<uint64_t> subtree_triangle_counts(const Bvh& bvh, const PrimitiveRefs& refs) {
  std::vector<uint64_t> count(bvh.nodes.size(), 0);
  if (bvh.empty()) return count;
  const std::vector<uint32_t> order = bvh.depth_first_order();
  std::vector<uint32_t> depth(bvh.nodes.size(), 0);
  for (uint32_t n : order)
    if (n != bvh.root) depth[n] = depth[bvh[n].parent] + 1;
  uint32_t triangles = 0;
  for (uint32_t t : refs.triangle_ids) triangles = std::max(triangles, t + 1);
  std::vector<uint32_t> last_leaf(triangles, kInvalidNode);
  std::vector<int64_t> delta(bvh.nodes.size(), 0);
  for (uint32_t n : order) {
    const BvhNode& nd = bvh[n];
    if (!nd.is_leaf()) continue;
    for (uint32_t k = 0; k < nd.ref_count(); ++k) {
      const uint32_t t = refs.triangle_ids[bvh.ref_indices[nd.first_ref() + k]];
      ++delta[n];
      if (last_leaf[t] != kInvalidNode) --delta[common_ancestor(bvh, depth, last_leaf[t], n)];
      last_leaf[t] = n;
    }
  }
  for (auto it = order.rbegin(); it != order.rend(); ++it) {
    const BvhNode& nd = bvh[*it];
    int64_t sum = delta[*it];
    if (!nd.is_leaf()) sum += static_cast<int64_t>(count[nd.left()] + count[nd.right()]);
    count[*it] = static_cast<uint64_t>(sum);
  }
  return count;
}

double sah_cost(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& model) {
  if (bvh.empty()) return 0.0;
  if (one_slot_per_triangle(bvh, refs)) return sah_cost(bvh, model);
  const std::vector<uint64_t> triangles = subtree_triangle_counts(bvh, refs);
  // The weights sah_cost uses (areas, or the formula's limit for a zero-area root).
  const CostWeights w(bvh);
  std::vector<double> cost(bvh.nodes.size(), 0.0);
  for (uint32_t n : bvh.post_order()) {
    const BvhNode& nd = bvh[n];
    cost[n] = nd.is_leaf() ? leaf_cost(w(nd), static_cast<uint32_t>(triangles[n]), model)
                           : model.traversal * w(nd) + cost[nd.left()] + cost[nd.right()];
  }
  const double c = cost[bvh.root] / w.root();
  check_finite_cost(c, "cost");
  return c;
}

double optimal_collapse_cost(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& model,
                             uint32_t max_leaf_size) {
  if (bvh.empty()) return 0.0;
  if (one_slot_per_triangle(bvh, refs)) return optimal_collapse_cost(bvh, model, max_leaf_size);
  const double c =
      collapse_costs(bvh, model, max_leaf_size, subtree_triangle_counts(bvh, refs)).best[bvh.root] / CostWeights(bvh).root();
  check_finite_cost(c, "ocost");
  return c;
}

TreeStats compute_stats(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& model) {
  TreeStats s = compute_stats(bvh, model);
  if (bvh.empty()) return s;
  s.cost = sah_cost(bvh, refs, model);
  s.ocost = optimal_collapse_cost(bvh, refs, model);
  return s;
}

}  // namespace bvhopt
