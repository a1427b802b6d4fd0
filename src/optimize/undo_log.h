// The way back to the best tree of a stage that may raise its cost (insertion's sequential
// form), without copying the tree: each node's record is saved the first time a move is
// about to change it after the restore point, so a pass costs memory and time in what it
// changes, not in the size of the tree.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "bvhopt/bvh.h"
#include "optimize/node_set.h"

namespace bvhopt::detail {

class UndoLog {
 public:
  // The tree as it is now becomes the restore point. `tracked_sum` is given back with it.
  void begin(const Bvh& bvh, double tracked_sum) {
    saved_.reset(bvh.nodes.size());
    entries_.clear();
    root_ = bvh.root;
    tracked_sum_ = tracked_sum;
    active_ = true;
  }
  // Call before changing node n in any way.
  void save(const Bvh& bvh, uint32_t n) {
    if (active_ && saved_.insert(n)) entries_.push_back({n, bvh[n]});
  }
  // Puts back every saved record (each node was saved once, with its restore-point record),
  // the root and the tracked sum; the restore point stays.
  void restore(Bvh& bvh, double& tracked_sum) {
    for (const auto& [n, record] : entries_) bvh[n] = record;
    bvh.root = root_;
    tracked_sum = tracked_sum_;
    saved_.clear();
    entries_.clear();
  }
  size_t size() const { return entries_.size(); }
  double restore_point_sum() const { return tracked_sum_; }
  // Room for `entries` records, reserved once so that the log's memory is known.
  void reserve(size_t entries) { entries_.reserve(entries); }
  size_t capacity() const { return entries_.capacity(); }

 private:
  std::vector<std::pair<uint32_t, BvhNode>> entries_;
  NodeSet saved_;
  uint32_t root_ = kInvalidNode;
  double tracked_sum_ = 0.0;
  bool active_ = false;
};

}  // namespace bvhopt::detail
