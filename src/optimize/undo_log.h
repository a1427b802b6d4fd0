// The way back to the best tree of a stage that may raise its cost (insertion's sequential
// form), without copying the tree: each node's record is saved the first time a move is
// about to change it after the restore point, so a pass costs memory and time in what it
// changes, not in the size of the tree.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "bvhopt/bvh.h"

namespace bvhopt::detail {

class UndoLog {
 public:
  // The tree as it is now becomes the restore point.
  void begin(const Bvh& bvh, double tracked_sum) {
    clear_marks();
    if (saved_.size() != (bvh.nodes.size() + 63) / 64) saved_.assign((bvh.nodes.size() + 63) / 64, 0);
    root_ = bvh.root;
    tracked_sum_ = tracked_sum;
    active_ = true;
  }
  // Call before changing node n in any way.
  void save(const Bvh& bvh, uint32_t n) {
    if (!active_) return;
    uint64_t& word = saved_[n >> 6];
    const uint64_t bit = uint64_t{1} << (n & 63);
    if (word & bit) return;
    word |= bit;
    entries_.push_back({n, bvh[n]});
  }
  // Puts back every saved record (each node was saved once, with its restore-point record),
  // the root and the tracked sum; the restore point stays.
  void restore(Bvh& bvh, double& tracked_sum) {
    for (const auto& [n, record] : entries_) bvh[n] = record;
    bvh.root = root_;
    tracked_sum = tracked_sum_;
    clear_marks();
  }
  size_t size() const { return entries_.size(); }
  bool active() const { return active_; }

 private:
  void clear_marks() {
    for (const auto& e : entries_) saved_[e.first >> 6] &= ~(uint64_t{1} << (e.first & 63));
    entries_.clear();
  }

  std::vector<std::pair<uint32_t, BvhNode>> entries_;
  std::vector<uint64_t> saved_;  // one bit per node: its record is in entries_
  uint32_t root_ = kInvalidNode;
  double tracked_sum_ = 0.0;
  bool active_ = false;
};

}  // namespace bvhopt::detail
