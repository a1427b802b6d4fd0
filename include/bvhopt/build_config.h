// Settings every top-down builder shares.
#pragma once

#include <cstdint>

#include "bvhopt/cost_model.h"

namespace bvhopt {

struct LeafConfig {
  // Largest number of references a leaf may hold. 1 (the default) gives the one
  // reference per leaf that the optimizers start from.
  uint32_t max_leaf_size = 1;
  // The SAH builders make a leaf of a node holding at most max_leaf_size references only
  // when the leaf costs no more than the best split; the median builders whenever the
  // node fits.
};

}  // namespace bvhopt
