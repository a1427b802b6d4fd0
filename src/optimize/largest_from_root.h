// The inner nodes with the largest keys, found from the root down instead of by a scan of
// the node array, for keys that never grow from a node to its children (the insertion
// optimizer's area measure). Private to the library.
//
// Why: the insertion optimizer selects its candidates by area on every pass of its first
// stages and of its last, 1 % of the inner nodes. LargestKeys reads every node for that, the
// whole array (288 MB at 4M triangles) on every pass: at 1M the first stage's passes took
// 15.5 ms with that scan, 9 ms with a best-first walk from the root. A node's box contains
// its children's, and rounding is monotone, so its area is at least theirs: the nodes with
// keys at or above any threshold hang together from the root.
//
// The walk is depth first from a threshold kept from the last call, not best first: the
// keys drift little from pass to pass, and a depth-first walk reads the nodes about in the
// order of the array, on a stack of a few dozen entries, where the best-first one kept a heap
// of about 2k entries (1.3 MB at 4M) and jumped around the array. Hall, 2 threads, a
// selection of the first stage 13 -> 7.7 ms at 4M triangles (40k keys), of the sequential
// stage's top window 30 -> 8.7 ms; at 1M 1.8 -> 1.6 and 2.8 -> 2.0 ms. (Since, the walk
// runs on all threads and the thresholds last a whole run: gather_from.)
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "bvhopt/bvh.h"
#include "optimize/reinsertion_search.h"

namespace bvhopt::detail {

class LargestFromRoot {
 public:
  // Whether the walk is worth it over a scan: it reads about 3k nodes, a scan all of them.
  static bool pays(size_t node_count, size_t k) { return 32 * k <= node_count; }

  // How the last call found the keys (for tests: each way must give the same keys).
  enum class Path {
    from_threshold,  // depth first from the threshold kept for this k
    best_first,      // best first from the root: no threshold, or it was off
    declined,        // neither: the caller scans
  };
  Path last_path() const { return last_path_; }

  // The k largest keys of the inner nodes below the root (key_of(i); the root itself is
  // left out), largest first, in `out`: exactly what LargestKeys::largest gives over the
  // inner nodes when the root's key is the smallest of all. key_of's upper 32 bits must never
  // grow from a node to a child (the lower ones break ties: they may, which is why every node
  // tied with the k-th is gathered before the sort). Returns false, with `out` unspecified,
  // where the walk would read much of the tree: so many nodes tied with the k-th (zero-area
  // boxes, all tied at 0) that a scan is cheaper, and 0 itself, where the root's key ties.
  template <class KeyOf>
  bool largest(const Bvh& bvh, size_t k, const KeyOf& key_of, std::vector<uint64_t>& out) {
    out.clear();
    last_path_ = Path::best_first;
    if (k == 0 || bvh.empty() || bvh[bvh.root].is_leaf()) return true;
    uint32_t& guess = guess_for(k);
    // With a threshold for this k: every node at or above it. One too high (fewer than k at
    // or above it, as one derived from another k's often is) is lowered by the shortfall and
    // walked again, up to twice: the number of nodes at or above an area goes about as the
    // inverse of the area, and at 4M triangles such a walk takes about 4 ms where the
    // best-first one took 50-80 (its heap of up to k entries). With none, one too low (far
    // more than k) or still too high, the best-first walk, which finds the threshold.
    // Either way every node tied with the k-th is among those gathered, so the sort gives
    // exactly the k largest.
    for (int walk = 0; walk < 3 && guess != 0; ++walk) {
      if (!gather_from(bvh, guess, 4 * k + 4096, key_of, out)) break;
      if (out.size() >= k) {
        last_path_ = Path::from_threshold;
        return finish(k, out, guess);
      }
      if (out.empty()) break;
      guess = std::bit_cast<uint32_t>(std::bit_cast<float>(guess) *
                                      (0.9f * static_cast<float>(static_cast<double>(out.size()) / static_cast<double>(k))));
    }
    if (!best_first(bvh, k, key_of, out)) {
      last_path_ = Path::declined;
      guess = 0;
      return false;
    }
    return finish(k, out, guess);
  }

