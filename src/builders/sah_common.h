// Internal: small pieces shared by the SAH builders.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "builders/top_down.h"
#include "bvhopt/box.h"
#include "bvhopt/build_config.h"
#include "bvhopt/error.h"
#include "bvhopt/references.h"

namespace bvhopt::detail {

// The one leaf-versus-split test of the SAH builders: a node of at most max_leaf_size
// references becomes a leaf when intersecting all of it costs no more than the split,
// c_I SA(N) n <= c_T SA(N) + c_I (SA(L) n_L + SA(R) n_R) with `split_cost` the bracket.
inline bool sah_prefers_leaf(const BuilderConfig& config, double node_area, size_t count, double split_cost) {
  const double c_t = config.cost.traversal, c_i = config.cost.intersection;
  return count <= config.leaf.max_leaf_size &&
         c_i * node_area * double(count) <= c_t * node_area + c_i * split_cost;
}

// Union of n boxes. Min and max are exact, so the result does not depend on how the
// work is split between threads.
inline Box parallel_bounds(const Box* boxes, size_t n) {
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, n, 16384), Box(),
      [&](const tbb::blocked_range<size_t>& r, Box b) {
        for (size_t i = r.begin(); i < r.end(); ++i) b.extend(boxes[i]);
        return b;
      },
      [](Box a, const Box& b) {
        a.extend(b);
        return a;
      });
}

}  // namespace bvhopt::detail
