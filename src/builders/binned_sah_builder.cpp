#include "bvhopt/binned_sah_builder.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "builders/sah_common.h"
#include "builders/sorted_range_sweep.h"
#include "builders/top_down.h"
#include "tree/huge_pages.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace bvhopt {
namespace {

// The builder's working copy of a reference: its box and id in 32 bytes, partitioned in
// place so that binning streams through memory instead of chasing ids. Bins are chosen
// by lo + hi, twice the box centre (the centroid make_references gives every reference).
struct alignas(32) BinRef {
  float lo[3];
  uint32_t id;
  float hi[3];
  uint32_t pad;
};

// A centroid box kept as twice the centre, to match BinRef's lo + hi.
struct CentroidBounds {
  float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity()};
  float hi[3] = {-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                 -std::numeric_limits<float>::infinity()};
  void extend(const BinRef& r) {
    for (int a = 0; a < 3; ++a) {
      float c = r.lo[a] + r.hi[a];
      lo[a] = std::min(lo[a], c);
      hi[a] = std::max(hi[a], c);
    }
  }
  void extend(const CentroidBounds& o) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], o.lo[a]);
      hi[a] = std::max(hi[a], o.hi[a]);
    }
  }
};

inline void extend_box(Box& b, const BinRef& r) {
  b.min = min(b.min, Vec3(r.lo[0], r.lo[1], r.lo[2]));
  b.max = max(b.max, Vec3(r.hi[0], r.hi[1], r.hi[2]));
}

constexpr uint32_t kMaxBins = kMaxBinCount;

// Per axis, per bin: the union of the boxes whose centroid falls in the bin and their
// count. Four floats per corner so that one SSE min/max updates a corner.
struct Bins {
  uint32_t bin_count;
  alignas(16) float lo_[3][kMaxBins][4];
  alignas(16) float hi_[3][kMaxBins][4];
  uint32_t count[3][kMaxBins];

  explicit Bins(uint32_t bins) : bin_count(bins) {
    for (int a = 0; a < 3; ++a)
      for (uint32_t b = 0; b < bins; ++b) {
        for (int k = 0; k < 4; ++k) {
          lo_[a][b][k] = std::numeric_limits<float>::infinity();
          hi_[a][b][k] = -std::numeric_limits<float>::infinity();
        }
        count[a][b] = 0;
      }
  }
  Bins(const Bins& o) : bin_count(o.bin_count) { *this = o; }
  // Copies only the bins in use: a node's bins are far fewer than the capacity.
  Bins& operator=(const Bins& o) {
    bin_count = o.bin_count;
    for (int a = 0; a < 3; ++a) {
      std::memcpy(lo_[a], o.lo_[a], sizeof(float) * 4 * bin_count);
      std::memcpy(hi_[a], o.hi_[a], sizeof(float) * 4 * bin_count);
      std::memcpy(count[a], o.count[a], sizeof(uint32_t) * bin_count);
    }
    return *this;
  }
  void merge(const Bins& o) {
    for (int a = 0; a < 3; ++a)
      for (uint32_t b = 0; b < bin_count; ++b) {
        for (int k = 0; k < 4; ++k) {
          lo_[a][b][k] = std::min(lo_[a][b][k], o.lo_[a][b][k]);
          hi_[a][b][k] = std::max(hi_[a][b][k], o.hi_[a][b][k]);
        }
        count[a][b] += o.count[a][b];
      }
  }
  Box box(int a, uint32_t b) const {
    return Box(Vec3(lo_[a][b][0], lo_[a][b][1], lo_[a][b][2]), Vec3(hi_[a][b][0], hi_[a][b][1], hi_[a][b][2]));
  }
};

// Maps a doubled centroid coordinate to its bin on each axis.
struct BinMapping {
  float origin[3];
  float scale[3];
  uint32_t last;

  BinMapping(const CentroidBounds& cb, uint32_t bins) : last(bins - 1) {
    for (int a = 0; a < 3; ++a) {
      origin[a] = cb.lo[a];
      float extent = cb.hi[a] - cb.lo[a];
      // Slightly under bins / extent so the largest centroid lands in the last bin.
      // A denormal extent would give an infinite scale and NaN bins: treat it as flat.
      float s = extent > 0.0f ? float(bins) * 0.99999f / extent : 0.0f;
      scale[a] = std::isfinite(s) ? s : 0.0f;
    }
  }
  uint32_t bin(const BinRef& r, int a) const {
    float c = r.lo[a] + r.hi[a];
    int b = static_cast<int>((c - origin[a]) * scale[a]);
    return static_cast<uint32_t>(std::clamp(b, 0, static_cast<int>(last)));
  }
};

