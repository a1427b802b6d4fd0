#include "bvhopt/sweep_sah_builder.h"

#include <tbb/parallel_invoke.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <bit>
#include <memory>

#include "builders/sah_common.h"
#include "builders/sorted_range_sweep.h"
#include "builders/top_down.h"

namespace bvhopt {
namespace {

// Float bits mapped to an unsigned key with the same order, so a (centroid, id) pair
// becomes one 64-bit integer and the presort compares integers. -0 is folded into +0
// first so that equal floats always get equal keys.
inline uint32_t orderable_bits(float f) {
  uint32_t u = std::bit_cast<uint32_t>(f + 0.0f);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

// The sweep's split search for TopDownTree: each node's references are three slices of
// the per-axis sorted lists, which every split partitions stably.
class SweepHeuristic {
 public:
  struct Node {
    Box box;
  };

  SweepHeuristic(const PrimitiveRefs& refs, const SweepSahConfig& config, Bvh& bvh)
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

    detail::TopDownTree tree(bvh_);
    tree.build(*this, detail::NodeRange{0, n_, 0}, kInvalidNode, Node{detail::parallel_bounds(refs_.boxes.data(), n_)},
               config_.parallel_threshold);
    tree.finish();
  }

  size_t split(const detail::NodeRange& r, const BvhNode& node, const Node&, Node& left, Node& right) {
    const size_t count = r.count();
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
      Box l = detail::bounds_of(refs_, ids, split.left_count);
      Box rr = detail::bounds_of(refs_, ids + split.left_count, count - split.left_count);
      split.cost = l.area() * double(split.left_count) + rr.area() * double(count - split.left_count);
    } else {
      split = find_split(r.begin, count, extra);
    }
    if (detail::sah_prefers_leaf(config_, node.area(), count, split.cost)) return 0;
    partition(r.begin, count, split, left.box, right.box, extra);
    return split.left_count;
  }

  // The slots already hold the node's references, in x order.
  void leaf(const detail::NodeRange&) {}

 private:
  // The suffix areas of a sweep and the right part of a stable partition are both
  // per-position scratch over the node's own range, never needed at the same time.
  union Scratch {
    double area;
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
    double cost = 0.0;      // A_L * n_L + A_R * n_R
  };

  // One axis of the sweep over the node's sorted list; `suffix` receives the areas.
  detail::SweepCandidate sweep_axis(int a, size_t begin, size_t count, Scratch* suffix) const {
    const Box* boxes = refs_.boxes.data();
    const uint32_t* ids = lists_[a] + begin;
    return detail::sweep_sorted_range(
        count, [&](Box& b, size_t k) { b.extend(boxes[ids[k]]); }, [&](size_t k) -> double& { return suffix[k].area; });
  }

  // Sweeps the node's three sorted lists. Large nodes sweep the three axes at once (each
  // axis needs its own area scratch then); the per-axis winners are combined by the same
  // rule, so the split is the same either way.
  Split find_split(size_t begin, size_t count, Scratch* extra[2]) const {
    detail::SweepCandidate best[3];
    Scratch* suffix[3] = {scratch_.get() + begin, extra ? extra[0] : nullptr, extra ? extra[1] : nullptr};
    if (extra) {
      tbb::parallel_invoke([&] { best[0] = sweep_axis(0, begin, count, suffix[0]); },
                           [&] { best[1] = sweep_axis(1, begin, count, suffix[1]); },
                           [&] { best[2] = sweep_axis(2, begin, count, suffix[2]); });
    } else {
      for (int a = 0; a < 3; ++a) best[a] = sweep_axis(a, begin, count, suffix[0]);
    }
    int winner = 0;
    for (int a = 1; a < 3; ++a)
      if (detail::better_candidate(best[a], best[winner])) winner = a;
    return Split{winner, best[winner].left_count, best[winner].cost};
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
      detail::stable_partition_by_side(
          lists_[a] + begin, count, [&](uint32_t id) { return is_left[id] != 0; },
          [&](size_t k) -> uint32_t& { return spill[k].id; });
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

  const PrimitiveRefs& refs_;
  const SweepSahConfig& config_;
  Bvh& bvh_;
  const size_t n_;
  uint32_t* lists_[3];                     // per axis: ids by (centroid, id), per node range
  std::unique_ptr<uint32_t[]> owned_lists_[2];  // storage of lists 1 and 2
  std::unique_ptr<uint8_t[]> is_left_;     // per reference id, written by its node's split
  std::unique_ptr<Scratch[]> scratch_;     // per position
};

}  // namespace

Bvh build_sweep_sah(const PrimitiveRefs& refs, const SweepSahConfig& config) {
  validate(config);
  Bvh bvh;
  if (refs.empty()) return bvh;
  check_reference_count(refs.size(), "sweep SAH builder");
  SweepHeuristic(refs, config, bvh).run();
  return bvh;
}

}  // namespace bvhopt
