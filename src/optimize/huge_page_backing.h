// Huge pages under a tree's node array while an optimizer runs (private to the library).
//
// The optimizers' searches visit nodes all over the array, and with 4 KiB pages most of
// those visits also miss the TLB: insertion at 1M triangles took 9-11 % less time with the
// array on 2 MiB pages. Asking for them when the array is allocated made the builds here
// 15-30 % slower in about half the runs (the first touch of fresh huge pages in this VM), a
// cost any build could pay, optimized or not. So the optimizer has the pages it already
// has collapsed into huge ones (MADV_COLLAPSE, Linux 6.1 and later) on a thread of its own,
// a few megabytes at a time, while the passes run, and a short run is not held up (the
// thread stops after the chunk it is on). The thread is not one of the optimizer's
// (--threads): it spends its time in the kernel, about 0.2 s at 1M triangles here, at the
// lowest priority, so that it takes the time the optimizer's threads leave idle (sequential
// passes, the serial parts of the parallel ones) rather than theirs: at normal priority the
// first pass at 1M, on 2 threads, took up to 0.31 s instead of 0.12 s. Even so it stalls
// the passes while it runs, so a run too short to win that back does without (pays_off).
// With the regional form's passes on every thread it still paid (measured at normal
// priority: 1M 8.6 s against 9.7 s without it, 4M 43.0 against 44.5 s). Where the kernel
// cannot do it, or no thread can be started, nothing happens. The tree, and so every
// result, is the same either way.
#pragma once

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <system_error>
#include <thread>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>
#endif

#include "bvhopt/bvh.h"

namespace bvhopt::detail {

class HugePageBacking {
 public:
  // The array must not move (no reallocation) until this object is destroyed.
  explicit HugePageBacking(const std::vector<BvhNode>& nodes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    const uintptr_t begin = reinterpret_cast<uintptr_t>(nodes.data());
    // Only the whole huge pages inside the array: the advice covers no one else's memory.
    const uintptr_t first = (begin + kHugePage - 1) & ~(kHugePage - 1);
    const uintptr_t last = (begin + nodes.size() * sizeof(BvhNode)) & ~(kHugePage - 1);
    if (last <= first) return;
    // Pages faulted in from now on (none, usually) come huge too.
    madvise(reinterpret_cast<void*>(first), last - first, MADV_HUGEPAGE);
    try {
      worker_ = std::thread([this, first, last] { collapse(first, last); });
    } catch (const std::system_error&) {
      // No thread to spare (a process limit): the optimizer runs on 4 KiB pages.
    }
#else
    (void)nodes;
#endif
  }
  ~HugePageBacking() {
    stop_.store(true, std::memory_order_relaxed);
    if (worker_.joinable()) worker_.join();
  }
  // Whether the collapse pays in a run of `time_limit` seconds (0: none) that has run for
  // `elapsed`. While it runs it stalls the optimizer's threads (a page being collapsed
  // cannot be read, and every attempt flushes the TLBs): about 1 s at 4M triangles, whose
  // nodes take 288 MB (the first pass 1.1 s instead of 0.35, the next 15 a quarter slower).
  // Afterwards the passes take about 5 % less time, so it pays only where the run may last
  // about 80 ms per MB of nodes more (4M: 23 s). Measured at 4M, 2 threads: to convergence
  // (38 s) 38.0-39.1 s with it, 39.7-39.8 without; within 5x the build time (14 s) 192
  // passes with it, 196-199 without (three pairs of runs), 358.10-358.33 against
  // 358.03-358.10 (six pairs).
  static bool pays_off(size_t bytes, double time_limit, double elapsed) {
    constexpr double kSecondsPerMB = 0.08;
    return time_limit == 0.0 || time_limit - elapsed >= kSecondsPerMB * (static_cast<double>(bytes) / 1e6);
  }
  HugePageBacking(const HugePageBacking&) = delete;
  HugePageBacking& operator=(const HugePageBacking&) = delete;

 private:
  static constexpr uintptr_t kHugePage = uintptr_t(2) << 20;
  // Four huge pages a call: about 20 ms here, the longest a finished run waits for it.
  static constexpr uintptr_t kChunk = 4 * kHugePage;
  static constexpr int kCollapse = 25;  // MADV_COLLAPSE, where the headers predate it

  void collapse(uintptr_t first, uintptr_t last) {
#if defined(__linux__)
    // Lowering one's own priority needs no privilege; if it fails the thread runs as before.
    (void)setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);
    for (uintptr_t at = first; at < last && !stop_.load(std::memory_order_relaxed); at += kChunk) {
      const uintptr_t end = last - at < kChunk ? last : at + kChunk;
      // EINVAL: a kernel without it, or huge pages disabled; then there is nothing to do.
      if (madvise(reinterpret_cast<void*>(at), end - at, kCollapse) != 0 && errno == EINVAL) return;
    }
#else
    (void)first, (void)last;
#endif
  }

  std::atomic<bool> stop_{false};
  std::thread worker_;
};

}  // namespace bvhopt::detail
