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

}  // namespace

Bvh build_object_median(const PrimitiveRefs& refs, const MedianConfig& config) {
  Bvh bvh;
  const uint32_t max_leaf = std::max<uint32_t>(1, config.leaf.max_leaf_size);
  detail::build_top_down(
      bvh, refs,
      [&](uint32_t* ids, size_t count, const Box&) -> size_t {
        return count <= max_leaf ? 0 : object_median_split(refs, ids, count);
      },
      config.parallel_threshold);
  return bvh;
}

Bvh build_spatial_median(const PrimitiveRefs& refs, const MedianConfig& config) {
  Bvh bvh;
  const uint32_t max_leaf = std::max<uint32_t>(1, config.leaf.max_leaf_size);
  detail::build_top_down(
      bvh, refs,
      [&](uint32_t* ids, size_t count, const Box& box) -> size_t {
        if (count <= max_leaf) return 0;
        int axis = box.largest_axis();
        float middle = box.center()[axis];
        uint32_t* mid = std::stable_partition(ids, ids + count, [&](uint32_t id) { return refs.centroids[id][axis] < middle; });
        size_t left = static_cast<size_t>(mid - ids);
        if (left == 0 || left == count) return object_median_split(refs, ids, count);
        return left;
      },
      config.parallel_threshold);
  return bvh;
}

}  // namespace bvhopt