inline void bin_range(Bins& bins, const BinMapping& m, const BinRef* refs, size_t begin, size_t end) {
#if defined(__SSE2__)
  // The same arithmetic as BinMapping::bin, four lanes at once (the fourth lane, the id
  // bits, goes along unused); clamping before truncation equals truncating then clamping
  // for every value the mapping can produce.
  const __m128 origin = _mm_setr_ps(m.origin[0], m.origin[1], m.origin[2], 0.0f);
  const __m128 scale = _mm_setr_ps(m.scale[0], m.scale[1], m.scale[2], 0.0f);
  const __m128 last = _mm_set1_ps(float(m.last));
  alignas(16) int32_t idx[4];
  for (size_t i = begin; i < end; ++i) {
    const __m128 lo = _mm_load_ps(refs[i].lo);
    const __m128 hi = _mm_load_ps(refs[i].hi);
    __m128 f = _mm_mul_ps(_mm_sub_ps(_mm_add_ps(lo, hi), origin), scale);
    f = _mm_min_ps(_mm_max_ps(f, _mm_setzero_ps()), last);
    _mm_store_si128(reinterpret_cast<__m128i*>(idx), _mm_cvttps_epi32(f));
    for (int a = 0; a < 3; ++a) {
      float* blo = bins.lo_[a][idx[a]];
      float* bhi = bins.hi_[a][idx[a]];
      _mm_store_ps(blo, _mm_min_ps(_mm_load_ps(blo), lo));
      _mm_store_ps(bhi, _mm_max_ps(_mm_load_ps(bhi), hi));
      bins.count[a][idx[a]]++;
    }
  }
#else
  for (size_t i = begin; i < end; ++i) {
    const BinRef& r = refs[i];
    for (int a = 0; a < 3; ++a) {
      uint32_t b = m.bin(r, a);
      float* lo = bins.lo_[a][b];
      float* hi = bins.hi_[a][b];
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], r.lo[k]);
        hi[k] = std::max(hi[k], r.hi[k]);
      }
      bins.count[a][b]++;
    }
  }
#endif
}

// Consecutive references often fall into the same bins, and then each update waits for
// the previous one's store. Alternating between two sets of bins halves that chain; the
// sets merge exactly (min, max, integer counts), so the result is the same.
inline void bin_range_two_sets(Bins& bins, const BinMapping& m, const BinRef* refs, size_t begin, size_t end) {
  if (end - begin < 1024) return bin_range(bins, m, refs, begin, end);
  Bins odd(bins.bin_count);
  size_t i = begin;
  for (; i + 2 <= end; i += 2) {
    bin_range(bins, m, refs, i, i + 1);
    bin_range(odd, m, refs, i + 1, i + 2);
  }
  bin_range(bins, m, refs, i, end);
  bins.merge(odd);
}

// A subtree of at most exact_sweep_below references, built by exact sweeps: the
// references are sorted per axis by (centroid, id) once, and each split filters the three
// orders stably, as the sweep builder does. Same tie rules as the bins. Works on a local
// copy; only the nodes and the leaves' slots are written. Sequential: the scratch is
// shared by the whole subtree.
class SmallSubtreeHeuristic {
 public:
  struct Node {
    Box box;
  };

  SmallSubtreeHeuristic(const BinRef* work, size_t begin, size_t count, const BinnedSahConfig& config, Bvh& bvh)
      : begin_(begin), config_(config), bvh_(bvh) {
    std::copy(work + begin, work + begin + count, refs_);
    float key[kMaxExactSweepBelow];
    for (int a = 0; a < 3; ++a) {
      uint16_t* o = order_[a];
      for (size_t i = 0; i < count; ++i) {
        o[i] = static_cast<uint16_t>(i);
        key[i] = refs_[i].lo[a] + refs_[i].hi[a];
      }
      // Ties by id make the order unique, so the result does not depend on the sort used.
      std::sort(o, o + count, [&](uint16_t x, uint16_t y) {
        return key[x] < key[y] || (key[x] == key[y] && refs_[x].id < refs_[y].id);
      });
    }
  }

