#include "bvhopt/median_builder.h"

#include <algorithm>

#include "builders/top_down.h"

namespace bvhopt {
namespace {

size_t object_median_split(const PrimitiveRefs& refs, uint32_t* ids, size_t count) {
  Box cb = detail::centroid_bounds_of(refs, ids, count);
  int axis = cb.largest_axis();
  size_t half = count / 2;
  // Ties broken by reference id so the split is a pure function of the input set.
  std::nth_element(ids, ids + half, ids + count, [&](uint32_t a, uint32_t b) {
    float ca = refs.centroids[a][axis], cb_ = refs.centroids[b][axis];
    return ca < cb_ || (ca == cb_ && a < b);
  });
  return half;
}

size_t spatial_median_split(const PrimitiveRefs& refs, uint32_t* ids, size_t count, const Box& box) {
  int axis = box.largest_axis();
  float middle = box.center()[axis];
  uint32_t* mid = std::stable_partition(ids, ids + count, [&](uint32_t id) { return refs.centroids[id][axis] < middle; });
  size_t left = static_cast<size_t>(mid - ids);
  if (left == 0 || left == count) return object_median_split(refs, ids, count);
  return left;
}

// Both medians as a TopDownTree heuristic: a node fitting in a leaf is one; the children's
// boxes are the bounds of their references.
template <bool kSpatial>
class MedianHeuristic {
 public:
  struct Node {
    Box box;
  };

  MedianHeuristic(const PrimitiveRefs& refs, const MedianConfig& config, Bvh& bvh)
      : refs_(refs), config_(config), bvh_(bvh) {}

  void run() {
    const size_t n = refs_.size();
    bvh_.nodes.assign(2 * n - 1, BvhNode{});
    bvh_.ref_indices.resize(n);
    for (size_t i = 0; i < n; ++i) bvh_.ref_indices[i] = static_cast<uint32_t>(i);
    bvh_.root = 0;
    detail::TopDownTree tree(bvh_);
    tree.build(*this, detail::NodeRange{0, n, 0}, kInvalidNode, Node{detail::bounds_of(refs_, bvh_.ref_indices.data(), n)},
               config_.parallel_threshold);
    tree.finish();
  }

  size_t split(const detail::NodeRange& r, const BvhNode&, const Node& node, Node& left, Node& right) {
    const size_t count = r.count();
    if (count <= config_.leaf.max_leaf_size) return 0;
    uint32_t* ids = bvh_.ref_indices.data() + r.begin;
    size_t left_count =
        kSpatial ? spatial_median_split(refs_, ids, count, node.box) : object_median_split(refs_, ids, count);
    left.box = detail::bounds_of(refs_, ids, left_count);
    right.box = detail::bounds_of(refs_, ids + left_count, count - left_count);
    return left_count;
  }

  void leaf(const detail::NodeRange&) {}  // the slots already hold the references

 private:
  const PrimitiveRefs& refs_;
  const MedianConfig& config_;
  Bvh& bvh_;
};

template <bool kSpatial>
Bvh build_median(const PrimitiveRefs& refs, const MedianConfig& config) {
  validate(config);
  check_reference_count(refs.size(), kSpatial ? "spatial median builder" : "object median builder");
  Bvh bvh;
  if (refs.empty()) return bvh;
  MedianHeuristic<kSpatial>(refs, config, bvh).run();
  return bvh;
}

}  // namespace

Bvh build_object_median(const PrimitiveRefs& refs, const MedianConfig& config) { return build_median<false>(refs, config); }

Bvh build_spatial_median(const PrimitiveRefs& refs, const MedianConfig& config) { return build_median<true>(refs, config); }

}  // namespace bvhopt
