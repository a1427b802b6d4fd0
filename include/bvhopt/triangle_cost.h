// The SAH cost of a ray's work when references are split (edge volume subdivision, the
// spatial-split builder): a ray that reaches a leaf intersects each of its triangles once,
// however many of the triangle's references the leaf holds. These count, for each leaf and
// subtree, the distinct triangles behind its references where cost.h counts references.
// The two agree whenever no leaf holds two references of one triangle, and always on trees
// with one reference per leaf (what the builders and optimizers work on).
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/cost.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/references.h"
#include "bvhopt/stats.h"

namespace bvhopt {

// True when no triangle has two of the tree's slots (bvh.ref_indices), as with one
// reference per triangle: then every count below is the plain reference count, and the
// functions here and collapse_leaves take the reference-counting paths of cost.h, which give
// the very same numbers without the per-triangle bookkeeping. O(slots), a bit per triangle.
bool one_slot_per_triangle(const Bvh& bvh, const PrimitiveRefs& refs);
// Per node, the distinct triangles among the references of its subtree (a leaf: of its
// own). Indexed by node; unreachable nodes get 0. O(references x depth).
std::vector<uint64_t> subtree_triangle_counts(const Bvh& bvh, const PrimitiveRefs& refs);

// sah_cost with each leaf's t_N its number of distinct triangles.
double sah_cost(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& model = {});

// optimal_collapse_cost with t(N) the subtree's distinct triangles: what a leaf made of the
// subtree costs once it keeps one reference per triangle (collapse_leaves with references).
double optimal_collapse_cost(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& model = {},
                             uint32_t max_leaf_size = 0);

// compute_stats with cost and ocost counting triangles as above; every other field is
// compute_stats's (`references` stays the number of leaf slots).
TreeStats compute_stats(const Bvh& bvh, const PrimitiveRefs& refs, const CostModel& model = {});

}  // namespace bvhopt
