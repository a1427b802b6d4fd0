#include "bvhopt/stats.h"

#include <algorithm>
#include <limits>

#include "bvhopt/cost.h"

namespace bvhopt {

// Expects a valid tree (see validate()). Areas are the nodes' area(), the same
// numbers the cost functions read, so the sums and the cost agree.
TreeStats compute_stats(const Bvh& bvh, const CostModel& model) {
  TreeStats s;
  if (bvh.empty()) return s;

  // Pre-order with an explicit stack of (node, depth): parents before children, so the
  // depth of each node is known when it is popped.
  std::vector<std::pair<uint32_t, uint32_t>> stack{{bvh.root, 0}};
  uint64_t leaf_depth_sum = 0;
  uint32_t min_refs = std::numeric_limits<uint32_t>::max();
  while (!stack.empty()) {
    auto [n, depth] = stack.back();
    stack.pop_back();
    const BvhNode& nd = bvh[n];
    ++s.nodes;
    s.max_depth = std::max(s.max_depth, depth);
    if (s.inner_area_by_depth.size() <= depth) {
      s.inner_area_by_depth.resize(depth + 1, 0.0);
      s.leaf_area_by_depth.resize(depth + 1, 0.0);
    }
    const double area = nd.area();
    if (nd.is_leaf()) {
      ++s.leaves;
      const uint32_t c = nd.ref_count();
      s.references += c;
      min_refs = std::min(min_refs, c);
      s.max_refs_per_leaf = std::max(s.max_refs_per_leaf, c);
      leaf_depth_sum += depth;
      s.leaf_area_sum += area;
      s.leaf_area_by_depth[depth] += area;
    } else {
      ++s.inner_nodes;
      s.inner_area_sum += area;
      s.inner_area_by_depth[depth] += area;
      stack.push_back({nd.right(), depth + 1});
      stack.push_back({nd.left(), depth + 1});
    }
  }
  s.min_refs_per_leaf = s.leaves ? min_refs : 0;
  s.mean_leaf_depth = s.leaves ? static_cast<double>(leaf_depth_sum) / static_cast<double>(s.leaves) : 0.0;
  s.mean_refs_per_leaf = s.leaves ? static_cast<double>(s.references) / static_cast<double>(s.leaves) : 0.0;
  s.root_area = bvh[bvh.root].area();
  s.cost = sah_cost(bvh, model);
  s.ocost = optimal_collapse_cost(bvh, model, 0);
  return s;
}

}  // namespace bvhopt

namespace bvhopt {

size_t count_distinct_triangles(const Bvh& bvh, const PrimitiveRefs& refs) {
  uint32_t max_id = 0;
  for (uint32_t t : refs.triangle_ids) max_id = std::max(max_id, t);
  std::vector<uint8_t> seen(refs.empty() ? 0 : size_t(max_id) + 1, 0);
  size_t distinct = 0;
  for (uint32_t n : bvh.depth_first_order()) {
    const BvhNode& nd = bvh[n];
    if (!nd.is_leaf()) continue;
    for (uint32_t i = 0; i < nd.ref_count(); ++i) {
      uint32_t t = refs.triangle_ids[bvh.ref_indices[nd.first_ref() + i]];
      distinct += !seen[t];
      seen[t] = 1;
    }
  }
  return distinct;
}

}  // namespace bvhopt