 private:
  // The nodes met best first until the k-th key's upper bits are passed (more when a child
  // is tied with its parent and numbered before it: the order is fixed by the final sort);
  // false where ties at the k-th key take over or the k-th key is 0.
  template <class KeyOf>
  bool best_first(const Bvh& bvh, size_t k, const KeyOf& key_of, std::vector<uint64_t>& out) {
    out.clear();
    heap_.clear();
    const BvhNode* nodes = bvh.nodes.data();
    auto push_children = [&](const BvhNode& n) {
      for (int side = 0; side < 2; ++side) {
        const uint32_t c = n.child(side);
        const BvhNode& cn = nodes[c];
        if (cn.is_leaf()) continue;
        // Its children are read when it is popped, usually several pops later.
        prefetch_children(nodes, cn);
        heap_.push_back({key_of(c), c});
        std::push_heap(heap_.begin(), heap_.end());
      }
    };
    const BvhNode& root = nodes[bvh.root];
    if (root.is_leaf()) return true;
    push_children(root);
    // Past this many, ties at the k-th key are taking over: a scan does better.
    const size_t most = 2 * k + 1024;
    uint32_t threshold = 0;  // the k-th key's upper bits, once k are out
    while (!heap_.empty()) {
      std::pop_heap(heap_.begin(), heap_.end());
      const auto [key, node] = heap_.back();
      heap_.pop_back();
      const uint32_t upper = static_cast<uint32_t>(key >> 32);
      if (out.size() >= k && upper < threshold) break;
      out.push_back(key);
      if (out.size() == k) {
        threshold = upper;
        if (threshold == 0) return false;
      }
      if (out.size() > most) return false;
      push_children(nodes[node]);
    }
    return true;
  }

  // Every inner node below the root whose key's upper bits are at least `threshold`, in
  // `out` in no particular order; false (out unspecified) past `most` of them.
  //
  // Why it is shaped so: the walk is bound by misses on the node array (at 4M triangles its
  // 80k or so nodes are spread over 288 MB). The first few levels are walked here, then
  // their subtrees on all threads; and each walk takes the entry kAhead below the top of
  // its stack, not the top, so that the node it reads was asked for when it was pushed, at
  // least kAhead pops before, where popping the top waited on each node. Any order gathers
  // the same nodes (all at or above the threshold, which hang together from the root), and
  // finish() sorts them: the same keys on any thread count. Hall, 2 threads, a converged
  // run's selections from the root (walks and sorts): 4M triangles 0.95 -> 0.45 s, with the
  // thresholds kept from stage to stage and a threshold a little too high walked again
  // (largest()); 1M 0.14 -> 0.08 s.
  static constexpr size_t kAhead = 16;
  static constexpr size_t kSubtrees = 64;
  template <class KeyOf>
  bool gather_from(const Bvh& bvh, uint32_t threshold, size_t most, const KeyOf& key_of, std::vector<uint64_t>& out) {
    out.clear();
    const BvhNode* nodes = bvh.nodes.data();
    // The first levels breadth first, until kSubtrees subtrees are left to walk.
    std::vector<uint32_t>& tops = stack_;
    tops.clear();
    const BvhNode& root = nodes[bvh.root];
    tops.push_back(root.left());
    tops.push_back(root.right());
    size_t head = 0;
    while (head < tops.size() && tops.size() - head < kSubtrees) {
      const uint32_t v = tops[head++];
      const BvhNode& n = nodes[v];
      if (n.is_leaf()) continue;
      const uint64_t key = key_of(v);
      if (static_cast<uint32_t>(key >> 32) < threshold) continue;
      if (out.size() == most) return false;
      out.push_back(key);
      tops.push_back(n.left());
      tops.push_back(n.right());
    }
    std::atomic<size_t> gathered = out.size();
    std::atomic<bool> over = false;
    for (Walker& w : walkers_) w.keys.clear();
    tbb::parallel_for(tbb::blocked_range<size_t>(head, tops.size(), 1), [&](const tbb::blocked_range<size_t>& r) {
      Walker& w = walkers_.local();
      for (size_t t = r.begin(); t < r.end() && !over.load(std::memory_order_relaxed); ++t) {
        w.stack.assign(1, tops[t]);
        size_t counted = w.keys.size();
        while (!w.stack.empty()) {
          const size_t at = w.stack.size() > kAhead ? w.stack.size() - 1 - kAhead : 0;
          const uint32_t v = w.stack[at];
          w.stack[at] = w.stack.back();
          w.stack.pop_back();
          const BvhNode& n = nodes[v];
          if (n.is_leaf()) continue;
          const uint64_t key = key_of(v);
          if (static_cast<uint32_t>(key >> 32) < threshold) continue;
          w.keys.push_back(key);
          prefetch_children(nodes, n);
          w.stack.push_back(n.right());
          w.stack.push_back(n.left());
          // The count against `most` is shared now and then, so that a threshold far too
          // low stops every walk soon, without a shared counter on every node.
          if (w.keys.size() - counted == 1024) {
            if (gathered.fetch_add(1024, std::memory_order_relaxed) + 1024 > most) over = true;
            counted = w.keys.size();
            if (over.load(std::memory_order_relaxed)) break;
          }
        }
        if (gathered.fetch_add(w.keys.size() - counted, std::memory_order_relaxed) + (w.keys.size() - counted) > most)
          over = true;
      }
    });
    if (over) return false;
    for (const Walker& w : walkers_) out.insert(out.end(), w.keys.begin(), w.keys.end());
    return true;
  }

