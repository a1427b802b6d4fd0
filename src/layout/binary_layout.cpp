// From a FlatBvh and its mesh to the BinaryNode pairs and leaf vertices the tracer reads.
#include "bvhopt/binary_layout.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "bvhopt/error.h"
#include "layout/box_padding.h"

namespace bvhopt {
namespace {

// Every right child a later node and every leaf's entries inside the id array, so the
// layout below never indexes out of range.
void check_flat_references(const FlatBvh& bvh) {
  const size_t n = bvh.nodes.size();
  if (n == 0) throw Error("tracer: the tree has no nodes");
  const size_t entries = bvh.triangle_ids.size();
  for (size_t i = 0; i < n; ++i) {
    const FlatNode& f = bvh.nodes[i];
    if (f.is_leaf()) {
      if (size_t(f.index) + f.count > entries)
        throw Error("tracer: node " + std::to_string(i) + ": leaf entries " + std::to_string(f.index) + "+" +
                    std::to_string(f.count) + " beyond the " + std::to_string(entries) + " triangle ids");
    } else if (i + 1 >= n || f.index <= i + 1 || f.index >= n) {
      throw Error("tracer: node " + std::to_string(i) + ": right child " + std::to_string(f.index) +
                  " is not a later node (the tree has " + std::to_string(n) + " nodes)");
    }
  }
}

// One BinaryNode per inner flat node, numbered in the flat (depth-first) order so a left
// child's BinaryNode follows its parent's. A tree that is a single leaf gets one BinaryNode
// holding that leaf and an empty slot.
void lay_out_nodes(const FlatBvh& bvh, const detail::BoxPadding& pad, BinaryLayout& out) {
  const size_t n = bvh.nodes.size();
  std::vector<uint32_t> pair_of(n, kInvalidNode);
  uint32_t pairs = 0;
  for (size_t i = 0; i < n; ++i)
    if (!bvh.nodes[i].is_leaf()) pair_of[i] = pairs++;
  out.nodes.assign(std::max<uint32_t>(pairs, 1), BinaryNode{});
  auto set_child = [&](BinaryNode& t, int slot, size_t flat) {
    const FlatNode& c = bvh.nodes[flat];
    t.x[slot] = pad.below(c.box.min.x);
    t.x[slot + 2] = pad.above(c.box.max.x);
    t.y[slot] = pad.below(c.box.min.y);
    t.y[slot + 2] = pad.above(c.box.max.y);
    t.z[slot] = pad.below(c.box.min.z);
    t.z[slot + 2] = pad.above(c.box.max.z);
    t.child[slot] = c.is_leaf() ? c.index : pair_of[flat];
    t.count[slot] = (t.count[slot] & ~BinaryNode::kCountMask) | (c.is_leaf() ? c.count : BinaryNode::kInnerChild);
  };
  std::vector<uint32_t> depth(n, 0);
  if (pairs == 0) {
    set_child(out.nodes[0], 0, 0);
    set_child(out.nodes[0], 1, 0);
    out.nodes[0].count[1] = 0;  // empty slot
  }
  for (size_t i = 0; i < n; ++i) {
    const FlatNode& f = bvh.nodes[i];
    if (f.is_leaf()) continue;
    BinaryNode& t = out.nodes[pair_of[i]];
    t.count[0] = uint32_t(f.axis > 2 ? 0 : f.axis) << 24;
    set_child(t, 0, i + 1);
    set_child(t, 1, f.index);
    depth[i + 1] = depth[f.index] = depth[i] + 1;
    out.depth = std::max<size_t>(out.depth, depth[i] + 1);
  }
}

// Per leaf entry, the nine vertex coordinates of its triangle.
void lay_out_leaf_vertices(const FlatBvh& bvh, const Mesh& mesh, BinaryLayout& out) {
  const size_t entries = bvh.triangle_ids.size();
  out.triangle_ids = bvh.triangle_ids;
  out.vertices.resize(9 * entries);
  for (size_t e = 0; e < entries; ++e) {
    if (out.triangle_ids[e] >= out.mesh_triangles)
      throw Error("tracer: leaf entry " + std::to_string(e) + ": triangle id " + std::to_string(out.triangle_ids[e]) +
                  " out of range (mesh " + mesh.name + " has " + std::to_string(out.mesh_triangles) + " triangles)");
    const Triangle t = mesh.triangle(out.triangle_ids[e]);
    const float v[9] = {t.v0.x, t.v0.y, t.v0.z, t.v1.x, t.v1.y, t.v1.z, t.v2.x, t.v2.y, t.v2.z};
    std::copy(v, v + 9, out.vertices.begin() + 9 * e);
  }
}

}  // namespace

BinaryLayout make_binary_layout(const FlatBvh& bvh, const Mesh& mesh) {
  check_flat_references(bvh);
  BinaryLayout out;
  out.mesh_triangles = mesh.triangle_count();
  lay_out_nodes(bvh, detail::BoxPadding(bvh), out);
  lay_out_leaf_vertices(bvh, mesh, out);
  return out;
}

}  // namespace bvhopt
