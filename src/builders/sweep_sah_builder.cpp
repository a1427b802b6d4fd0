#include "bvhopt/sweep_sah_builder.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <memory>
#include <new>
#include <type_traits>
#include <vector>

#include "builders/sah_common.h"
#include "builders/sorted_range_sweep.h"
#include "builders/top_down.h"
#include "tree/huge_pages.h"

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
// the per-axis sorted lists, which every split partitions stably. kInPlace: the references
// are the mesh's triangles, one each, leaves of one, their boxes kept inside the node array
// and their centroids taken from those boxes as make_references takes them; else a
// PrimitiveRefs.
template <bool kInPlace>
class SweepHeuristic {
 public:
  struct Node {
    Box box;
  };

  SweepHeuristic(const PrimitiveRefs& refs, const SweepSahConfig& config, Bvh& bvh)
    requires(!kInPlace)
      : refs_(&refs), config_(config), bvh_(bvh), n_(refs.size()), boxes_(refs.boxes.data()) {}

  // Keeps each triangle's box in the node array's last 24 n bytes, where no inner node is
  // written while the tree grows (see TopDownTree::place_leaves_in_place). Packed as an
  // array of boxes, not one per leaf node, so that the sweeps read them as densely as a
  // PrimitiveRefs' (in each leaf's node, 36 bytes apart, they made the build at 4M
  // triangles 13 % slower).
  SweepHeuristic(const Mesh& mesh, const SweepSahConfig& config, Bvh& bvh)
    requires(kInPlace)
      : mesh_(&mesh), config_(config), bvh_(bvh), n_(mesh.triangle_count()) {
    detail::reserve_on_huge_pages(bvh_.nodes, 2 * n_ - 1);
    bvh_.nodes.assign(2 * n_ - 1, BvhNode{});
    std::byte* end = reinterpret_cast<std::byte*>(bvh_.nodes.data() + bvh_.nodes.size());
    Box* boxes = reinterpret_cast<Box*>(end - n_ * sizeof(Box));
    static_assert(alignof(Box) <= alignof(BvhNode) && std::is_trivially_copyable_v<Box>);
    root_box_ = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, n_, 16384), Box(),
        [&](const tbb::blocked_range<size_t>& r, Box b) {
          for (size_t t = r.begin(); t < r.end(); ++t) {
            // The boxes begin their lives in the nodes' storage; no node there is read
            // before finish() writes it anew.
            new (&boxes[t]) Box(mesh.triangle(t).bounds());
            b.extend(boxes[t]);
          }
          return b;
        },
        [](Box a, const Box& b) { return merge(a, b); });
    boxes_ = boxes;
  }

  void run() {
    // The x-sorted list lives in the tree's own ref_indices: a leaf's slots are then
    // already its references. Without leaves in place, nodes are allocated after the
    // presort so that the sort's temporary keys and the nodes are never held together
    // (peak memory); with them, the nodes hold the boxes and come first.
    detail::reserve_on_huge_pages(bvh_.ref_indices, n_);
    bvh_.ref_indices.resize(n_);
    lists_[0] = bvh_.ref_indices.data();
    for (int a = 1; a < 3; ++a) {
      owned_lists_[a - 1].reset(new uint32_t[n_]);
      detail::advise_huge_pages(owned_lists_[a - 1].get(), n_ * sizeof(uint32_t));
      lists_[a] = owned_lists_[a - 1].get();
    }
    presort();
    if constexpr (!kInPlace) {
      detail::reserve_on_huge_pages(bvh_.nodes, 2 * n_ - 1);
      bvh_.nodes.assign(2 * n_ - 1, BvhNode{});
      root_box_ = detail::parallel_bounds(refs_->boxes.data(), n_);
    }
    bvh_.root = 0;
    is_left_.reset(new uint8_t[n_]);
    detail::advise_huge_pages(is_left_.get(), n_);
    scratch_.reset(new Scratch[n_]);
    detail::advise_huge_pages(scratch_.get(), n_ * sizeof(Scratch));

    detail::TopDownTree tree(bvh_);
    if constexpr (kInPlace) tree.place_leaves_in_place([this](uint32_t t) { return mesh_->triangle(t).bounds(); });
    tree.build(*this, detail::NodeRange{0, n_, 0}, kInvalidNode, Node{root_box_}, config_.parallel_threshold);
    tree.wait();
    // The scratch goes first: finish() has arrays of its own (peak memory).
    for (auto& list : owned_lists_) list.reset();
    is_left_.reset();
    scratch_.reset();
    tree.finish();
  }

  size_t split(const detail::NodeRange& r, const BvhNode& node, const Node&, Node& left, Node& right) {
    const size_t count = r.count();
    // Large nodes split each sweep and each list's partition into chunks on all threads.
    const bool large = count >= config_.parallel_split_threshold;

    Split split;
    if (centroids_coincide(r.begin, count)) {
      // No position separates anything: halve the list (ordered by id here).
      split.axis = 0;
      split.left_count = count / 2;
      const uint32_t* ids = lists_[0] + r.begin;
      Box l = detail::bounds_of(boxes_, ids, split.left_count);
      Box rr = detail::bounds_of(boxes_, ids + split.left_count, count - split.left_count);
      split.cost = l.area() * double(split.left_count) + rr.area() * double(count - split.left_count);
    } else {
      split = find_split(r.begin, count, large);
    }
    if (detail::sah_prefers_leaf(config_, node.area(), count, split.cost)) return 0;
    partition(r.begin, count, split, left.box, right.box, large);
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
    detail::advise_huge_pages(keys.get(), n_ * sizeof(uint64_t));
    for (int a = 0; a < 3; ++a) {
      tbb::parallel_for(tbb::blocked_range<size_t>(0, n_, 16384), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i)
          keys[i] = (uint64_t(orderable_bits(centroid(i, a))) << 32) | uint64_t(i);
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
    const Box* boxes = boxes_;
    const uint32_t* ids = lists_[a] + begin;
    return detail::sweep_sorted_range(
        count, [&](Box& b, size_t k) { b.extend(boxes[ids[k]]); }, [&](size_t k) -> double& { return suffix[k].area; });
  }

  // The positions of a large node's sweeps and partitions go to threads in chunks of this
  // many; fixed, so that the work, and any grouping, never depends on the thread count.
  static constexpr size_t kChunk = 8192;
  static size_t chunks_of(size_t count) { return (count + kChunk - 1) / kChunk; }

  // One axis of a large node's sweep, in chunks on all threads: the same boxes (a union is
  // exact in any grouping), so the same areas and costs at every position, and the chunks'
  // winners combined in order by the sequential rule (a later candidate wins only if
  // strictly better): the very candidate sweep_axis picks. It needs no scratch beyond the
  // node's own suffix areas; sweeping the three axes at once needed two more arrays, 16
  // bytes per reference at the root, the build's peak.
  detail::SweepCandidate sweep_axis_chunked(int a, size_t begin, size_t count, Scratch* suffix) const {
    const Box* boxes = boxes_;
    const uint32_t* ids = lists_[a] + begin;
    const size_t chunks = chunks_of(count);
    std::vector<Box> before(chunks + 1), after(chunks + 1);  // unions of the chunks before / after c
    std::vector<Box> own(chunks);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
      Box b;
      for (size_t k = c * kChunk, e = std::min(count, k + kChunk); k < e; ++k) b.extend(boxes[ids[k]]);
      own[c] = b;
    });
    for (size_t c = 0; c < chunks; ++c) before[c + 1] = merge(before[c], own[c]);
    for (size_t c = chunks; c-- > 0;) after[c] = merge(after[c + 1], own[c]);
    std::vector<detail::SweepCandidate> best(chunks);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
      const size_t first = c * kChunk, end = std::min(count, first + kChunk);
      Box right = after[c + 1];
      for (size_t k = end; k-- > std::max<size_t>(first, 1);) {
        right.extend(boxes[ids[k]]);
        suffix[k].area = right.area_unchecked();
      }
      Box left = before[c];
      detail::SweepCandidate& b = best[c];
      for (size_t k = first; k < end; ++k) {
        if (k > 0) {
          const double cost = left.area_unchecked() * double(k) + suffix[k].area * double(count - k);
          const size_t balance = k * 2 > count ? k * 2 - count : count - k * 2;
          const detail::SweepCandidate here{k, cost, balance};
          if (detail::better_candidate(here, b)) b = here;
        }
        left.extend(boxes[ids[k]]);
      }
    });
    detail::SweepCandidate winner;
    for (const detail::SweepCandidate& b : best)
      if (detail::better_candidate(b, winner)) winner = b;
    return winner;
  }

  // Sweeps the node's three sorted lists, one after the other (a large node's in chunks on
  // all threads); the per-axis winners are combined by the same rule either way.
  Split find_split(size_t begin, size_t count, bool large) const {
    detail::SweepCandidate best[3];
    Scratch* suffix = scratch_.get() + begin;
    for (int a = 0; a < 3; ++a)
      best[a] = large ? sweep_axis_chunked(a, begin, count, suffix) : sweep_axis(a, begin, count, suffix);
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
      if (centroid(ids[0], a) != centroid(ids[count - 1], a)) return false;
    }
    return true;
  }

  // A large node's stable partition of one list, in chunks on all threads: each chunk counts
  // its left entries, and from the counts before it knows where its entries go in the
  // partitioned order, which it writes to the scratch; the scratch is then copied back.
  void stable_partition_chunked(int a, size_t begin, size_t count) {
    uint32_t* list = lists_[a] + begin;
    Scratch* out = scratch_.get() + begin;
    const uint8_t* is_left = is_left_.get();
    const size_t chunks = chunks_of(count);
    std::vector<size_t> lefts(chunks + 1, 0);  // left entries before chunk c (after the scan)
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
      size_t n = 0;
      for (size_t k = c * kChunk, e = std::min(count, k + kChunk); k < e; ++k) n += is_left[list[k]] != 0;
      lefts[c + 1] = n;
    });
    for (size_t c = 0; c < chunks; ++c) lefts[c + 1] += lefts[c];
    const size_t total_left = lefts[chunks];
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
      size_t l = lefts[c], r = total_left + c * kChunk - lefts[c];
      for (size_t k = c * kChunk, e = std::min(count, k + kChunk); k < e; ++k) out[is_left[list[k]] ? l++ : r++].id = list[k];
    });
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
      for (size_t k = c * kChunk, e = std::min(count, k + kChunk); k < e; ++k) list[k] = out[k].id;
    });
  }

  // Moves the left references to the front of the other two lists, keeping their sorted
  // order (a stable partition by the per-reference side flag). Returns the child boxes.
  // Large nodes mark the two sides at the same time and partition each list in chunks.
  void partition(size_t begin, size_t count, const Split& split, Box& left_box, Box& right_box, bool large) {
    const Box* boxes = boxes_;
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
    if (large) {
      tbb::parallel_invoke([&] { mark(0, split.left_count, 1, left_box); },
                           [&] { mark(split.left_count, count, 0, right_box); });
      stable_partition_chunked(a1, begin, count);
      stable_partition_chunked(a2, begin, count);
    } else {
      mark(0, split.left_count, 1, left_box);
      mark(split.left_count, count, 0, right_box);
      stable_partition(a1, scratch_.get() + begin);
      stable_partition(a2, scratch_.get() + begin);
    }
  }

  // A reference's centroid on axis a: its box's centre, computed as make_references does,
  // with leaves in place.
  float centroid(size_t id, int a) const {
    if constexpr (kInPlace)
      return boxes_[id].center()[a];
    else
      return refs_->centroids[id][a];
  }

  const PrimitiveRefs* refs_ = nullptr;  // without leaves in place
  const Mesh* mesh_ = nullptr;           // with them
  const SweepSahConfig& config_;
  Bvh& bvh_;
  const size_t n_;
  const Box* boxes_ = nullptr;  // the references' boxes, where they are kept
  Box root_box_;
  uint32_t* lists_[3];                     // per axis: ids by (centroid, id), per node range
  std::unique_ptr<uint32_t[]> owned_lists_[2];  // storage of lists 1 and 2
  std::unique_ptr<uint8_t[]> is_left_;     // per reference id, written by its node's split
  std::unique_ptr<Scratch[]> scratch_;     // per position
};

