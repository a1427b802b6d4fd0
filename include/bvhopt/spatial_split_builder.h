// Spatial-split SAH builder (Stich, Friedrich and Dietrich 2009, "SBVH"): a reference may be
// split by a plane into two clipped pieces, one on each side, when that lowers the SAH.
#pragma once

#include <cstddef>
#include <cstdint>

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"

namespace bvhopt {

// What only the spatial-split builder has; BuildOptions carries it next to the shared settings.
struct SpatialSplitParams {
  // At most budget * triangles references in the tree (never fewer than it was given). The
  // split that would pass it is not taken: the budget is never exceeded.
  double budget = 1.3;
  // Spatial splits are tried at a node only when its best object split's two boxes overlap
  // by more than alpha times the root's surface area (the paper's alpha).
  double alpha = 1e-5;
  // ... and by more than node_alpha times the node's own surface area. Where the children
  // barely overlap for their size, a spatial split seldom wins, and its binning (each
  // crossing reference cut at every slab plane it crosses) was over a third of the build on
  // the architectural scenes. At 0.1 classroom and staircase built with about 10 % fewer
  // instructions, and no cost rose by more than 0.4 % (nefertiti 100.75 -> 101.13,
  // staircase 46.84 -> 46.90; all still below Embree HIGH's); at 0.15 2CylinderEngine rose
  // to 258.98, above Embree's 258.90. 0: alpha's test alone.
  double node_alpha = 0.1;
  // Bins per axis over the node's box (2 to 128); a node of n references uses at most
  // 4 + n / 2 of them.
  uint32_t spatial_bins = 32;
  // Nodes of fewer references take object splits only. The split's SAH counts each child as
  // a leaf, which near the leaves undervalues what a spatial split's extra references cost
  // below it: on the shared scenes, spatial splits in nodes of 2 to 7 references raised the
  // cost slightly (Conference 104.90 without them, 104.91 with, at 1.049 references per
  // triangle instead of 1.063) and took about a third of the build. 0 tries them everywhere.
  uint32_t spatial_from = 8;
  // Nodes of more references than this take object splits only (0: no limit). Spatial splits
  // near the root win the greedy SAH but fix the duplicated references in place: insertion
  // optimization moves subtrees, never merges a triangle's pieces again. bake --quality best
  // tries a start limited to 256 (see docs/spatial-splits.md for what it gains and where).
  uint32_t spatial_max = 0;
  // Object splits are binned by box centre: a node of n references uses
  // clamp(n / 256, object_bins, 128) bins, at most 4 + n / 5 (as the binned builder).
  uint32_t object_bins = 32;  // 2 to 128
  // Nodes of at most this many references find their object split by the exact sweep over
  // their references sorted by box centre instead (0 to 65536), at a sort per node. Off by
  // default: with spatial splits it raised the cost on staircase (48.24 at 256, 48.61 at
  // every node, against 47.85 binned), though alone it is the sweep builder's lower cost.
  uint32_t exact_sweep_below = 0;
  // Nodes with at least this many references bin and partition in parallel.
  uint32_t parallel_binning_threshold = 8192;
};

struct SpatialSplitConfig : BuilderConfig, SpatialSplitParams {};

// Throws Error naming a setting out of its range: budget finite and >= 1, alpha and
// node_alpha finite and >= 0, spatial_bins and object_bins 2 to 128, exact_sweep_below 0 to 65536, and those of
// validate(const BuilderConfig&).
void validate(const SpatialSplitConfig& config);

struct SpatialSplitStats {
  size_t input_references = 0;
  size_t references = 0;        // in the result
  size_t budget = 0;            // most references allowed
  size_t spatial_splits = 0;    // nodes split by a plane through references
  size_t object_splits = 0;
  size_t split_references = 0;  // references cut into two pieces, over all spatial splits
  size_t unsplit_references = 0;  // straddling references sent whole to one side instead
};

// The builder's result: a tree over new references, which it made from the ones it was
// given (each a box bounding the part of its triangle it stands for: a whole triangle, or
// an edge volume subdivision piece). Every reference keeps its triangle id; the leaves'
// references are numbered in depth-first order (ref_indices is 0, 1, 2, ...). A leaf never
// holds two references of one triangle (they are merged into one whose box is their union).
struct SpatialSplitResult {
  Bvh bvh;
  PrimitiveRefs refs;
  SpatialSplitStats stats;
};

// Each node takes the cheaper of the best object split (binned over box centres) and, when
// its boxes overlap by more than alpha (of the root's area) and node_alpha (of the node's)
// and it holds at least spatial_from references, the
// best spatial split: binned over the node's box, where a reference crossing bins adds to
// each bin its triangle's piece in that slab (bounded in float: the bins only estimate the
// cost). The chosen split cuts its crossing references exactly (slice_triangle,
// triangle_clipping.h) and intersects each piece with the reference's box; a crossing
// reference goes whole to one side when that is cheaper (the paper's reference
// unsplitting). Each subtree owns a fixed range of reference slots whose spare room is
// shared between the children by their SAH weights (count times surface area), so the
// budget holds without any shared counter, and the tree is the same on any number of
// threads. A subtree of fewer than
// parallel_threshold references is built by one task, left child first, and the room its
// left child leaves unused goes to the right one (so parallel_threshold shapes the tree;
// the number of threads does not). Leaf boxes and inner boxes are refitted to the final
// references.
SpatialSplitResult build_spatial_split(const Mesh& mesh, const PrimitiveRefs& refs,
                                       const SpatialSplitConfig& config = {});

}  // namespace bvhopt
