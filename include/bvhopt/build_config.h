// Settings every top-down builder shares.
#pragma once

#include <cstdint>

#include "bvhopt/cost_model.h"

namespace bvhopt {

struct LeafConfig {
  // Largest number of references a leaf may hold (at least 1). 1 (the default) gives the
  // one reference per leaf that the optimizers start from.
  uint32_t max_leaf_size = 1;
  // The SAH builders make a leaf of a node holding at most max_leaf_size references only
  // when the leaf costs no more than the best split; the median builders whenever the
  // node fits.
};

// The base of every builder's config (SweepSahConfig, BinnedSahConfig, MedianConfig).
// `leaf` comes first so that `MedianConfig{LeafConfig{4}}` sets the leaf size.
struct BuilderConfig {
  LeafConfig leaf;
  CostModel cost;  // c_T and c_I weigh a split against a leaf (the median builders ignore it)
  // Nodes with fewer references than this are built by one task (no further spawning).
  uint32_t parallel_threshold = 4096;
};

// Throws Error naming the first setting outside its allowed range: max_leaf_size >= 1,
// cost constants finite and >= 0. Every builder checks its config this way on entry.
void validate(const BuilderConfig& config);

}  // namespace bvhopt
