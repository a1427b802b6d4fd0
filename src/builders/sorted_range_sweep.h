// Internal: the exact SAH sweep over one axis's sorted references, shared by the sweep
// builder and the binned builder's small nodes.
#pragma once

#include <cstddef>
#include <limits>

#include "bvhopt/box.h"

namespace bvhopt::detail {

// A candidate split of a sorted range: the first `left_count` references go left.
struct SweepCandidate {
  size_t left_count = 0;
  double cost = std::numeric_limits<double>::infinity();  // SA(L) n_L + SA(R) n_R
  size_t balance = ~size_t(0);                          // |n_L - n_R|
};

// Lower cost wins, then the more balanced split; on exact ties the earlier candidate
// (lower axis, lower position) stays, so a node of coincident references is halved
// instead of peeled one by one.
inline bool better_candidate(const SweepCandidate& a, const SweepCandidate& b) {
  return a.cost < b.cost || (a.cost == b.cost && a.balance < b.balance);
}

// Sweeps `count` references in sorted order; every position between two of them is a
// candidate. `extend(box, k)` adds the k-th reference's box; `suffix_area(k)` is a double
// slot that receives the area of references [k, count). Returns the best candidate by
// better_candidate, the first one on exact ties.
template <class Extend, class SuffixArea>
SweepCandidate sweep_sorted_range(size_t count, const Extend& extend, const SuffixArea& suffix_area) {
  Box right;
  for (size_t k = count - 1; k > 0; --k) {
    extend(right, k);
    suffix_area(k) = right.area_unchecked();
  }
  SweepCandidate best;
  Box left;
  for (size_t k = 1; k < count; ++k) {
    extend(left, k - 1);
    double c = left.area_unchecked() * double(k) + suffix_area(k) * double(count - k);
    if (c <= best.cost) {
      size_t balance = k * 2 > count ? k * 2 - count : count - k * 2;
      if (c < best.cost || balance < best.balance) best = SweepCandidate{k, c, balance};
    }
  }
  return best;
}

}  // namespace bvhopt::detail

namespace bvhopt::detail {

// After a split on one axis, the other axes' sorted lists are filtered by side: the left
// entries move to the front and the right ones after them, each in their sorted order.
// `spill(k)` is a slot holding the k-th right entry meanwhile.
template <class T, class IsLeft, class Spill>
void stable_partition_by_side(T* list, size_t count, const IsLeft& is_left, const Spill& spill) {
  size_t l = 0, r = 0;
  for (size_t k = 0; k < count; ++k) {
    const T entry = list[k];
    if (is_left(entry))
      list[l++] = entry;
    else
      spill(r++) = entry;
  }
  for (size_t k = 0; k < r; ++k) list[l + k] = spill(k);
}

}  // namespace bvhopt::detail
