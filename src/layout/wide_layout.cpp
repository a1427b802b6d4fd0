// The wide layout: collapsed nodes written depth-first into one aligned arena, each node
// followed by its leaf blocks, so a node and the triangles it points to share pages.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <cmath>
#include <limits>
#include <new>
#include <string>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/wide_bvh.h"
#include "layout/box_padding.h"
#include "tree/huge_pages.h"

namespace bvhopt {

std::string_view triangle_test_name(TriangleTest test) {
  return test == TriangleTest::watertight ? "watertight" : "moller-trumbore";
}

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The arena: one block for the layout, 64-byte aligned. Arenas of 2 MiB or more are 2 MiB
// aligned, rounded up to whole 2 MiB pages and asked to be backed by huge pages: incoherent
// rays touch nodes all over the arena, and with 4 KiB pages most node visits would also miss
// the TLB (Embree allocates its BVH the same way). The rounding is for the time it takes to
// write: a partial huge page at the end is backed by 4 KiB pages, each a fault of its own,
// and in this VM a fault costs about 9 us (2CylinderEngine, 7.6 MB: the layout took 7.4 ms
// with its last 1.6 MB on small pages, 3.9 ms rounded up; writing 7.6 MB of fresh memory
// took 3.2 ms against 0.35). It costs at most 2 MiB of memory, under half the block. Not
// cleared: the writers fill every byte, so the pages are first touched by the threads that
// write them.
constexpr size_t kHugePage = detail::kHugePageBytes;

std::unique_ptr<std::byte[], WideBvh::FreeArena> allocate_arena(size_t bytes) {
  const bool huge = bytes >= kHugePage;
  const size_t size = huge ? (bytes + kHugePage - 1) / kHugePage * kHugePage : std::max<size_t>(bytes, 64);
  void* p = nullptr;
  if (posix_memalign(&p, huge ? kHugePage : 64, size) != 0)
    throw Error("wide layout: out of memory for " + std::to_string(bytes) + " bytes");
  if (huge) detail::advise_huge_pages(p, size);
  return std::unique_ptr<std::byte[], WideBvh::FreeArena>(static_cast<std::byte*>(p));
}

// Node-type specifics: where the boxes, child words and ranks of a W-wide node are.
template <uint32_t W>
struct NodeAccess;
template <>
struct NodeAccess<8> {
  using Node = Bvh8Node;
  static void set_order(Node& n, int octant, uint32_t position, uint32_t child) {
    n.octant_order[octant] |= child << (3 * position);
  }
};
template <>
struct NodeAccess<4> {
  using Node = Bvh4Node;
  static void set_order(Node& n, int octant, uint32_t position, uint32_t child) {
    n.octant_order[octant] = uint8_t(n.octant_order[octant] | (child << (2 * position)));
  }
};

// Depth-first, each node followed by its leaves' blocks (in slot order), then its inner
// children's subtrees (in slot order); every node on a 64-byte boundary. A subtree's size
// does not depend on where it is placed, so all offsets are known before anything is
// written (one pass bottom-up for the sizes, one top-down for the offsets), and the nodes
// are then written in parallel: the same bytes on any number of threads.
template <uint32_t W>
class LayoutBuilder {
  using Access = NodeAccess<W>;
  using Node = typename Access::Node;

 public:
  LayoutBuilder(const CollapsedBvh& wide, const FlatBvh& bvh, const Mesh& mesh, TriangleTest test)
      : wide_(wide), bvh_(bvh), mesh_(mesh), test_(test), pad_(bvh),
        offset_(wide.node_count()), stack_need_(wide.node_count()) {
    place();
  }

