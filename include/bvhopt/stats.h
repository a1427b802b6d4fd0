// Tree statistics for `bvhopt stats`, the demo table and Bittner's Figure 7.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/references.h"

namespace bvhopt {

struct TreeStats {
  size_t nodes = 0;
  size_t inner_nodes = 0;
  size_t leaves = 0;
  size_t references = 0;        // sum over leaves of their reference counts
  uint32_t max_depth = 0;       // root has depth 0
  double mean_leaf_depth = 0.0;
  uint32_t min_refs_per_leaf = 0;
  uint32_t max_refs_per_leaf = 0;
  double mean_refs_per_leaf = 0.0;
  double cost = 0.0;            // sah_cost
  double ocost = 0.0;           // optimal_collapse_cost, no leaf size limit
  double root_area = 0.0;
  double inner_area_sum = 0.0;  // sum of SA over inner nodes (not normalized)
  double leaf_area_sum = 0.0;   // sum of SA over leaves
  std::vector<double> inner_area_by_depth;  // index = depth
  std::vector<double> leaf_area_by_depth;
};

TreeStats compute_stats(const Bvh& bvh, const CostModel& model = {});

}  // namespace bvhopt

namespace bvhopt {

// Distinct triangles behind the references in the tree's leaves: with subdivided
// references (edge_volume_subdivision.h) several references share a triangle, and the
// ratio references / triangles says what the subdivision cost in memory.
size_t count_distinct_triangles(const Bvh& bvh, const PrimitiveRefs& refs);

}  // namespace bvhopt
