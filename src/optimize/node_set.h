// A set of node ids for the optimizers' scratch: one bit per node, cleared in time
// proportional to what was added (the members are listed), so a pass that marks a few
// nodes of a huge tree neither scans nor reallocates a per-node array.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

namespace bvhopt::detail {

class NodeSet {
 public:
  // Empties the set and makes room for ids below `node_count`.
  void reset(size_t node_count) {
    clear();
    if (bits_.size() != (node_count + 63) / 64) bits_.assign((node_count + 63) / 64, 0);
  }
  bool contains(uint32_t n) const { return (bits_[n >> 6] >> (n & 63)) & 1u; }
  // False if n was already in.
  bool insert(uint32_t n) {
    uint64_t& word = bits_[n >> 6];
    const uint64_t bit = uint64_t{1} << (n & 63);
    if (word & bit) return false;
    word |= bit;
    members_.push_back(n);
    return true;
  }
  // insert() for threads that share the set, each inserting ids of its own: the bit is set
  // atomically (ids of different threads may share a word) and the id is not listed; the
  // caller lists it with adopt() once the threads are done.
  bool insert_shared(uint32_t n) {
    const uint64_t bit = uint64_t{1} << (n & 63);
    return !(std::atomic_ref<uint64_t>(bits_[n >> 6]).fetch_or(bit, std::memory_order_relaxed) & bit);
  }
  void adopt(uint32_t n) { members_.push_back(n); }
  void clear() {
    for (uint32_t n : members_) bits_[n >> 6] = 0;
    members_.clear();
  }
  size_t size() const { return members_.size(); }
  // The members in the order they went in.
  const std::vector<uint32_t>& members() const { return members_; }

 private:
  std::vector<uint64_t> bits_;
  std::vector<uint32_t> members_;
};

// A set of node ids filled once and then only read: bits alone, with no list of members
// (a list of every inner node of a 4M-triangle tree would take 16 MB).
class NodeBits {
 public:
  void reset(size_t node_count) { bits_.assign((node_count + 63) / 64, 0); }
  void insert(uint32_t n) { bits_[n >> 6] |= uint64_t{1} << (n & 63); }
  bool contains(uint32_t n) const { return (bits_[n >> 6] >> (n & 63)) & 1u; }

 private:
  std::vector<uint64_t> bits_;
};

}  // namespace bvhopt::detail