  // Writes every node and block; returns the arena.
  std::unique_ptr<std::byte[], WideBvh::FreeArena> write() {
    auto arena = allocate_arena(bytes_);
    std::byte* base = arena.get();
    // One thread first touches one byte per huge page: when two threads' writes both fault
    // on huge pages, the faults contend (Conference, bvh8, 2 threads: the layout took 10.9 ms
    // against 8.9 on one thread; with these touches first, 4.9 to 6.2 ms). Where no huge
    // pages are granted this is one small page per 2 MiB.
    for (size_t k = 0; k < bytes_; k += kHugePage) *reinterpret_cast<volatile char*>(base + k) = 0;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, wide_.node_count(), 512), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t w = r.begin(); w < r.end(); ++w) {
        if (w + 1 < r.end()) prefetch_node(uint32_t(w + 1));
        write_node(base, uint32_t(w));
      }
    });
    return arena;
  }

  size_t bytes() const { return bytes_; }
  size_t blocks() const { return blocks_; }
  uint32_t stack_need() const { return stack_need_.empty() ? 0 : stack_need_[0]; }

 private:
  static size_t round64(size_t n) { return (n + 63) / 64 * 64; }
  uint32_t blocks_of_leaf(uint32_t leaf) const {
    const uint32_t count = wide_.leaf_begin[leaf + 1] - wide_.leaf_begin[leaf];
    const uint32_t blocks = (count + 3) / 4;
    if (blocks == 0 || blocks > kWideMaxBlocks) throw Error("wide layout: a leaf of " + std::to_string(count) + " triangles");
    return blocks;
  }
  // The node and its leaves' blocks.
  size_t own_bytes(uint32_t w) const {
    size_t blocks = 0;
    for (uint32_t s = wide_.child_begin[w]; s < wide_.child_begin[w + 1]; ++s)
      if (wide_.child_is_leaf[s]) blocks += blocks_of_leaf(wide_.child_index[s]);
    return sizeof(Node) + round64(blocks * sizeof(TriangleBlock));
  }

  // Wide nodes are numbered depth-first (children after their parent), so sizes go
  // bottom-up in reverse order and offsets top-down in order.
  void place() {
    const size_t n = wide_.node_count();
    std::vector<size_t> subtree(n);
    for (size_t w = n; w-- > 0;) {
      size_t size = own_bytes(uint32_t(w));
      uint32_t deepest = 0;
      const uint32_t begin = wide_.child_begin[w], end = wide_.child_begin[w + 1];
      for (uint32_t s = begin; s < end; ++s) {
        if (wide_.child_is_leaf[s]) {
          blocks_ += blocks_of_leaf(wide_.child_index[s]);
        } else {
          size += subtree[wide_.child_index[s]];
          deepest = std::max(deepest, stack_need_[wide_.child_index[s]]);
        }
      }
      subtree[w] = size;
      stack_need_[w] = deepest + (end - begin) - 1;
    }
    bytes_ = n ? subtree[0] : 0;
    if (bytes_ / kWideUnit > kWideOffsetMask) throw Error("wide layout: the tree needs more than 4 GiB");
    for (size_t w = 0; w < n; ++w) {
      size_t at = offset_[w] + own_bytes(uint32_t(w));
      for (uint32_t s = wide_.child_begin[w]; s < wide_.child_begin[w + 1]; ++s) {
        if (wide_.child_is_leaf[s]) continue;
        offset_[wide_.child_index[s]] = at;
        at += subtree[wide_.child_index[s]];
      }
    }
  }

  // Asks for what node w will read first, one node ahead: its child boxes and its leaves'
  // index triples lie anywhere in the tree and the mesh, and fetched only when the node is
  // written they were its longest waits (the index triple before the vertices it names).
  void prefetch_node(uint32_t w) const {
    for (uint32_t s = wide_.child_begin[w]; s < wide_.child_begin[w + 1]; ++s) {
      __builtin_prefetch(&bvh_.nodes[wide_.children[s]]);
      if (!wide_.child_is_leaf[s]) continue;
      const uint32_t leaf = wide_.child_index[s];
      for (uint32_t k = wide_.leaf_begin[leaf]; k < wide_.leaf_begin[leaf + 1]; ++k)
        __builtin_prefetch(mesh_.indices.data() + 3 * size_t(wide_.leaf_triangles[k]));
    }
  }

  void write_node(std::byte* base, uint32_t w) {
    const uint32_t begin = wide_.child_begin[w], end = wide_.child_begin[w + 1];
    uint32_t words[W];
    std::fill(words, words + W, kWideEmptyChild);
    size_t at = offset_[w] + sizeof(Node);
    for (uint32_t s = begin; s < end; ++s) {
      if (wide_.child_is_leaf[s]) {
        const uint32_t blocks = blocks_of_leaf(wide_.child_index[s]);
        write_leaf(reinterpret_cast<TriangleBlock*>(base + at), wide_.child_index[s], blocks);
        words[s - begin] = kWideLeafFlag | ((blocks - 1) << 27) | uint32_t(at / kWideUnit);
        at += blocks * sizeof(TriangleBlock);
      } else {
        words[s - begin] = uint32_t(offset_[wide_.child_index[s]] / kWideUnit);
      }
    }
    std::memset(base + at, 0, round64(at) - at);  // the gap after an odd number of blocks
    Node* node = new (base + offset_[w]) Node{};
    fill_node(*node, begin, end, words);
  }

  void write_leaf(TriangleBlock* out, uint32_t leaf, uint32_t blocks) const {
    const uint32_t first = wide_.leaf_begin[leaf], count = wide_.leaf_begin[leaf + 1] - first;
    // The leaf's triangles lie anywhere in the mesh: ask for all their index triples, then
    // all their vertices, before reading any, so that the misses overlap instead of each
    // triangle waiting for its indices and then its vertices (that chain was the largest
    // part of writing a node).
    const uint32_t* ids = wide_.leaf_triangles.data() + first;
    for (uint32_t k = 0; k < count; ++k) __builtin_prefetch(mesh_.indices.data() + 3 * size_t(ids[k]));
    for (uint32_t k = 0; k < count; ++k) {
      const uint32_t* v = mesh_.indices.data() + 3 * size_t(ids[k]);
      for (int c = 0; c < 3; ++c) __builtin_prefetch(mesh_.positions.data() + 3 * size_t(v[c]));
    }
    for (uint32_t b = 0; b < blocks; ++b) {
      TriangleBlock& block = out[b];
      for (uint32_t lane = 0; lane < 4; ++lane) {
        const uint32_t id = wide_.leaf_triangles[first + std::min(4 * b + lane, count - 1)];
        const Triangle t = mesh_.triangle(id);
        const Vec3 p1 = test_ == TriangleTest::watertight ? t.v1 : t.v1 - t.v0;
        const Vec3 p2 = test_ == TriangleTest::watertight ? t.v2 : t.v2 - t.v0;
        const float rows[9] = {t.v0.x, t.v0.y, t.v0.z, p1.x, p1.y, p1.z, p2.x, p2.y, p2.z};
        for (int r = 0; r < 9; ++r) block.p[r][lane] = rows[r];
        block.id[lane] = id;
      }
    }
  }

  void fill_node(Node& node, uint32_t begin, uint32_t end, const uint32_t* words) const {
    for (uint32_t c = 0; c < W; ++c) {
      for (int a = 0; a < 3; ++a) {
        node.bounds[2 * a][c] = kInf;
        node.bounds[2 * a + 1][c] = -kInf;
      }
      node.child[c] = words[c];
    }
    Vec3 centre[W];
    for (uint32_t s = begin; s < end; ++s) {
      const Box& b = bvh_.nodes[wide_.children[s]].box;
      const uint32_t c = s - begin;
      const float lo[3] = {b.min.x, b.min.y, b.min.z}, hi[3] = {b.max.x, b.max.y, b.max.z};
      for (int a = 0; a < 3; ++a) {
        node.bounds[2 * a][c] = pad_.below(lo[a]);
        node.bounds[2 * a + 1][c] = pad_.above(hi[a]);
      }
      centre[c] = b.center();
    }
    // Per octant, children sorted by the position of their centre along the octant's
    // diagonal: the order a ray of that octant meets them when they do not overlap.
    // A child's place in the stable sort is the number of children of smaller key plus those
    // of equal key before it in slot order; in the opposite octant (o ^ 7, every key negated)
    // the number of larger key plus the same equal ones. Both are counted from one
    // comparison of all pairs, without branches: the insertion sort it replaces mispredicted
    // most of its steps, a quarter of writing a node. Empty slots get NaN keys, which compare
    // false with everything, and keep their own places after the used ones.
    const uint32_t used = end - begin;
    for (int o = 0; o < 4; ++o) {
      const Vec3 s((o & 1) ? -1.0f : 1.0f, (o & 2) ? -1.0f : 1.0f, 1.0f);
      float key[W];
      bool ordered = true;  // no NaN among the used keys (a strict weak order)
      for (uint32_t c = 0; c < W; ++c) {
        key[c] = c < used ? dot(centre[c], s) : std::numeric_limits<float>::quiet_NaN();
        ordered = ordered && !(c < used && key[c] != key[c]);
      }
      uint32_t order[W], opposite[W];
      for (uint32_t c = used; c < W; ++c) order[c] = opposite[c] = c;
      if (ordered) {
        // Across all children at once (the inner loop vectorizes), one other child at a time.
        int32_t less[W] = {}, greater[W] = {}, tied_before[W] = {};
        for (uint32_t j = 0; j < W; ++j)
          for (uint32_t i = 0; i < W; ++i) {
            less[i] += key[j] < key[i] ? 1 : 0;
            greater[i] += key[j] > key[i] ? 1 : 0;
            tied_before[i] += (j < i && key[j] == key[i]) ? 1 : 0;
          }
        for (uint32_t i = 0; i < used; ++i) {
          order[less[i] + tied_before[i]] = i;
          opposite[greater[i] + tied_before[i]] = i;
        }
      } else {
        sort_with_nan(key, used, order, opposite);
      }
      for (uint32_t k = 0; k < W; ++k) Access::set_order(node, o, k, order[k]);
      for (uint32_t k = 0; k < W; ++k) Access::set_order(node, o ^ 7, k, opposite[k]);
    }
  }

  // The orders of fill_node for keys that include a NaN (a scene of infinite extent): what
  // the stable insertion sort leaves, the opposite one reversed with runs of equal keys put
  // back in slot order.
  static void sort_with_nan(const float* key, uint32_t used, uint32_t* order, uint32_t* opposite) {
    for (uint32_t c = 0; c < used; ++c) order[c] = c;
    for (uint32_t i = 1; i < used; ++i)
      for (uint32_t j = i; j > 0 && key[order[j]] < key[order[j - 1]]; --j) std::swap(order[j], order[j - 1]);
    for (uint32_t k = 0; k < used; ++k) opposite[k] = order[used - 1 - k];
    for (uint32_t run = 0; run < used;) {
      uint32_t stop = run + 1;
      while (stop < used && key[opposite[stop]] == key[opposite[run]]) ++stop;
      std::reverse(opposite + run, opposite + stop);
      run = stop;
    }
  }

  const CollapsedBvh& wide_;
  const FlatBvh& bvh_;
  const Mesh& mesh_;
  TriangleTest test_;
  detail::BoxPadding pad_;
  std::vector<size_t> offset_;        // per wide node, bytes from the arena's start
  std::vector<uint32_t> stack_need_;  // per wide node, the deepest stack its subtree needs
  size_t bytes_ = 0, blocks_ = 0;
};

}  // namespace

