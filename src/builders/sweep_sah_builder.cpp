#include "bvhopt/sweep_sah_builder.h"

#include <tbb/parallel_invoke.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <memory>

#include "builders/sah_common.h"

namespace bvhopt {
namespace {

// Float bits mapped to an unsigned key with the same order, so a (centroid, id) pair
// becomes one 64-bit integer and the presort compares integers. -0 is folded into +0
// first so that equal floats always get equal keys.
inline uint32_t orderable_bits(float f) {
  uint32_t u = std::bit_cast<uint32_t>(f + 0.0f);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

class SweepBuilder {
 public:
  SweepBuilder(const PrimitiveRefs& refs, const SweepSahConfig& config, Bvh& bvh)
      : refs_(refs), config_(config), bvh_(bvh), n_(refs.size()) {}

  void run() {
    // The x-sorted list lives in the tree's own ref_indices: a leaf's slots are then
    // already its references. Nodes are allocated after the presort so that the sort's
    // temporary keys and the nodes are never held together (peak memory).
    bvh_.ref_indices.resize(n_);
    lists_[0] = bvh_.ref_indices.data();
    for (int a = 1; a < 3; ++a) {
      owned_lists_[a - 1].reset(new uint32_t[n_]);
      lists_[a] = owned_lists_[a - 1].get();
    }
    presort();
    bvh_.nodes.assign(2 * n_ - 1, BvhNode{});
    bvh_.root = 0;
    is_left_.reset(new uint8_t[n_]);
    scratch_.reset(new Scratch[n_]);

    Box root_box = detail::parallel_bounds(refs_.boxes.data(), n_);
    build(detail::NodeRange{0, n_, 0}, kInvalidNode, root_box);
    tasks_.wait();
    for (auto& l : owned_lists_) l.reset();
    is_left_.reset();
    scratch_.reset();
    // With leaves of several references some preallocated nodes stay unused.
    if (2 * leaves_.load() - 1 != bvh_.nodes.size()) bvh_.renumber_depth_first();
  }

 private:
  // The suffix areas of a sweep and the right part of a stable partition are both
  // per-position scratch over the node's own range, never needed at the same time.
  union Scratch {
    float area;
    uint32_t id;
  };

  void presort() {
    // One key array reused for the three axes keeps the extra memory at 8 bytes per ref.
    std::unique_ptr<uint64_t[]> keys(new uint64_t[n_]);
    for (int a = 0; a < 3; ++a) {
      tbb::parallel_for(tbb::blocked_range<size_t>(0, n_, 16384), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i)
          keys[i] = (uint64_t(orderable_bits(refs_.centroids[i][a])) << 32) | uint64_t(i);
      });
      // Keys are distinct (the id is part of each), so any sort gives the one order.
      tbb::parallel_sort(keys.get(), keys.get() + n_);
      uint32_t* out = lists_[a];
      tbb::parallel_for(tbb::blocked_range<size_t>(0, n_, 16384), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) out[i] = static_cast<uint32_t>(keys[i]);
      });
    }
  }

  struct Split {
    int axis = -1;
    size_t left_count = 0;  // references left of the split, in the axis's sorted order
    float cost = 0.0f;      // A_L * n_L + A_R * n_R
  };

  // Sweeps the node's three sorted lists; every position between two references is a
  // candidate. Ties go to the more balanced split, then to the lower axis and position,
  // so a node of coincident references is halved instead of peeled one by one.
  // One axis of the sweep: `suffix` receives the areas right of each position. The best
  // position by (cost, balance), the first one on exact ties.
  Split sweep_axis(int a, size_t begin, size_t count, Scratch* suffix, size_t& best_balance) const {
    const Box* boxes = refs_.boxes.data();
    const uint32_t* ids = lists_[a] + begin;
    Split best;
    best.cost = std::numeric_limits<float>::infinity();
    best_balance = ~size_t(0);
    Box right;
    for (size_t k = count - 1; k > 0; --k) {
      right.extend(boxes[ids[k]]);
      suffix[k].area = right.area_unchecked();
    }
    Box left;
    for (size_t k = 1; k < count; ++k) {
      left.extend(boxes[ids[k - 1]]);
      float c = left.area_unchecked() * float(k) + suffix[k].area * float(count - k);
      if (c <= best.cost) {
        size_t balance = k * 2 > count ? k * 2 - count : count - k * 2;
        if (c < best.cost || balance < best_balance) {
          best = Split{a, k, c};
          best_balance = balance;
        }
      }
    }
    return best;
  }

  // Sweeps the node's three sorted lists; every position between two references is a
  // candidate. Ties go to the more balanced split, then to the lower axis and position,
  // so a node of coincident references is halved instead of peeled one by one. Large
  // nodes sweep the three axes at once (each axis needs its own area scratch then); the
  // per-axis winners are combined by the same rule, so the split is the same either way.
  Split find_split(size_t begin, size_t count, Scratch* extra[2]) const {
    Split best[3];
    size_t balance[3];
    Scratch* suffix[3] = {scratch_.get() + begin, extra ? extra[0] : nullptr, extra ? extra[1] : nullptr};
    if (extra) {
      tbb::parallel_invoke([&] { best[0] = sweep_axis(0, begin, count, suffix[0], balance[0]); },
                           [&] { best[1] = sweep_axis(1, begin, count, suffix[1], balance[1]); },
                           [&] { best[2] = sweep_axis(2, begin, count, suffix[2], balance[2]); });
    } else {
      for (int a = 0; a < 3; ++a) best[a] = sweep_axis(a, begin, count, suffix[0], balance[a]);
    }
    int winner = 0;
    for (int a = 1; a < 3; ++a)
      if (best[a].cost < best[winner].cost || (best[a].cost == best[winner].cost && balance[a] < balance[winner]))
        winner = a;
    return best[winner];
  }

  // True when every centroid in the node is the same point: the first and last entries
  // of each sorted list then hold equal coordinates.
  bool centroids_coincide(size_t begin, size_t count) const {
    for (int a = 0; a < 3; ++a) {
      const uint32_t* ids = lists_[a] + begin;
      if (refs_.centroids[ids[0]][a] != refs_.centroids[ids[count - 1]][a]) return false;
    }
    return true;
  }

  void make_leaf(BvhNode& node, size_t begin, size_t count) {
    // The slots already hold the node's references, in x order.
    node.make_leaf(static_cast<uint32_t>(begin), static_cast<uint32_t>(count));
    leaves_.fetch_add(1, std::memory_order_relaxed);
  }

  // Moves the left references to the front of the other two lists, keeping their sorted
  // order (a stable partition by the per-reference side flag). Returns the child boxes.
  // Moves the left references to the front of the other two lists, keeping their sorted
  // order (a stable partition by the per-reference side flag). Returns the child boxes.
  // With `extra` (large nodes) the two sides are marked, and the two lists partitioned,
  // at the same time; the second list then spills into extra[0].
  void partition(size_t begin, size_t count, const Split& split, Box& left_box, Box& right_box,
                 Scratch* extra[2]) {
    const Box* boxes = refs_.boxes.data();
    uint8_t* is_left = is_left_.get();
    const uint32_t* ids = lists_[split.axis] + begin;
    auto mark = [&](size_t from, size_t to, uint8_t side, Box& box) {
      for (size_t k = from; k < to; ++k) {
        is_left[ids[k]] = side;
        box.extend(boxes[ids[k]]);
      }
    };
    auto stable_partition = [&](int a, Scratch* spill) {
      uint32_t* list = lists_[a] + begin;
      size_t l = 0, r = 0;
      for (size_t k = 0; k < count; ++k) {
        uint32_t id = list[k];
        if (is_left[id])
          list[l++] = id;
        else
          spill[r++].id = id;
      }
      for (size_t k = 0; k < r; ++k) list[l + k] = spill[k].id;
    };
    const int a1 = split.axis == 0 ? 1 : 0, a2 = split.axis == 2 ? 1 : 2;
    if (extra) {
      tbb::parallel_invoke([&] { mark(0, split.left_count, 1, left_box); },
                           [&] { mark(split.left_count, count, 0, right_box); });
      tbb::parallel_invoke([&] { stable_partition(a1, scratch_.get() + begin); },
                           [&] { stable_partition(a2, extra[0]); });
    } else {
      mark(0, split.left_count, 1, left_box);
      mark(split.left_count, count, 0, right_box);
      stable_partition(a1, scratch_.get() + begin);
      stable_partition(a2, scratch_.get() + begin);
    }
  }

  void build(detail::NodeRange r, uint32_t parent, Box box) {
    const double c_t = config_.cost.traversal, c_i = config_.cost.intersection;
    const size_t max_leaf = std::max<uint32_t>(1, config_.leaf.max_leaf_size);
    for (;;) {
      const size_t count = r.end - r.begin;
      BvhNode& node = bvh_.nodes[r.base];
      node.parent = parent;
      node.set_box(box);
      if (count == 1) return make_leaf(node, r.begin, count);

      // Large nodes work on their three axes at once and need two more scratch arrays
      // while they do; freed before the children are built.
      std::unique_ptr<Scratch[]> large;
      Scratch* extra_storage[2] = {nullptr, nullptr};
      Scratch** extra = nullptr;
      if (count >= config_.parallel_split_threshold) {
        large.reset(new Scratch[2 * count]);
        extra_storage[0] = large.get();
        extra_storage[1] = large.get() + count;
        extra = extra_storage;
      }

      Split split;
      if (centroids_coincide(r.begin, count)) {
        // No position separates anything: halve the list (ordered by id here).
        split.axis = 0;
        split.left_count = count / 2;
        const uint32_t* ids = lists_[0] + r.begin;
        Box l = detail::bounds_of_ids(refs_, ids, split.left_count);
        Box rr = detail::bounds_of_ids(refs_, ids + split.left_count, count - split.left_count);
        split.cost = l.area() * float(split.left_count) + rr.area() * float(count - split.left_count);
      } else {
        split = find_split(r.begin, count, extra);
      }
      // A small node becomes a leaf when intersecting all of it costs no more than the split.
      if (count <= max_leaf && c_i * node.area * double(count) <= c_t * node.area + c_i * double(split.cost))
        return make_leaf(node, r.begin, count);
      Box left_box, right_box;
      partition(r.begin, count, split, left_box, right_box, extra);
      large.reset();

      const size_t left_count = split.left_count;
      const size_t mid = r.begin + left_count;
      const uint32_t left = r.base + 1;
      const uint32_t right = r.base + static_cast<uint32_t>(2 * left_count);
      node.make_inner(left, right);
      detail::NodeRange lr{r.begin, mid, left}, rr{mid, r.end, right};
      const uint32_t me = r.base;
      // The smaller side goes to another task; this one keeps the larger.
      const bool left_smaller = left_count < count - left_count;
      if (count >= config_.parallel_threshold) {
        if (left_smaller)
          tasks_.run([this, lr, me, left_box] { build(lr, me, left_box); });
        else
          tasks_.run([this, rr, me, right_box] { build(rr, me, right_box); });
      } else {
        if (left_smaller)
          build(lr, me, left_box);
        else
          build(rr, me, right_box);
      }
      r = left_smaller ? rr : lr;
      box = left_smaller ? right_box : left_box;
      parent = me;
    }
  }

  const PrimitiveRefs& refs_;
  const SweepSahConfig& config_;
  Bvh& bvh_;
  const size_t n_;
  uint32_t* lists_[3];                     // per axis: ids by (centroid, id), per node range
  std::unique_ptr<uint32_t[]> owned_lists_[2];  // storage of lists 1 and 2
  std::unique_ptr<uint8_t[]> is_left_;     // per reference id, written by its node's split
  std::unique_ptr<Scratch[]> scratch_;     // per position
  std::atomic<size_t> leaves_{0};
  tbb::task_group tasks_;
};

}  // namespace

Bvh build_sweep_sah(const PrimitiveRefs& refs, const SweepSahConfig& config) {
  Bvh bvh;
  if (refs.empty()) return bvh;
  detail::check_reference_count(refs.size(), "sweep SAH builder");
  SweepBuilder(refs, config, bvh).run();
  return bvh;
}

}  // namespace bvhopt
