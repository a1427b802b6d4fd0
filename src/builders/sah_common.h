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
#include "bvhopt/error.h"
#include "bvhopt/references.h"

namespace bvhopt::detail {

// Node indices and leaf counts are 32-bit with a flag bit: 2n - 1 nodes must fit below it.
inline void check_reference_count(size_t n, const char* builder) {
  if (n > 0x7fffffffu)
    throw Error(std::string(builder) + ": " + std::to_string(n) +
                " references, more than the 2^31 - 1 a tree can hold");
}

inline Box bounds_of_ids(const PrimitiveRefs& refs, const uint32_t* ids, size_t count) {
  Box b;
  for (size_t i = 0; i < count; ++i) b.extend(refs.boxes[ids[i]]);
  return b;
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
