// The compressed 8-wide layout (Ylitie, Karras and Laine 2017): the SAH-optimal 8-wide
// collapse with leaves of at most 3 triangles, child boxes quantized to 8 bits per plane.
#include "bvhopt/compressed_wide_bvh.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numeric>
#include <string>

#include "bvhopt/error.h"
#include "layout/box_padding.h"

namespace bvhopt {
namespace {

constexpr uint32_t kWidth = 8;
constexpr uint32_t kMinExponent = 1, kMaxExponent = 254;  // biased: normal binary32 scales only

float scale_of(uint8_t biased) { return std::bit_cast<float>(uint32_t(biased) << 23); }
float decode(float origin, uint32_t q, float scale) { return origin + float(q) * scale; }

// The smallest scale whose 255 steps from `lo` reach `hi` once rounded as a reader decodes.
uint8_t exponent_for(float lo, float hi) {
  const double range = double(hi) - double(lo);
  int biased = int(kMinExponent);
  if (range > 0.0) biased = std::max(biased, int(std::ceil(std::log2(range / 255.0))) + 127);
  biased = std::min(biased, int(kMaxExponent));
  while (biased < int(kMaxExponent) && decode(lo, 255, scale_of(uint8_t(biased))) < hi) ++biased;
  return uint8_t(biased);
}

// Rounded outward: the decoded lower bound never above `lo`, the upper never below `hi`.
uint8_t quantize_down(float origin, float scale, float lo) {
  int q = int(std::clamp(std::floor((double(lo) - double(origin)) / double(scale)), 0.0, 255.0));
  while (q > 0 && decode(origin, uint32_t(q), scale) > lo) --q;
  return uint8_t(q);
}
uint8_t quantize_up(float origin, float scale, float hi) {
  int q = int(std::clamp(std::ceil((double(hi) - double(origin)) / double(scale)), 0.0, 255.0));
  while (q < 255 && decode(origin, uint32_t(q), scale) < hi) ++q;
  return uint8_t(q);
}

Box triangle_box(const Mesh& mesh, uint32_t id) { return mesh.triangle(id).bounds(); }

Box intersect(const Box& a, const Box& b) { return Box(max(a.min, b.min), min(a.max, b.max)); }

// A copy of the tree whose leaves hold at most `limit` distinct triangles: a larger leaf
// becomes a subtree split at the median centroid on the widest axis, each part's box the
// leaf's box clipped to its triangles (edge volume subdivision may have clipped the leaf).
class LeafSplitter {
 public:
  LeafSplitter(const FlatBvh& bvh, const Mesh& mesh, uint32_t limit) : bvh_(bvh), mesh_(mesh), limit_(limit) {}

  FlatBvh run() {
    std::vector<uint32_t> new_index(bvh_.nodes.size());
    for (size_t i = 0; i < bvh_.nodes.size(); ++i) {
      const FlatNode& f = bvh_.nodes[i];
      new_index[i] = uint32_t(out_.nodes.size());
      if (!f.is_leaf()) {
        out_.nodes.push_back(f);
        continue;
      }
      std::vector<uint32_t> ids(bvh_.triangle_ids.begin() + f.index, bvh_.triangle_ids.begin() + f.index + f.count);
      std::sort(ids.begin(), ids.end());
      ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
      emit(ids.data(), uint32_t(ids.size()), f.box);
    }
    for (size_t i = 0; i < bvh_.nodes.size(); ++i)
      if (!bvh_.nodes[i].is_leaf()) out_.nodes[new_index[i]].index = new_index[bvh_.nodes[i].index];
    return std::move(out_);
  }