void WideBvh::FreeArena::operator()(std::byte* p) const { std::free(p); }

WideBvh::WideBvh(const FlatBvh& bvh, const Mesh& mesh, const WideLayoutOptions& options)
    : width_(options.collapse.width), test_(options.test), mesh_triangles_(mesh.triangle_count()) {
  for (uint32_t id : bvh.triangle_ids)
    if (id >= mesh_triangles_)
      throw Error("wide layout: triangle id " + std::to_string(id) + " out of range (mesh " + mesh.name + " has " +
                  std::to_string(mesh_triangles_) + " triangles)");
  auto t0 = std::chrono::steady_clock::now();
  const CollapsedBvh wide = collapse_to_wide(bvh, options.collapse);
  stats_.collapse_seconds = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  auto run = [&](auto&& builder) {
    arena_ = builder.write();
    root_ = 0;  // the root is the first node
    stack_entries_ = builder.stack_need();
    stats_.nodes = wide.node_count();
    stats_.blocks = builder.blocks();
    stats_.bytes = builder.bytes();
  };
  if (width_ == 8)
    run(LayoutBuilder<8>(wide, bvh, mesh, test_));
  else
    run(LayoutBuilder<4>(wide, bvh, mesh, test_));
  stack_entries_ += 1 + width_;
  stats_.leaves = wide.leaf_count();
  stats_.triangle_slots = 4 * stats_.blocks;
  stats_.sah_cost = wide.sah_cost;
  stats_.layout_seconds = seconds_since(t0);
}

}  // namespace bvhopt
