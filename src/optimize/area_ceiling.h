// An upper bound of each node's area, kept as a float in the node's spare word, that lets the
// reinsertion searches drop most children without computing their area in double.
//
// A bound, not a cached area: a search queues a child only if its exact bound beats the best
// cost, and the bound taken with an area that is too large is never larger (IEEE rounding is
// monotone), so a child the ceiling drops is one the exact test drops too. The searches then
// make exactly the decisions they make without it: the same trees and costs, at any scale.
// The float holds area * 2^s with 2^s from the root's area, so it stays in range at any
// scene scale; a power of two scales exactly, and the float is raised until it bounds.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "bvhopt/bvh.h"

namespace bvhopt::detail {

class AreaCeilings {
 public:
  // Inactive: bound() is +inf, so no child is dropped by it.
  AreaCeilings() = default;
  // For a tree whose root has this area (positive): areas up to it are kept below 2.
  explicit AreaCeilings(double root_area)
      : scale_(std::ldexp(1.0, -std::ilogb(root_area))), unscale_(std::ldexp(1.0, std::ilogb(root_area))) {}

  bool active() const { return unscale_ != 0.0; }

  // At least n's area in double, if n's ceiling was stored since its box last changed.
  double bound(const BvhNode& n) const {
    if (!active()) return std::numeric_limits<double>::infinity();
    return static_cast<double>(std::bit_cast<float>(n.spare)) * unscale_;
  }

  // The ceiling of n's box as it is now: the least float whose bound() is at least the area.
  uint32_t ceiling(const BvhNode& n) const {
    const double a = n.area();
    float f = static_cast<float>(a * scale_);
    while (static_cast<double>(f) * unscale_ < a) f = std::nextafter(f, std::numeric_limits<float>::infinity());
    return std::bit_cast<uint32_t>(f);
  }
  void store(BvhNode& n) const { n.spare = ceiling(n); }

 private:
  double scale_ = 0.0;
  double unscale_ = 0.0;
};

}  // namespace bvhopt::detail
