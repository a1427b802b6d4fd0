// Wide BVHs: the binary tree collapsed into 4- or 8-wide nodes, and their memory layout
// (SoA child boxes, per-octant child order, 4-triangle SIMD leaf blocks) that the wide
// tracer (bvhopt/wide_tracer.h) reads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"

namespace bvhopt {

// The wide SAH cost: C = [c_node * sum_nodes A(n) + c_blk * sum_leaves A(l) * ceil(p(l)/4)]
// / A(root), p(l) the distinct triangles of leaf l (a leaf block tests 4 triangles at once).
// Only the ratio matters to the collapse. Calibrated by tracing the best trees of the shared
// scenes collapsed with several c_blk (c_node = 1) against Embree in the same run
// (bench/trace_bench --wide-variants or --block-costs; primary, random and AO rays, 1 thread;
// docs/wide-bvh.md). On a Xeon (AVX-512) no ratio beat 1:1 beyond the noise. On Zen 4, once
// the kernel prefetched a node's leaf blocks with the node, 0.5 was ahead of 1. On Zen 5
// (December 2026, three runs over the 33 scene and ray pairs) 0.25, 0.35 and 0.5 were level
// overall (geometric means 1.310, 1.316 and 1.316 of Embree's rays/s), 0.25 ahead on primary
// rays (+3 %) and 2 % behind on random and AO rays, with layouts 10-14 % smaller; and only
// 0.25 let the spatial-split tree of staircase trace its primary rays faster than the
// unsplit one (1.10 against 0.93-0.98). So 0.25 is the default.
// bench/trace_bench --fit-costs prints nodes and blocks per ray beside ns/ray for redoing
// this on another CPU.
struct WideCostModel {
  double node = 1.0;    // c_node, per wide inner node visited
  double block = 0.25;  // c_blk, per 4-triangle leaf block tested
};

enum class CollapseMethod : uint8_t {
  // Ylitie, Karras and Laine (2017), section 3.1: dynamic programming over the binary tree
  // for the collapse of least wide SAH cost (each binary node may become a wide node, a leaf
  // holding its whole subtree, or disappear into its parent's slots).
  sah_optimal = 0,
  // Embree's widening: a node adopts the grandchildren of its largest-area inner child until
  // its slots are full; the binary leaves stay the leaves. Reported to show what the DP gains.
  greedy = 1,
};

struct CollapseOptions {
  uint32_t width = 8;  // 4 or 8
  CollapseMethod method = CollapseMethod::sah_optimal;
  WideCostModel cost;
  // Most distinct triangles the DP may gather into one leaf (at most 64: 16 blocks). A binary
  // leaf with more is kept as it is when it fits 64, else the layout throws Error.
  uint32_t max_leaf_triangles = 16;
};

// The collapsed topology, in terms of the binary (flat) tree's nodes: wide node w stands for
// flat node nodes[w] and has children children[child_begin[w] .. child_begin[w+1]), each a
// flat node that is a wide node (child_index = its wide node) or a leaf (child_index = its
// leaf, whose distinct triangle ids, ascending, are leaf_triangles[leaf_begin[l] ..
// leaf_begin[l+1])). Wide nodes are depth-first, the root first.
struct CollapsedBvh {
  uint32_t width = 8;
  std::vector<uint32_t> nodes;
  std::vector<uint32_t> child_begin{0};
  std::vector<uint32_t> children;
  std::vector<uint8_t> child_is_leaf;
  std::vector<uint32_t> child_index;
  std::vector<uint32_t> leaf_begin{0};
  std::vector<uint32_t> leaf_triangles;
  double sah_cost = 0.0;  // wide SAH cost, normalized by the root's area

