// A flat tree without finalize, so the tests can tell a finalize fault from a traversal one.
#include "bvhopt/testing/flatten_for_tracing.h"

#include "bvhopt/error.h"

#include <cmath>
#include <string>
#include <utility>
#include <vector>

namespace bvhopt {

FlatBvh flatten_for_tracing(const Bvh& bvh, const PrimitiveRefs& refs) {
  FlatBvh out;
  if (bvh.empty()) return out;
  struct Item {
    uint32_t node;
    uint32_t parent_slot;  // flat index whose `index` becomes this node (right children)
  };
  std::vector<Item> todo{{bvh.root, kInvalidNode}};
  while (!todo.empty()) {
    const Item it = todo.back();
    todo.pop_back();
    const uint32_t flat = static_cast<uint32_t>(out.nodes.size());
    if (it.parent_slot != kInvalidNode) out.nodes[it.parent_slot].index = flat;
    const BvhNode& n = bvh[it.node];
    FlatNode f{};
    f.box = n.box;
    if (n.is_leaf()) {
      f.index = static_cast<uint32_t>(out.triangle_ids.size());
      // The flat node's count is 16 bits; casting would drop triangles without a word.
      if (n.ref_count() > kMaxTracedLeafSize)
        throw Error("flatten_for_tracing: node " + std::to_string(it.node) + ": leaf holds " +
                    std::to_string(n.ref_count()) + " references, more than " + std::to_string(kMaxTracedLeafSize));
      f.count = static_cast<uint16_t>(n.ref_count());
      for (uint32_t i = 0; i < n.ref_count(); ++i)
        out.triangle_ids.push_back(refs.triangle_ids[bvh.ref_indices[n.first_ref() + i]]);
      out.nodes.push_back(f);
      continue;
    }
    // Lower child on the axis of widest centre separation first, so split_axis order works.
    uint32_t a = n.left(), b = n.right();
    const Vec3 ca = bvh[a].box.center(), cb = bvh[b].box.center();
    const Vec3 d = cb - ca;
    int axis = 0;
    if (std::fabs(d.y) > std::fabs(d[axis])) axis = 1;
    if (std::fabs(d.z) > std::fabs(d[axis])) axis = 2;
    if (d[axis] < 0.0f) std::swap(a, b);
    f.axis = static_cast<uint8_t>(axis);
    out.nodes.push_back(f);
    todo.push_back({b, flat});
    todo.push_back({a, kInvalidNode});
  }
  return out;
}

}  // namespace bvhopt