  // The k largest of `out` (all of them when fewer), largest first, and the next call's
  // threshold for this k: a little below the k-th key, so that the keys' drift from pass
  // to pass rarely takes it above the next k-th.
  static bool finish(size_t k, std::vector<uint64_t>& out, uint32_t& guess) {
    if (out.empty()) return true;
    k = std::min(k, out.size());
    std::nth_element(out.begin(), out.begin() + (k - 1), out.end(), std::greater<uint64_t>());
    // On all threads: at 4M triangles a sort of the 40k-200k keys was half the selection's
    // time (3.8 ms a call on one thread, 2.5 on two). The keys are distinct, so the order is
    // the same on any thread count.
    tbb::parallel_sort(out.begin(), out.begin() + k, std::greater<uint64_t>());
    out.resize(k);
    guess = std::bit_cast<uint32_t>(std::bit_cast<float>(static_cast<uint32_t>(out.back() >> 32)) * 0.95f);
    return true;
  }

  // The threshold kept for k (0: none), among the last few k asked for. A k not among them
  // starts from the nearest one's, scaled by their ratio: the number of nodes at or above an
  // area goes about as the inverse of the area (the windows of the ranking ask for 1 to 8
  // times one k, each the first time without a threshold of its own).
  uint32_t& guess_for(size_t k) {
    const std::pair<size_t, uint32_t>* near = nullptr;
    for (auto& entry : guesses_) {
      if (entry.first == k) return entry.second;
      if (entry.second != 0 && (near == nullptr || std::max(entry.first, k) * std::min(near->first, k) <
                                                       std::max(near->first, k) * std::min(entry.first, k)))
        near = &entry;
    }
    const uint32_t derived =
        near == nullptr ? 0
                        : std::bit_cast<uint32_t>(std::bit_cast<float>(near->second) *
                                                  static_cast<float>(static_cast<double>(near->first) / static_cast<double>(k)));
    auto& slot = guesses_[next_guess_++ % guesses_.size()];
    slot = {k, derived};
    return slot.second;
  }

  std::vector<std::pair<uint64_t, uint32_t>> heap_;  // the frontier's keys and nodes, a max-heap
  std::vector<uint32_t> stack_;  // gather_from's first levels
  struct Walker {
    std::vector<uint32_t> stack;
    std::vector<uint64_t> keys;
  };
  tbb::enumerable_thread_specific<Walker> walkers_;  // gather_from's walks of the subtrees
  std::array<std::pair<size_t, uint32_t>, 16> guesses_{};  // k and its threshold's bits
  size_t next_guess_ = 0;
  Path last_path_ = Path::best_first;
};

}  // namespace bvhopt::detail