 private:
  void emit(uint32_t* ids, uint32_t count, const Box& box) {
    FlatNode node{box, 0, 0, 0, 0};
    if (count <= limit_) {
      node.index = uint32_t(out_.triangle_ids.size());
      node.count = uint16_t(count);
      out_.triangle_ids.insert(out_.triangle_ids.end(), ids, ids + count);
      out_.nodes.push_back(node);
      return;
    }
    Box centroids;
    for (uint32_t i = 0; i < count; ++i) centroids.extend(triangle_box(mesh_, ids[i]).center());
    const int axis = centroids.largest_axis();
    std::sort(ids, ids + count, [&](uint32_t a, uint32_t b) {
      const float ca = triangle_box(mesh_, a).center()[axis], cb = triangle_box(mesh_, b).center()[axis];
      return ca < cb || (ca == cb && a < b);
    });
    const uint32_t half = count / 2;
    node.axis = uint8_t(axis);
    const size_t at = out_.nodes.size();
    out_.nodes.push_back(node);
    emit(ids, half, part_box(ids, half, box));
    out_.nodes[at].index = uint32_t(out_.nodes.size());
    emit(ids + half, count - half, part_box(ids + half, count - half, box));
  }

  Box part_box(const uint32_t* ids, uint32_t count, const Box& leaf) const {
    Box b;
    for (uint32_t i = 0; i < count; ++i) b.extend(triangle_box(mesh_, ids[i]));
    const Box clipped = intersect(b, leaf);
    return clipped.is_empty() ? leaf : clipped;
  }

  const FlatBvh& bvh_;
  const Mesh& mesh_;
  uint32_t limit_;
  FlatBvh out_;
};

// Writes the collapsed tree breadth-first, so that each node's inner children are consecutive.
class CwbvhWriter {
 public:
  CwbvhWriter(const CollapsedBvh& wide, const FlatBvh& bvh, const Mesh& mesh)
      : wide_(wide), bvh_(bvh), mesh_(mesh), pad_(bvh) {}

  CompressedWideBvh run() {
    std::vector<uint32_t> order{0};  // wide node of each output node
    for (size_t k = 0; k < order.size(); ++k) {
      out_.nodes.emplace_back();
      out_.exact_child_boxes.resize(out_.exact_child_boxes.size() + kWidth);
      write_node(order[k], k, order);
    }
    out_.stack_entries = stack_need() + 1;
    return std::move(out_);
  }

 private:
  void write_node(uint32_t w, size_t k, std::vector<uint32_t>& order) {
    const uint32_t begin = wide_.child_begin[w], end = wide_.child_begin[w + 1];
    if (end - begin > kWidth) throw Error("cwbvh: internal error, a node of " + std::to_string(end - begin) + " children");
    CwbvhNode node{};
    node.child_base = uint32_t(order.size());
    node.triangle_base = uint32_t(out_.triangles.size());
    Box* exact = &out_.exact_child_boxes[k * kWidth];
    Box all;
    for (uint32_t s = begin; s < end; ++s) {
      const Box& b = bvh_.nodes[wide_.children[s]].box;
      exact[s - begin] = Box(Vec3(pad_.below(b.min.x), pad_.below(b.min.y), pad_.below(b.min.z)),
                             Vec3(pad_.above(b.max.x), pad_.above(b.max.y), pad_.above(b.max.z)));
      all.extend(exact[s - begin]);
    }
    quantize(node, exact, end - begin, all);
    for (uint32_t s = begin; s < end; ++s) {
      const uint32_t slot = s - begin;
      if (!wide_.child_is_leaf[s]) {
        node.inner_mask = uint8_t(node.inner_mask | (1u << slot));
        node.meta[slot] = uint8_t(0x20u | (24u + slot));
        order.push_back(wide_.child_index[s]);
      } else {
        node.meta[slot] = leaf_meta(wide_.child_index[s], node.triangle_base);
      }
    }
    out_.nodes[k] = node;
  }