  size_t split(const detail::NodeRange& r, const BvhNode& node, const Node&, Node& left, Node& right) {
    const size_t lo = r.begin - begin_, count = r.count();
    int best_axis = 0;
    detail::SweepCandidate best[3];
    for (int a = 0; a < 3; ++a) {
      const uint16_t* o = order_[a] + lo;
      best[a] = detail::sweep_sorted_range(
          count, [&](Box& b, size_t k) { extend_box(b, refs_[o[k]]); },
          [&](size_t k) -> double& { return right_area_[k]; });
      if (a > 0 && detail::better_candidate(best[a], best[best_axis])) best_axis = a;
    }
    const size_t best_k = best[best_axis].left_count;
    if (detail::sah_prefers_leaf(config_, node.area(), count, best[best_axis].cost)) return 0;

    const uint16_t* chosen = order_[best_axis] + lo;
    for (size_t k = 0; k < count; ++k) {
      is_left_[chosen[k]] = k < best_k;
      extend_box(k < best_k ? left.box : right.box, refs_[chosen[k]]);
    }
    for (int a = 0; a < 3; ++a) {
      if (a == best_axis) continue;
      detail::stable_partition_by_side(
          order_[a] + lo, count, [&](uint16_t i) { return is_left_[i] != 0; },
          [&](size_t k) -> uint16_t& { return spill_[k]; });
    }
    return best_k;
  }

  void leaf(const detail::NodeRange& r) {
    for (size_t k = r.begin; k < r.end; ++k) bvh_.ref_indices[k] = refs_[order_[0][k - begin_]].id;
  }

 private:
  const size_t begin_;  // the subtree's first slot
  const BinnedSahConfig& config_;
  Bvh& bvh_;
  BinRef refs_[kMaxExactSweepBelow];
  uint16_t order_[3][kMaxExactSweepBelow];
  uint16_t spill_[kMaxExactSweepBelow];
  double right_area_[kMaxExactSweepBelow];
  uint8_t is_left_[kMaxExactSweepBelow];
};

// The binned split search for TopDownTree. The builder works on a copy of the references
// (BinRef) that it partitions in place; each node carries its centroid bounds, over which
// its bins are laid.
class BinnedHeuristic {
 public:
  struct Node {
    Box box;
    CentroidBounds cb;
  };

  BinnedHeuristic(const PrimitiveRefs& refs, const BinnedSahConfig& config, Bvh& bvh)
      : refs_(refs), config_(config), bvh_(bvh), n_(refs.size()) {}