  size_t node_count() const { return nodes.size(); }
  size_t leaf_count() const { return leaf_begin.size() - 1; }
};

// Collapses a finalized binary tree, in parallel where it can. Deterministic: the same tree
// and cost on any thread count. The root is always a wide node (a tree that is one leaf
// becomes a root with a single leaf child). Throws Error for a width other than 4 or 8.
CollapsedBvh collapse_to_wide(const FlatBvh& bvh, const CollapseOptions& options = {});

// The wide SAH cost of a collapse, evaluated from its structure (the tests check the DP's own
// figure against it).
double wide_sah_cost(const CollapsedBvh& wide, const FlatBvh& bvh, const WideCostModel& cost);

// Which ray-triangle test the leaf blocks are laid out for.
enum class TriangleTest : uint8_t {
  // Moller and Trumbore (1997) on 4 triangles at once from v0 and the two edges stored per
  // block: the default, the faster of the two (see wide_tracer.h for the measured figures).
  moller_trumbore = 0,
  // Woop, Benthin and Wald (2013), the same test as the binary Tracer: no ray slips through
  // a shared edge. Blocks store the three vertices.
  watertight = 1,
};
std::string_view triangle_test_name(TriangleTest test);

// Memory layout. Everything lives in one 64-byte aligned arena addressed in 32-byte units;
// nodes are depth-first and each node's leaf blocks follow it directly.
//
// A child word: kEmptyChild for an unused slot (its box is inverted, min = +inf, max = -inf,
// so no ray enters it); a leaf when bit 31 is set: bits 27-30 hold the number of blocks - 1
// and bits 0-26 the offset of the first block; otherwise the offset of an inner node.
inline constexpr uint32_t kWideLeafFlag = 0x80000000u;
inline constexpr uint32_t kWideEmptyChild = 0xffffffffu;
inline constexpr uint32_t kWideOffsetMask = 0x07ffffffu;
inline constexpr uint32_t kWideMaxBlocks = 16;
// The most distinct triangles a wide leaf holds; a binary leaf of more cannot be laid out.
inline constexpr uint32_t kWideMaxLeafTriangles = 4 * kWideMaxBlocks;
inline constexpr size_t kWideUnit = 32;  // bytes per offset unit

// Child boxes as SoA rows lo_x, hi_x, lo_y, hi_y, lo_z, hi_z (padded outward, see
// wide_layout.cpp). octant_order[o]: for a ray whose direction signs are octant o (bit 0: x
// negative, bit 1: y, bit 2: z), the children nearest first along the octant's diagonal,
// 3 bits each (the k-th nearest in bits 3k..3k+2); empty slots come last.
struct alignas(64) Bvh8Node {
  float bounds[6][8];
  uint32_t child[8];
  uint32_t octant_order[8];
};
static_assert(sizeof(Bvh8Node) == 256);

// The same for 4 children in two cache lines; the order 2 bits per child.
struct alignas(64) Bvh4Node {
  float bounds[6][4];
  uint32_t child[4];
  uint8_t octant_order[8];
  uint8_t unused[8];
};
static_assert(sizeof(Bvh4Node) == 128);

// Four triangles as SoA rows: rows 0-2 v0 x, y, z; rows 3-5 the edge v1 - v0 (Moller-Trumbore)
// or v1 (watertight); rows 6-8 v2 - v0 or v2. A block of fewer than 4 triangles repeats its
// last triangle.
struct alignas(32) TriangleBlock {
  float p[9][4];
  uint32_t id[4];
};
static_assert(sizeof(TriangleBlock) == 160);

struct WideLayoutOptions {
  CollapseOptions collapse;
  TriangleTest test = TriangleTest::moller_trumbore;
};

struct WideLayoutStats {
  size_t nodes = 0;
  size_t leaves = 0;
  size_t blocks = 0;
  size_t triangle_slots = 0;   // 4 per block
  size_t bytes = 0;            // the arena
  double sah_cost = 0.0;       // of the collapse
  double collapse_seconds = 0.0;
  double layout_seconds = 0.0;
};

// A finalized binary tree collapsed and laid out for the wide tracer. Several leaf entries
// of one triangle (edge volume subdivision) are merged: each leaf holds a triangle once.
class WideBvh {
 public:
  struct FreeArena {  // the arena is allocated with posix_memalign
    void operator()(std::byte* p) const;
  };

  WideBvh(const FlatBvh& bvh, const Mesh& mesh, const WideLayoutOptions& options = {});

  uint32_t width() const { return width_; }
  TriangleTest triangle_test() const { return test_; }
  const std::byte* data() const { return arena_.get(); }
  uint32_t root() const { return root_; }  // child word of the root (an inner node)
  // Stack entries a traversal may need at most (width - 1 per level of the deepest path, and
  // room for the kernels' full-vector stores beyond the top).
  uint32_t stack_entries() const { return stack_entries_; }
  const WideLayoutStats& stats() const { return stats_; }
  size_t triangle_count() const { return mesh_triangles_; }

 private:
  std::unique_ptr<std::byte[], FreeArena> arena_;
  uint32_t root_ = 0;
  uint32_t width_ = 8;
  TriangleTest test_ = TriangleTest::moller_trumbore;
  uint32_t stack_entries_ = 0;
  size_t mesh_triangles_ = 0;
  WideLayoutStats stats_;
};

}  // namespace bvhopt
