// The k largest 64-bit keys among the members of a large array, found again on every pass of
// an optimizer while the keys drift: the insertion optimizer's selection of the inner nodes
// with the largest measure.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <vector>

namespace bvhopt::detail {

class LargestKeys {
 public:
  // How a call found the keys (for tests: each way must give the same keys).
  enum class Path {
    all_keys,    // an array smaller than the histogram: every key kept
    one_scan,    // the histogram's scan gathered every key from the threshold up
    two_scans,   // the threshold fell below the guess, or the gathering overflowed
  };

  // The k largest keys of the members i < count (is_member(i)), largest first, in `out`
  // (fewer when there are fewer members). key_of(i) is called only for members; keys must
  // be distinct for the order to be total (callers put the index in the low bits).
  // The same keys on any thread count: the threshold comes from integer counts and the kept
  // keys are sorted, so the order they were gathered in does not matter.
  template <class IsMember, class KeyOf>
  Path largest(size_t count, size_t k, const IsMember& is_member, const KeyOf& key_of, std::vector<uint64_t>& out) {
    const Path path = collect(count, k, is_member, key_of, out);
    k = std::min(k, out.size());
    if (k == 0) {
      out.clear();
      return path;
    }
    std::nth_element(out.begin(), out.begin() + (k - 1), out.end(), std::greater<uint64_t>());
    std::sort(out.begin(), out.begin() + k, std::greater<uint64_t>());
    out.resize(k);
    return path;
  }

  static constexpr size_t kBuckets = size_t{1} << 16;
  static size_t bucket(uint64_t key) { return static_cast<size_t>(key >> 48); }

 private:
  // Leaves in `out` the keys of (at least) the k largest: a histogram of the keys' top 16
  // bits finds the bucket that holds the k-th, and only keys from that bucket up are kept,
  // so the scratch is about k keys, not one per member (8 bytes a node on a huge tree).
  // An array with fewer entries than buckets keeps every key instead: the histogram's fixed
  // 2^16 steps would be most of a pass there, and its keys fit in less scratch than the
  // histogram.
  // The threshold moves little from pass to pass: the histogram's own scan also gathers the
  // keys from a guess below the last pass's threshold, so a second scan of the array is
  // needed only when the threshold falls below the guess.
  template <class IsMember, class KeyOf>
  Path collect(size_t count, size_t k, const IsMember& is_member, const KeyOf& key_of, std::vector<uint64_t>& out) {
    out.clear();
    if (count <= kBuckets) {
      for (size_t i = 0; i < count; ++i)
        if (is_member(i)) out.push_back(key_of(i));
      return Path::all_keys;
    }
    tbb::combinable<std::vector<uint32_t>> local([] { return std::vector<uint32_t>(kBuckets, 0); });
    tbb::combinable<std::vector<uint64_t>> gathered;
    const size_t guess = guess_;
    // A threshold that jumps up would gather far more than 3k keys: past 4k the gathering
    // stops and the second scan runs, so the scratch stays about k keys.
    std::atomic<bool> overflow = false;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 16384), [&](const tbb::blocked_range<size_t>& r) {
      std::vector<uint32_t>& h = local.local();
      std::vector<uint64_t>& mine = gathered.local();
      for (size_t i = r.begin(); i < r.end(); ++i) {
        if (!is_member(i)) continue;
        const uint64_t key = key_of(i);
        ++h[bucket(key)];
        if (bucket(key) < guess || overflow.load(std::memory_order_relaxed)) continue;
        if (mine.size() >= 4 * k) overflow = true;
        mine.push_back(key);
      }
    });
    histogram_.assign(kBuckets, 0);
    local.combine_each([&](const std::vector<uint32_t>& h) {
      for (size_t b = 0; b < kBuckets; ++b) histogram_[b] += h[b];
    });
    size_t first = kBuckets, above = 0;
    while (first > 0 && above < k) above += histogram_[--first];
    // The next guess: the lowest bucket with at most 3k keys from it up in this pass.
    size_t next = first, upto = above;
    while (next > 0 && upto + histogram_[next - 1] <= 3 * k) upto += histogram_[--next];
    guess_ = next;
    out.reserve(above);
    if (first >= guess && !overflow) {
      gathered.combine_each([&](const std::vector<uint64_t>& part) {
        for (uint64_t key : part)
          if (bucket(key) >= first) out.push_back(key);
      });
      return Path::one_scan;
    }
    tbb::combinable<std::vector<uint64_t>> kept;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 16384), [&](const tbb::blocked_range<size_t>& r) {
      std::vector<uint64_t>& mine = kept.local();
      for (size_t i = r.begin(); i < r.end(); ++i) {
        if (!is_member(i)) continue;
        const uint64_t key = key_of(i);
        if (bucket(key) >= first) mine.push_back(key);
      }
    });
    kept.combine_each([&](const std::vector<uint64_t>& part) { out.insert(out.end(), part.begin(), part.end()); });
    return Path::two_scans;
  }

  size_t guess_ = kBuckets;  // lowest bucket whose keys the histogram's scan gathers
  std::vector<uint64_t> histogram_;
};

}  // namespace bvhopt::detail
