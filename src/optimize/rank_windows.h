// Selection of an optimizer's candidates in windows of a ranking (private to the library):
// pass after pass, the next batch down the ranking instead of its top every time.
//
// Why: the insertion optimizer's paper selection takes the k nodes of largest measure on
// every pass. Once those are well placed its passes only shuffle them (hall 4M: after three
// passes, eight more gained 2 units in 0.9 s before the stage stalled), and the nodes just
// below them are never chosen; the random passes that follow choose mostly the small nodes
// near the leaves, where an update gains least. Windows reach down the ranking a batch at a
// time, and come back to the top, whose nodes keep gaining as the ones below them move.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "optimize/largest_keys.h"

namespace bvhopt::detail {

class RankWindows {
 public:
  enum class Order {
    // Pass i of the stage (from 1) takes window min(trailing zeros of i, count - 1): the top
    // every other pass, the next every fourth, and so on. The ranking is made afresh for
    // every pass: it changes most at the top, which the next pass may take again.
    ruler,
    // Windows 0, 1, ..., count - 1, then again, from one partition of the ranking made at
    // each cycle's start (partition_into_windows): ranking count windows on every pass
    // would be most of the pass.
    cycle,
  };

  RankWindows(Order order, uint32_t count) : order_(order), count_(std::max<uint32_t>(count, 1)) {}

  static uint32_t window(Order order, uint32_t count, uint32_t pass_of_stage) {
    count = std::max<uint32_t>(count, 1);
    if (order == Order::ruler) return std::min<uint32_t>(std::countr_zero(pass_of_stage + 1), count - 1);
    return pass_of_stage % count;
  }

  // The next pass's candidates in `out`: window w of the ranking (none where the ranking is
  // shorter). By the ruler, ranks [w k, (w + 1) k): rank(n, ids) must leave in `ids` the n
  // best-ranked ids, best first. In a cycle, partition(count, k, ids, starts) must leave in
  // `ids` the cycle's windows, each after the one above it, window w in ids[starts[w],
  // starts[w + 1]) (starts: count + 1 offsets), as partition_into_windows does; a later
  // window's ids are those of the cycle's start, so the caller must accept ids whose rank
  // has changed since.
  template <class Rank, class Partition>
  void next(size_t k, const Rank& rank, const Partition& partition, std::vector<uint32_t>& out) {
    last_ = window(order_, count_, passes_++);
    if (order_ == Order::ruler) {
      const size_t from = size_t{last_} * k;
      rank(from + k, out);
      out.erase(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(std::min(from, out.size())));
      return;
    }
    if (last_ == 0) partition(count_, k, ranking_, starts_);
    out.assign(ranking_.begin() + static_cast<std::ptrdiff_t>(starts_[last_]),
               ranking_.begin() + static_cast<std::ptrdiff_t>(starts_[last_ + 1]));
  }

  // The window of the last pass next() selected for.
  uint32_t last_window() const { return last_; }

 private:
  Order order_;
  uint32_t count_;
  uint32_t passes_ = 0;
  uint32_t last_ = 0;
  std::vector<uint32_t> ranking_;  // a cycle's windows
  std::vector<size_t> starts_;     // where each begins in ranking_
};

// The members i < n (is_member(i)) of the `count` * k largest keys (key_of(i): distinct
// 64-bit keys), in `count` windows of about k each, largest first: window w is
// ids[starts[w], starts[w + 1]), its ids in index order; every key of a window is larger than
// every key of the next. Windows are cut between buckets of the keys' upper 16 bits (a
// float measure's sign, exponent and 7 mantissa bits: 1/128 of a power of two), a bucket
// going whole to the window its largest key falls in, so a window holds k give or take a
// bucket; the last window ends with the bucket that reaches count * k.
//
// Why not an exact ranking: the insertion optimizer's regional stage takes a third of the
// inner nodes in windows. Finding them from the root down took 3 s a cycle at 10M
// triangles, and gathering their keys in a scan held up to four times as many 8-byte keys
// (4M triangles: the optimizer's peak heap 103.5 bytes a triangle instead of 88). Here three
// scans (the histogram, the counts, the placing) keep the ids alone, 4 bytes each. The same
// windows on any thread count (fixed chunks, placed by their counts in chunk order).
template <class IsMember, class KeyOf>
void partition_into_windows(size_t n, size_t k, uint32_t count, const IsMember& is_member, const KeyOf& key_of,
                            std::vector<uint32_t>& ids, std::vector<size_t>& starts) {
  // The buckets of LargestKeys, which selects from the same keys.
  constexpr size_t kBuckets = LargestKeys::kBuckets, kChunk = 16384;
  const auto bucket = [](uint64_t key) { return LargestKeys::bucket(key); };
  tbb::combinable<std::vector<uint32_t>> local([] { return std::vector<uint32_t>(kBuckets, 0); });
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, kChunk), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<uint32_t>& h = local.local();
    for (size_t i = r.begin(); i < r.end(); ++i)
      if (is_member(i)) ++h[bucket(key_of(i))];
  });
  std::vector<size_t> histogram(kBuckets, 0);
  local.combine_each([&](const std::vector<uint32_t>& h) {
    for (size_t b = 0; b < kBuckets; ++b) histogram[b] += h[b];
  });
  // Each bucket's window, from the largest down; kNone below the last.
  constexpr uint32_t kNone = 0xffffffffu;
  std::vector<uint32_t> window_of(kBuckets, kNone);
  k = std::max<size_t>(k, 1);
  for (size_t b = kBuckets, above = 0; b-- > 0;) {
    if (histogram[b] == 0) continue;
    const size_t w = above / k;
    if (w >= count) break;
    window_of[b] = static_cast<uint32_t>(w);
    above += histogram[b];
  }
  // Per fixed chunk of the indices, its members of each window; then every chunk's place in
  // each window, in chunk order.
  const size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<size_t> place(chunks * count, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, chunks), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t c = r.begin(); c < r.end(); ++c)
      for (size_t i = c * kChunk, end = std::min(n, i + kChunk); i < end; ++i) {
        if (!is_member(i)) continue;
        const uint32_t w = window_of[bucket(key_of(i))];
        if (w != kNone) ++place[c * count + w];
      }
  });
  starts.assign(size_t{count} + 1, 0);
  size_t total = 0;
  for (uint32_t w = 0; w < count; ++w) {
    starts[w] = total;
    for (size_t c = 0; c < chunks; ++c) {
      const size_t members = place[c * count + w];
      place[c * count + w] = total;
      total += members;
    }
  }
  starts[count] = total;
  ids.resize(total);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, chunks), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t c = r.begin(); c < r.end(); ++c)
      for (size_t i = c * kChunk, end = std::min(n, i + kChunk); i < end; ++i) {
        if (!is_member(i)) continue;
        const uint32_t w = window_of[bucket(key_of(i))];
        if (w != kNone) ids[place[c * count + w]++] = static_cast<uint32_t>(i);
      }
  });
}

}  // namespace bvhopt::detail
