// Binned SAH (Wald 2007).
#pragma once

#include <cstdint>

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

struct BinnedSahConfig {
  CostModel cost;
  LeafConfig leaf;
  uint32_t bin_count = 32;  // bins per axis over the node's centroid bounds
  uint32_t parallel_threshold = 4096;
};

Bvh build_binned_sah(const PrimitiveRefs& refs, const BinnedSahConfig& config = {});

}  // namespace bvhopt
