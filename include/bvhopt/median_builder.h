// Median splits: the fast, poor trees that the optimizers are tested against.
#pragma once

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

struct MedianConfig {
  LeafConfig leaf;
  uint32_t parallel_threshold = 4096;
};

// Splits the node's box at the middle of its longest axis (as in Bittner et al.); when all
// centroids fall on one side, falls back to the object median.
Bvh build_spatial_median(const PrimitiveRefs& refs, const MedianConfig& config = {});

// Splits the references into two halves by centroid along the longest axis of the
// centroid bounds.
Bvh build_object_median(const PrimitiveRefs& refs, const MedianConfig& config = {});

}  // namespace bvhopt