  uint8_t leaf_meta(uint32_t leaf, uint32_t triangle_base) {
    const uint32_t first = wide_.leaf_begin[leaf], count = wide_.leaf_begin[leaf + 1] - first;
    if (count == 0 || count > kCwbvhMaxLeafTriangles)
      throw Error("cwbvh: internal error, a leaf of " + std::to_string(count) + " triangles");
    const uint32_t offset = uint32_t(out_.triangles.size()) - triangle_base;
    for (uint32_t i = 0; i < count; ++i) {
      const uint32_t id = wide_.leaf_triangles[first + i];
      const Triangle t = mesh_.triangle(id);
      out_.triangles.push_back({{t.v0.x, t.v0.y, t.v0.z}, id, {t.v1.x, t.v1.y, t.v1.z}, 0, {t.v2.x, t.v2.y, t.v2.z}, 0});
    }
    static constexpr uint8_t kUnary[4] = {0, 0x20, 0x60, 0xe0};
    return uint8_t(kUnary[count] | offset);
  }

  static void quantize(CwbvhNode& node, const Box* exact, uint32_t used, const Box& all) {
    const float lo[3] = {all.min.x, all.min.y, all.min.z}, hi[3] = {all.max.x, all.max.y, all.max.z};
    for (int a = 0; a < 3; ++a) {
      node.origin[a] = lo[a];
      node.exponent[a] = exponent_for(lo[a], hi[a]);
      const float scale = scale_of(node.exponent[a]);
      for (uint32_t c = 0; c < used; ++c) {
        node.q_lo[a][c] = quantize_down(lo[a], scale, exact[c].min[a]);
        node.q_hi[a][c] = quantize_up(lo[a], scale, exact[c].max[a]);
      }
    }
  }

  // Deepest sum over a root-to-leaf path of (children - 1): bottom-up over the breadth-first
  // order, children always after their parent.
  uint32_t stack_need() const {
    std::vector<uint32_t> need(out_.nodes.size(), 0);
    for (size_t k = out_.nodes.size(); k-- > 0;) {
      const CwbvhNode& n = out_.nodes[k];
      uint32_t children = 0, deepest = 0, inner = 0;
      for (uint32_t s = 0; s < kWidth; ++s) {
        if (n.meta[s] == 0) continue;
        ++children;
        if (n.inner_mask & (1u << s)) deepest = std::max(deepest, need[n.child_base + inner++]);
      }
      need[k] = deepest + (children > 0 ? children - 1 : 0);
    }
    return need.empty() ? 0 : need[0];
  }

  const CollapsedBvh& wide_;
  const FlatBvh& bvh_;
  const Mesh& mesh_;
  detail::BoxPadding pad_;
  CompressedWideBvh out_;
};

}  // namespace

CompressedWideBvh build_compressed_wide_bvh(const FlatBvh& bvh, const Mesh& mesh, const WideCostModel& cost) {
  for (uint32_t id : bvh.triangle_ids)
    if (id >= mesh.triangle_count())
      throw Error("cwbvh: triangle id " + std::to_string(id) + " out of range (mesh " + mesh.name + " has " +
                  std::to_string(mesh.triangle_count()) + " triangles)");
  const FlatBvh small_leaves = LeafSplitter(bvh, mesh, kCwbvhMaxLeafTriangles).run();
  CollapseOptions options;
  options.width = kWidth;
  options.cost = cost;
  options.max_leaf_triangles = kCwbvhMaxLeafTriangles;
  const CollapsedBvh wide = collapse_to_wide(small_leaves, options);
  CompressedWideBvh out = CwbvhWriter(wide, small_leaves, mesh).run();
  out.sah_cost = wide.sah_cost;
  return out;
}

Box cwbvh_child_box(const CwbvhNode& node, uint32_t slot) {
  if (slot >= kWidth || node.meta[slot] == 0) return Box();
  Box b;
  for (int a = 0; a < 3; ++a) {
    const float scale = scale_of(node.exponent[a]);
    b.min[a] = decode(node.origin[a], node.q_lo[a][slot], scale);
    b.max[a] = decode(node.origin[a], node.q_hi[a][slot], scale);
  }
  return b;
}

}  // namespace bvhopt
