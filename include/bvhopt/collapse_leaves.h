// BVH compaction (Bittner et al. 2013, section 2.6): after optimizing a tree with one
// reference per leaf, collapse every subtree whose references cost less as one leaf.
#pragma once

#include <cstdint>

#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/references.h"

namespace bvhopt {

struct CollapseConfig {
  CostModel cost;  // c_T and c_I decide where a leaf beats a subtree
  // A subtree holding more references than this is never collapsed; 0 (the default) = no
  // limit, the paper's `ocost`. Tracers with a fixed leaf capacity set it (e.g. 8).
  uint32_t max_leaf_size = 0;
};

struct CollapseResult {
  double cost_before = 0.0;   // sah_cost before
  double cost_after = 0.0;    // sah_cost after; equals optimal_collapse_cost(before)
  uint64_t leaves_before = 0;
  uint64_t leaves_after = 0;
  uint64_t nodes_before = 0;  // reachable nodes
  uint64_t nodes_after = 0;
  // With references: slots dropped because their leaf already held their triangle.
  uint64_t dropped_references = 0;
};

// Bottom-up, a subtree becomes one leaf wherever c_I * SA(N) * t(N) is no more than its
// cost as a tree (after the collapses below it). The new leaf's references are its old
// leaves' references in depth-first order, so every leaf's slots stay contiguous; then
// bvh.renumber_depth_first() renumbers the nodes depth-first. Never raises the cost.
CollapseResult collapse_leaves(Bvh& bvh, const CollapseConfig& config = {});

// The same over split references (edge volume subdivision, the sbvh builder): t(N) counts
// the distinct triangles of a subtree (triangle_cost.h), and every new leaf keeps one
// reference per triangle (dedup_leaf_references, whose notes apply: check the result with
// validate_deduplicated). cost_before and cost_after are sah_cost with references; the
// latter equals optimal_collapse_cost(before, refs). The same as the plain collapse when
// no subtree holds two references of one triangle.
CollapseResult collapse_leaves(Bvh& bvh, const PrimitiveRefs& refs, const CollapseConfig& config = {});

}  // namespace bvhopt