  void run() {
    detail::reserve_on_huge_pages(bvh_.nodes, 2 * n_ - 1);
    bvh_.nodes.assign(2 * n_ - 1, BvhNode{});
    detail::reserve_on_huge_pages(bvh_.ref_indices, n_);
    bvh_.ref_indices.resize(n_);
    bvh_.root = 0;
    work_.reset(new BinRef[n_]);
    detail::advise_huge_pages(work_.get(), n_ * sizeof(BinRef));
    BinRef* work = work_.get();
    Node root = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, n_, 16384), Node{},
        [&](const tbb::blocked_range<size_t>& r, Node acc) {
          for (size_t i = r.begin(); i < r.end(); ++i) {
            const Box& b = refs_.boxes[i];
            BinRef& w = work[i];
            w.lo[0] = b.min.x, w.lo[1] = b.min.y, w.lo[2] = b.min.z;
            w.hi[0] = b.max.x, w.hi[1] = b.max.y, w.hi[2] = b.max.z;
            w.id = static_cast<uint32_t>(i);
            w.pad = 0;
            acc.box.extend(b);
            acc.cb.extend(w);
          }
          return acc;
        },
        [](Node a, const Node& b) {
          a.box.extend(b.box);
          a.cb.extend(b.cb);
          return a;
        });
    detail::TopDownTree tree(bvh_);
    tree.build(*this, detail::NodeRange{0, n_, 0}, kInvalidNode, root, config_.parallel_threshold);
    tree.finish();
  }

  // Small nodes: the exact sweep, one task for the whole subtree.
  bool build_subtree(detail::TopDownTree& tree, const detail::NodeRange& r, uint32_t parent, const Node& node) {
    if (r.count() > config_.exact_sweep_below) return false;
    SmallSubtreeHeuristic small(work_.get(), r.begin, r.count(), config_, bvh_);
    tree.build(small, r, parent, SmallSubtreeHeuristic::Node{node.box}, std::numeric_limits<size_t>::max());
    return true;
  }

  size_t split(const detail::NodeRange& r, const BvhNode& node, const Node& state, Node& left, Node& right) {
    const size_t count = r.count();
    BinRef* refs = work_.get() + r.begin;
    const uint32_t nbins = bins_for(count);
    BinMapping mapping(state.cb, nbins);
    Split split = find_split(bin(refs, count, mapping, nbins));

    size_t left_count = 0;
    if (split.axis < 0) {
      // All centroids in one bin (coincident centroids): halve the node in id order.
      left_count = count / 2;
      std::nth_element(refs, refs + left_count, refs + count,
                       [](const BinRef& x, const BinRef& y) { return x.id < y.id; });
      for (size_t k = 0; k < count; ++k) {
        extend_box(k < left_count ? split.left : split.right, refs[k]);
        (k < left_count ? left.cb : right.cb).extend(refs[k]);
      }
      split.cost = split.left.area() * double(left_count) + split.right.area() * double(count - left_count);
    }
    if (detail::sah_prefers_leaf(config_, node.area(), count, split.cost)) return 0;
    if (split.axis >= 0) {
      const int axis = split.axis;
      const uint32_t first_right = split.bin;
      auto is_left = [&](const BinRef& x) { return mapping.bin(x, axis) < first_right; };
      left_count = count >= config_.parallel_binning_threshold ? parallel_partition(refs, count, is_left, left.cb, right.cb)
                                                               : partition(refs, count, is_left, left.cb, right.cb);
    }
    left.box = split.left;
    right.box = split.right;
    return left_count;
  }

  void leaf(const detail::NodeRange& r) {
    for (size_t k = r.begin; k < r.end; ++k) bvh_.ref_indices[k] = work_[k].id;
    // In id order, so that the tree depends only on each node's set of references, not on
    // the order a partition left them in (sequential and parallel partitions differ).
    std::sort(bvh_.ref_indices.begin() + r.begin, bvh_.ref_indices.begin() + r.end);
  }

 private:
  struct Split {
    int axis = -1;
    uint32_t bin = 0;  // first bin of the right side
    double cost = std::numeric_limits<double>::infinity();
    Box left, right;
  };

  // More bins where the pass over the references dwarfs the sweep over the bins, and
  // fewer where most bins would stay empty anyway.
  uint32_t bins_for(size_t count) const {
    const uint32_t base = config_.bin_count;
    if (config_.refs_per_bin == 0) return base;
    size_t nbins = std::clamp<size_t>(count / config_.refs_per_bin, base, std::max(base, config_.max_bin_count));
    return static_cast<uint32_t>(std::min<size_t>(nbins, 4 + count / 5));
  }

  Bins bin(const BinRef* refs, size_t count, const BinMapping& mapping, uint32_t nbins) const {
    Bins bins(nbins);
    if (count >= config_.parallel_binning_threshold) {
      // Min, max and integer counts merge exactly: the bins do not depend on the split.
      bins = tbb::parallel_reduce(
          tbb::blocked_range<size_t>(0, count, 8192), Bins(nbins),
          [&](const tbb::blocked_range<size_t>& br, Bins acc) {
            bin_range_two_sets(acc, mapping, refs, br.begin(), br.end());
            return acc;
          },
          [](Bins a, const Bins& b) {
            a.merge(b);
            return a;
          });
    } else {
      bin_range_two_sets(bins, mapping, refs, 0, count);
    }
    return bins;
  }

  Split find_split(const Bins& bins) const {
    const uint32_t nb = bins.bin_count;
    double right_area[kMaxBins];
    uint32_t right_count[kMaxBins];
    Split best;
    uint32_t best_balance = std::numeric_limits<uint32_t>::max();
    for (int a = 0; a < 3; ++a) {
      Box right;
      uint32_t rc = 0;
      for (uint32_t b = nb - 1; b > 0; --b) {
        right.extend(bins.box(a, b));
        rc += bins.count[a][b];
        right_area[b] = right.area();
        right_count[b] = rc;
      }
      Box left;
      uint32_t lc = 0;
      for (uint32_t b = 1; b < nb; ++b) {
        left.extend(bins.box(a, b - 1));
        lc += bins.count[a][b - 1];
        if (lc == 0 || right_count[b] == 0) continue;
        double c = left.area() * double(lc) + right_area[b] * double(right_count[b]);
        if (c <= best.cost) {
          uint32_t balance = lc > right_count[b] ? lc - right_count[b] : right_count[b] - lc;
          if (c < best.cost || balance < best_balance) {
            best.axis = a;
            best.bin = b;
            best.cost = c;
            best_balance = balance;
          }
        }
      }
    }
    if (best.axis >= 0)
      for (uint32_t b = 0; b < nb; ++b) (b < best.bin ? best.left : best.right).extend(bins.box(best.axis, b));
    return best;
  }

  // The in-place partition of a large node, in parallel: fixed blocks are partitioned
  // on their own, then the right-side references that lie left of the final boundary are
  // swapped pairwise with the left-side ones that lie right of it. Block size and pairing
  // depend only on the input, so the result does not depend on the thread count.
  template <class IsLeft>
  size_t parallel_partition(BinRef* a, size_t count, const IsLeft& is_left, CentroidBounds& lcb,
                            CentroidBounds& rcb) {
    constexpr size_t kBlock = 16384;
    const size_t blocks = (count + kBlock - 1) / kBlock;
    std::vector<size_t> left_in_block(blocks);
    std::vector<CentroidBounds> lcbs(blocks), rcbs(blocks);
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      const size_t begin = b * kBlock, size = std::min(kBlock, count - begin);
      left_in_block[b] = partition(a + begin, size, is_left, lcbs[b], rcbs[b]);
    });
    size_t left_count = 0;
    for (size_t b = 0; b < blocks; ++b) {
      left_count += left_in_block[b];
      lcb.extend(lcbs[b]);
      rcb.extend(rcbs[b]);
    }
    // Misplaced runs, in block order: right-side references before the boundary and
    // left-side ones after it. There are as many of one kind as of the other.
    struct Run {
      size_t begin, size;
    };
    std::vector<Run> wrong_right, wrong_left;
    for (size_t b = 0; b < blocks; ++b) {
      const size_t begin = b * kBlock, end = std::min(begin + kBlock, count), mid = begin + left_in_block[b];
      if (mid < left_count && mid < end) wrong_right.push_back({mid, std::min(end, left_count) - mid});
      if (begin < mid && mid > left_count) {
        const size_t from = std::max(begin, left_count);
        wrong_left.push_back({from, mid - from});
      }
    }
    std::vector<size_t> right_offsets{0}, left_offsets{0};
    for (const Run& r : wrong_right) right_offsets.push_back(right_offsets.back() + r.size);
    for (const Run& r : wrong_left) left_offsets.push_back(left_offsets.back() + r.size);
    const size_t misplaced = right_offsets.back();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, misplaced, kBlock), [&](const tbb::blocked_range<size_t>& range) {
      // The k-th misplaced right reference trades places with the k-th misplaced left one.
      size_t ri = std::upper_bound(right_offsets.begin(), right_offsets.end(), range.begin()) - right_offsets.begin() - 1;
      size_t li = std::upper_bound(left_offsets.begin(), left_offsets.end(), range.begin()) - left_offsets.begin() - 1;
      for (size_t k = range.begin(); k < range.end(); ++k) {
        while (k >= right_offsets[ri + 1]) ++ri;
        while (k >= left_offsets[li + 1]) ++li;
        std::swap(a[wrong_right[ri].begin + (k - right_offsets[ri])], a[wrong_left[li].begin + (k - left_offsets[li])]);
      }
    });
    return left_count;
  }

  // In-place two-sided partition; also collects each side's centroid bounds for the
  // children's bin mappings. Sequential, so the order it leaves is a function of the input.
  template <class IsLeft>
  size_t partition(BinRef* a, size_t count, const IsLeft& is_left, CentroidBounds& lcb, CentroidBounds& rcb) const {
    size_t i = 0, j = count;
    for (;;) {
      while (i < j && is_left(a[i])) lcb.extend(a[i++]);
      while (i < j && !is_left(a[j - 1])) rcb.extend(a[--j]);
      if (i >= j) break;
      std::swap(a[i], a[j - 1]);
      lcb.extend(a[i++]);
      rcb.extend(a[--j]);
    }
    return i;
  }

  const PrimitiveRefs& refs_;
  const BinnedSahConfig& config_;
  Bvh& bvh_;
  const size_t n_;
  std::unique_ptr<BinRef[]> work_;
};

}  // namespace

Bvh build_binned_sah(const PrimitiveRefs& refs, const BinnedSahConfig& config) {
  validate(config);
  Bvh bvh;
  if (refs.empty()) return bvh;
  check_reference_count(refs.size(), "binned SAH builder");
  BinnedHeuristic(refs, config, bvh).run();
  return bvh;
}

}  // namespace bvhopt
