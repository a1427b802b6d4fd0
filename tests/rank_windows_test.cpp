// The insertion optimizer's selection in windows of a ranking (src/optimize/rank_windows.h).
#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

#include "optimize/rank_windows.h"

namespace bvhopt::detail {
namespace {

using Order = RankWindows::Order;

TEST(RankWindows, RulerTakesTheTopEveryOtherPassAndDeeperWindowsHalfAsOften) {
  // Passes 1..16 of a stage: trailing zeros of the pass number, at most count - 1.
  const std::vector<uint32_t> expected = {0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0, 3};
  for (uint32_t p = 0; p < expected.size(); ++p) EXPECT_EQ(RankWindows::window(Order::ruler, 4, p), expected[p]) << p;
  EXPECT_EQ(RankWindows::window(Order::ruler, 8, 127), 7u);  // pass 128
  EXPECT_EQ(RankWindows::window(Order::ruler, 8, 255), 7u);  // pass 256: capped
  EXPECT_EQ(RankWindows::window(Order::ruler, 1, 1), 0u);
}

TEST(RankWindows, CycleTakesEveryWindowInTurn) {
  for (uint32_t p = 0; p < 20; ++p) EXPECT_EQ(RankWindows::window(Order::cycle, 5, p), p % 5) << p;
}

// A ranking of `total` ids (id i ranked i-th, shifted by `offset` to tell rankings apart):
// by the ruler, the first n; in a cycle, windows of exactly k. Counts the calls.
struct FakeRanking {
  size_t total;
  uint32_t offset = 0;
  std::vector<size_t> asked = {};
  size_t partitions = 0;
  void rank(size_t n, std::vector<uint32_t>& ids) {
    asked.push_back(n);
    ids.resize(std::min(n, total));
    std::iota(ids.begin(), ids.end(), offset);
  }
  void partition(uint32_t count, size_t k, std::vector<uint32_t>& ids, std::vector<size_t>& starts) {
    ++partitions;
    rank(count * k, ids);
    starts.resize(count + 1);
    for (uint32_t w = 0; w <= count; ++w) starts[w] = std::min(ids.size(), w * k);
  }
};

void next(RankWindows& w, size_t k, FakeRanking& f, std::vector<uint32_t>& out) {
  w.next(
      k, [&](size_t n, std::vector<uint32_t>& ids) { f.rank(n, ids); },
      [&](uint32_t count, size_t kk, std::vector<uint32_t>& ids, std::vector<size_t>& starts) {
        f.partition(count, kk, ids, starts);
      },
      out);
}

std::vector<uint32_t> ranks(uint32_t from, uint32_t to, uint32_t offset = 0) {
  std::vector<uint32_t> v(to - from);
  std::iota(v.begin(), v.end(), from + offset);
  return v;
}

TEST(RankWindows, RulerSelectsItsWindowFromAFreshRankingEveryPass) {
  RankWindows w(Order::ruler, 4);
  FakeRanking f{100};
  std::vector<uint32_t> out;
  const uint32_t k = 10;
  const uint32_t windows[] = {0, 1, 0, 2, 0, 1, 0, 3};
  for (size_t p = 0; p < std::size(windows); ++p) {
    next(w, k, f, out);
    EXPECT_EQ(w.last_window(), windows[p]);
    EXPECT_EQ(out, ranks(windows[p] * k, (windows[p] + 1) * k)) << "pass " << p;
    ASSERT_EQ(f.asked.size(), p + 1);  // ranked afresh
    EXPECT_EQ(f.asked.back(), (windows[p] + 1) * k);
  }
  EXPECT_EQ(f.partitions, 0u);
}

TEST(RankWindows, CyclePartitionsOnceACycleAndTakesItsWindowsInTurn) {
  RankWindows w(Order::cycle, 3);
  FakeRanking f{1000};
  std::vector<uint32_t> out, seen;
  const uint32_t k = 7;
  for (uint32_t p = 0; p < 3; ++p) {
    next(w, k, f, out);
    EXPECT_EQ(w.last_window(), p);
    EXPECT_EQ(out, ranks(p * k, (p + 1) * k));
    seen.insert(seen.end(), out.begin(), out.end());
  }
  EXPECT_EQ(seen, ranks(0, 3 * k));  // every one of the top 3k once, in rank order
  EXPECT_EQ(f.partitions, 1u);       // one partition for the cycle
  // The next cycle partitions again, and its windows come from the new one.
  f.offset = 500;
  next(w, k, f, out);
  EXPECT_EQ(f.partitions, 2u);
  EXPECT_EQ(out, ranks(0, k, 500));
  next(w, k, f, out);
  EXPECT_EQ(out, ranks(k, 2 * k, 500));
}

TEST(RankWindows, WindowsPastTheEndOfAShortRankingAreShortOrEmpty) {
  RankWindows cycle(Order::cycle, 4);
  FakeRanking f{15};
  std::vector<uint32_t> out;
  next(cycle, 10, f, out);
  EXPECT_EQ(out, ranks(0, 10));
  next(cycle, 10, f, out);
  EXPECT_EQ(out, ranks(10, 15));
  next(cycle, 10, f, out);
  EXPECT_TRUE(out.empty());

  RankWindows ruler(Order::ruler, 4);
  next(ruler, 10, f, out);  // window 0
  next(ruler, 10, f, out);  // window 1
  EXPECT_EQ(out, ranks(10, 15));
  next(ruler, 10, f, out);  // window 0
  next(ruler, 10, f, out);  // window 2
  EXPECT_TRUE(out.empty());
}

// Keys as the insertion optimizer makes them: a float measure's bits above the complemented
// index (distinct keys, ties to the lower index).
uint64_t key_of_measure(float m, uint32_t i) {
  return (uint64_t{std::bit_cast<uint32_t>(m)} << 32) | (0xffffffffu - i);
}

// The partition's windows: ordered (every key of a window above every key of the next),
// each about k (give or take one bucket of the upper 16 bits), every member above the last
// window's lowest bucket in one, ids in index order within a window; and the same on 1 and 2
// threads.
TEST(RankWindows, PartitionCutsTheRankingIntoOrderedWindowsOfAboutK) {
  const size_t n = 100000;
  std::mt19937 rng(7);
  std::lognormal_distribution<float> measure(0.0f, 3.0f);
  std::vector<uint64_t> keys(n);
  std::vector<bool> member(n);
  for (size_t i = 0; i < n; ++i) {
    keys[i] = key_of_measure(measure(rng), static_cast<uint32_t>(i));
    member[i] = (i % 3) != 0;  // a third are not (leaves)
  }
  const auto is_member = [&](size_t i) { return bool(member[i]); };
  const auto key_of = [&](size_t i) { return keys[i]; };
  const size_t k = 1000;
  const uint32_t count = 20;
  std::vector<uint32_t> ids;
  std::vector<size_t> starts;
  partition_into_windows(n, k, count, is_member, key_of, ids, starts);
  ASSERT_EQ(starts.size(), count + 1u);
  EXPECT_EQ(starts[0], 0u);
  EXPECT_EQ(starts[count], ids.size());
  const auto bucket_size = [&](uint64_t key) {
    size_t size = 0;
    for (size_t i = 0; i < n; ++i) size += member[i] && (keys[i] >> 48) == (key >> 48);
    return size;
  };
  uint64_t lowest_above = ~uint64_t{0};
  for (uint32_t w = 0; w < count; ++w) {
    ASSERT_LE(starts[w], starts[w + 1]);
    uint64_t lo = ~uint64_t{0}, hi = 0;
    for (size_t j = starts[w]; j < starts[w + 1]; ++j) {
      ASSERT_TRUE(member[ids[j]]);
      if (j > starts[w]) {
        EXPECT_LT(ids[j - 1], ids[j]) << "index order within a window";
      }
      lo = std::min(lo, keys[ids[j]]);
      hi = std::max(hi, keys[ids[j]]);
    }
    const size_t size = starts[w + 1] - starts[w];
    ASSERT_GT(size, 0u) << w;
    EXPECT_LT(hi, lowest_above) << "window " << w << " overlaps the one above";
    lowest_above = lo;
    // Each window ends where a bucket would take it to k or past it: k give or take the
    // bucket at either end.
    EXPECT_LE(size, k + bucket_size(lo)) << w;
    EXPECT_GE(size + bucket_size(hi), k) << w;
  }
  // Every member with a key at or above the last window's lowest bucket is in a window.
  const uint64_t last_bucket = lowest_above >> 48;
  size_t expected = 0;
  for (size_t i = 0; i < n; ++i) expected += member[i] && (keys[i] >> 48) >= last_bucket;
  EXPECT_EQ(ids.size(), expected);
  EXPECT_GE(ids.size(), count * k);

  // The same windows on one thread.
  tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  std::vector<uint32_t> ids1;
  std::vector<size_t> starts1;
  partition_into_windows(n, k, count, is_member, key_of, ids1, starts1);
  EXPECT_EQ(ids1, ids);
  EXPECT_EQ(starts1, starts);
}

TEST(RankWindows, PartitionOfFewerMembersThanTheWindowsHoldEndsEarly) {
  const std::vector<uint64_t> keys = {key_of_measure(3.0f, 0), key_of_measure(1.0f, 1), key_of_measure(2.0f, 2)};
  std::vector<uint32_t> ids;
  std::vector<size_t> starts;
  partition_into_windows(keys.size(), 2, 4, [](size_t) { return true; }, [&](size_t i) { return keys[i]; }, ids, starts);
  // 3.0 and 2.0 (two buckets) make the first window; 1.0 the second; the rest are empty.
  EXPECT_EQ(ids, (std::vector<uint32_t>{0, 2, 1}));
  EXPECT_EQ(starts, (std::vector<size_t>{0, 2, 3, 3, 3}));
}

}  // namespace
}  // namespace bvhopt::detail
