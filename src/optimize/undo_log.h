// The way back to the best tree of a stage that may raise its cost (insertion's sequential
// and regional forms), without copying the tree: each node's record is saved the first time
// a move is about to change it after the restore point, so a pass costs memory and time in
// what it changes, not in the size of the tree.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "bvhopt/bvh.h"
#include "optimize/node_set.h"

namespace bvhopt::detail {

class UndoLog {
 public:
  using Entry = std::pair<uint32_t, BvhNode>;

  // The tree as it is now becomes the restore point. `tracked_sum` is given back with it.
  void begin(const Bvh& bvh, double tracked_sum) {
    saved_.reset(bvh.nodes.size());
    size_ = 0;
    root_ = bvh.root;
    tracked_sum_ = tracked_sum;
    active_ = true;
  }
  // Call before changing node n in any way.
  void save(const Bvh& bvh, uint32_t n) {
    if (active_ && saved_.insert(n)) push({n, bvh[n]});
  }
  // Puts back every saved record (each node was saved once, with its restore-point record,
  // so the order does not matter), the root and the tracked sum; the restore point stays.
  void restore(Bvh& bvh, double& tracked_sum) {
    for (size_t i = 0; i < size_; ++i) bvh[entries_[i].first] = entries_[i].second;
    bvh.root = root_;
    tracked_sum = tracked_sum_;
    saved_.clear();
    size_ = 0;
  }
  size_t size() const { return size_; }
  bool active() const { return active_; }
  double restore_point_sum() const { return tracked_sum_; }
  // Room for `entries` records, allocated once so that the log's memory is known; past it the
  // log still grows.
  void reserve(size_t entries) {
    if (entries_.size() < entries) entries_.resize(entries);
  }
  size_t capacity() const { return entries_.size(); }

  // Lanes: records of threads that change disjoint parts of the tree at once (the regional
  // passes). Each lane writes into its own share of the room past the log's records, so the
  // lanes take no memory of their own; a lane whose share runs out keeps the rest apart.
  // A node is still saved once, whichever lane saves it.
  struct Lane {
    size_t begin = 0, next = 0, end = 0;
    std::vector<Entry> overflow;
  };
  // Shares the room among lanes.size() lanes, in proportion to `weights`.
  void open_lanes(const std::vector<size_t>& weights, std::vector<Lane>& lanes) {
    lanes.resize(weights.size());
    size_t total = 0;
    for (size_t w : weights) total += w;
    const size_t room = entries_.size() - size_;
    size_t at = size_;
    for (size_t j = 0; j < weights.size(); ++j) {
      const size_t share = total == 0 ? 0 : static_cast<size_t>(static_cast<double>(room) * weights[j] / total);
      lanes[j].begin = lanes[j].next = at;
      lanes[j].end = at = std::min(at + share, entries_.size());
      lanes[j].overflow.clear();
    }
  }
  void save(const Bvh& bvh, uint32_t n, Lane& lane) {
    if (!active_ || !saved_.insert_shared(n)) return;
    if (lane.next < lane.end)
      entries_[lane.next++] = {n, bvh[n]};
    else
      lane.overflow.push_back({n, bvh[n]});
  }
  // Gathers the lanes' records after the log's: each share moves down in lane order (shares
  // lie in that order, so nothing is overwritten before it moves), then every overflow.
  void close_lanes(std::vector<Lane>& lanes) {
    for (Lane& l : lanes) {
      for (size_t i = l.begin; i < l.next; ++i) saved_.adopt(entries_[i].first);
      if (l.begin != size_) std::copy(entries_.begin() + l.begin, entries_.begin() + l.next, entries_.begin() + size_);
      size_ += l.next - l.begin;
      l.begin = l.next = l.end = size_;
    }
    for (Lane& l : lanes) {
      for (const Entry& e : l.overflow) {
        saved_.adopt(e.first);
        push(e);
      }
      l.overflow.clear();
      l.overflow.shrink_to_fit();
    }
  }

 private:
  void push(const Entry& e) {
    if (size_ < entries_.size())
      entries_[size_] = e;
    else
      entries_.push_back(e);
    ++size_;
  }

  std::vector<Entry> entries_;  // the first size_ are the records
  size_t size_ = 0;
  NodeSet saved_;
  uint32_t root_ = kInvalidNode;
  double tracked_sum_ = 0.0;
  bool active_ = false;
};

}  // namespace bvhopt::detail