bool all_finite(const std::vector<float>& values) {
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, values.size(), 65536), true,
      [&](const tbb::blocked_range<size_t>& r, bool ok) {
        for (size_t i = r.begin(); i < r.end(); ++i) ok &= std::isfinite(values[i]);
        return ok;
      },
      [](bool a, bool b) { return a && b; });
}

}  // namespace

Bvh build_sweep_sah(const PrimitiveRefs& refs, const SweepSahConfig& config) {
  validate(config);
  Bvh bvh;
  if (refs.empty()) return bvh;
  check_reference_count(refs.size(), "sweep SAH builder");
  SweepHeuristic<false>(refs, config, bvh).run();
  return bvh;
}

Bvh build_sweep_sah(const Mesh& mesh, const SweepSahConfig& config) {
  validate(config);
  Bvh bvh;
  if (mesh.triangle_count() == 0) return bvh;
  check_reference_count(mesh.triangle_count(), "sweep SAH builder");
  // Leaves of several references need their nodes while the boxes are still in use; and a
  // coordinate that is not finite (a mesh made by hand: loaded scenes refuse them) can make
  // a node that no split separates, which only the reference path can keep as one leaf.
  if (config.leaf.max_leaf_size > 1 || !all_finite(mesh.positions)) return build_sweep_sah(make_references(mesh), config);
  SweepHeuristic<true>(mesh, config, bvh).run();
  return bvh;
}

}  // namespace bvhopt
