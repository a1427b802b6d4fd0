// Median splits: the fast, poor trees that the optimizers are tested against.
#pragma once

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

// The median builders have no settings of their own; they ignore `cost`.
struct MedianConfig : BuilderConfig {};

// Throws Error on a setting out of range (see validate(const BuilderConfig&)).
void validate(const MedianConfig& config);

// Splits the node's box at the middle of its longest axis (as in Bittner et al.); when all
// centroids fall on one side, falls back to the object median.
Bvh build_spatial_median(const PrimitiveRefs& refs, const MedianConfig& config = {});

// Splits the references into two halves by centroid along the longest axis of the
// centroid bounds.
Bvh build_object_median(const PrimitiveRefs& refs, const MedianConfig& config = {});

}  // namespace bvhopt
