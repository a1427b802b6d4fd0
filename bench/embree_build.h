// The callbacks of Embree's builder API (rtcBuildBVH) that build_bench and sbvh_bench give
// it: the peer's tree in the simplest form they allow, one primitive per leaf node, kept
// with the primitive's box (a spatial split's piece when Embree splits it). Header-only, as
// bench_support.h; include it only where BVHOPT_HAVE_EMBREE is set.
#pragma once

#include <embree3/rtcore.h>

#include <cstdint>

#include "bvhopt/box.h"

namespace bvhopt::bench {

struct EmbreeNode {
  bool leaf;
  uint32_t prim;  // leaf: the primitive's id (primID)
  Box box;        // leaf: the primitive's box as Embree passed it
  EmbreeNode* children[2];
};

inline void* embree_create_node(RTCThreadLocalAllocator alloc, unsigned int, void*) {
  auto* n = static_cast<EmbreeNode*>(rtcThreadLocalAlloc(alloc, sizeof(EmbreeNode), 16));
  n->leaf = false;
  n->children[0] = n->children[1] = nullptr;
  return n;
}

inline void embree_set_children(void* node, void** children, unsigned int count, void*) {
  auto* n = static_cast<EmbreeNode*>(node);
  for (unsigned i = 0; i < count && i < 2; ++i) n->children[i] = static_cast<EmbreeNode*>(children[i]);
}

// Our conversions recompute every inner box from the leaves, so Embree's are not kept.
inline void embree_set_bounds(void*, const RTCBounds**, unsigned int, void*) {}

// maxLeafSize 1 gives one primitive per leaf; a larger leaf becomes a chain of inner nodes.
inline void* embree_create_leaf(RTCThreadLocalAllocator alloc, const RTCBuildPrimitive* prims, size_t count, void*) {
  EmbreeNode* node = nullptr;
  for (size_t i = 0; i < count; ++i) {
    auto* leaf = static_cast<EmbreeNode*>(rtcThreadLocalAlloc(alloc, sizeof(EmbreeNode), 16));
    leaf->leaf = true;
    leaf->prim = prims[i].primID;
    leaf->box = Box(Vec3(prims[i].lower_x, prims[i].lower_y, prims[i].lower_z),
                    Vec3(prims[i].upper_x, prims[i].upper_y, prims[i].upper_z));
    if (!node) {
      node = leaf;
    } else {
      auto* inner = static_cast<EmbreeNode*>(rtcThreadLocalAlloc(alloc, sizeof(EmbreeNode), 16));
      inner->leaf = false;
      inner->children[0] = node;
      inner->children[1] = leaf;
      node = inner;
    }
  }
  return node;
}

// The four callbacks set on `args`.
inline void set_embree_callbacks(RTCBuildArguments& args) {
  args.createNode = embree_create_node;
  args.setNodeChildren = embree_set_children;
  args.setNodeBounds = embree_set_bounds;
  args.createLeaf = embree_create_leaf;
}

}  // namespace bvhopt::bench
