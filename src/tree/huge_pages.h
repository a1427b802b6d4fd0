// Large arrays asked to be backed by 2 MiB pages (private to the library).
//
// Why: a build writes hundreds of megabytes of fresh memory, and each first write to a page
// is a fault (about 9 us in the VM this project is measured on): with 2 MiB pages there is
// one fault where there were 512. Measured there, whole process: `bvhopt build` 0.79x the
// time at 1M and 4M triangles, the binned build 0.83x (docs/optimization-at-scale.md). The
// optimizer's passes, which read the same arrays at random, were not faster on them: their
// TLB misses are not what they wait for. Linux backs memory that asks (MADV_HUGEPAGE) with
// 2 MiB pages where it can, also when transparent huge pages are enabled only on request
// ("defrag: madvise"), where a plain allocation there got none at all. The advice must come
// before the first write, which is when a page is chosen. Elsewhere it is a no-op. (The wide
// layout's arena asks for them too, for its traversal's TLB misses: layout/wide_layout.cpp.)
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace bvhopt::detail {

inline constexpr size_t kHugePageBytes = size_t(2) << 20;

// Asks for huge pages behind the whole 2 MiB pages inside [p, p + bytes) (a smaller or
// unaligned rest keeps small pages). Advice only: nothing fails if the system says no.
inline void advise_huge_pages(void* p, size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(p) + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(p) + bytes) & ~(kHugePageBytes - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)p;
  (void)bytes;
#endif
}

// v.reserve(n), with the new room asked to be on huge pages before anything is written
// there: call it before the assign or resize that fills it. Memory `v` already holds is left
// as it is (its pages are chosen), and so is room under one huge page.
template <class T>
void reserve_on_huge_pages(std::vector<T>& v, size_t n) {
  if (v.capacity() >= n) return;
  v.reserve(n);
  if (n * sizeof(T) >= kHugePageBytes) advise_huge_pages(v.data(), n * sizeof(T));
}

}  // namespace bvhopt::detail
