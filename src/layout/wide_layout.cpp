// The wide layout: collapsed nodes written depth-first into one aligned arena, each node
// followed by its leaf blocks, so a node and the triangles it points to share pages.
#include <sys/mman.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <cmath>
#include <limits>
#include <string>

#include "bvhopt/error.h"
#include "bvhopt/wide_bvh.h"
#include "layout/box_padding.h"

namespace bvhopt {

std::string_view triangle_test_name(TriangleTest test) {
  return test == TriangleTest::watertight ? "watertight" : "moller-trumbore";
}

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The arena as it is written: 32-byte units, nodes on 64-byte boundaries, in one block of
// the size the collapse implies (an upper bound, computed before writing). Arenas of 2 MiB
// or more are 2 MiB aligned and asked to be backed by huge pages: incoherent rays touch
// nodes all over the arena, and with 4 KiB pages most node visits would also miss the TLB
// (Embree allocates its BVH the same way).
class ArenaWriter {
 public:
  explicit ArenaWriter(size_t capacity) : capacity_((capacity + 63) / 64 * 64) {
    constexpr size_t kHuge = size_t(2) << 20;
    void* p = nullptr;
    if (posix_memalign(&p, capacity_ >= kHuge ? kHuge : 64, std::max<size_t>(capacity_, 64)) != 0)
      throw Error("wide layout: out of memory for " + std::to_string(capacity_) + " bytes");
#ifdef MADV_HUGEPAGE
    if (capacity_ >= kHuge) madvise(p, capacity_, MADV_HUGEPAGE);
#endif
    std::memset(p, 0, capacity_);
    data_.reset(static_cast<std::byte*>(p));
  }
  uint32_t reserve(size_t bytes, size_t align) {
    const size_t at = (used_ + align - 1) / align * align;
    if ((at + bytes) / kWideUnit > kWideOffsetMask) throw Error("wide layout: the tree needs more than 4 GiB");
    if (at + bytes > capacity_) throw Error("wide layout: internal error, arena estimate too small");
    used_ = at + bytes;
    return uint32_t(at / kWideUnit);
  }
  template <class T>
  T* at(uint32_t unit) {
    return reinterpret_cast<T*>(data_.get() + size_t(unit) * kWideUnit);
  }
  size_t size() const { return (used_ + 63) / 64 * 64; }
  std::unique_ptr<std::byte[], WideBvh::FreeArena>& storage() { return data_; }

 private:
  size_t capacity_;
  size_t used_ = 0;
  std::unique_ptr<std::byte[], WideBvh::FreeArena> data_;
};

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

template <uint32_t W>
class LayoutBuilder {
  using Access = NodeAccess<W>;
  using Node = typename Access::Node;

 public:
  LayoutBuilder(const CollapsedBvh& wide, const FlatBvh& bvh, const Mesh& mesh, TriangleTest test)
      : wide_(wide), bvh_(bvh), mesh_(mesh), test_(test), pad_(bvh), arena_(arena_bound(wide)) {}

  // Every node, and every leaf's blocks with a 64-byte alignment gap.
  static size_t arena_bound(const CollapsedBvh& wide) {
    size_t bytes = wide.node_count() * sizeof(Node);
    for (size_t l = 0; l < wide.leaf_count(); ++l)
      bytes += (wide.leaf_begin[l + 1] - wide.leaf_begin[l] + 3) / 4 * sizeof(TriangleBlock) + 64;
    return bytes;
  }

  // Writes the subtree of wide node w; returns its offset and the deepest stack it needs.
  uint32_t write(uint32_t w, uint32_t& stack_need) {
    const uint32_t self = arena_.reserve(sizeof(Node), 64);
    const uint32_t begin = wide_.child_begin[w], end = wide_.child_begin[w + 1];
    uint32_t words[W];
    std::fill(words, words + W, kWideEmptyChild);
    for (uint32_t s = begin; s < end; ++s)
      if (wide_.child_is_leaf[s]) words[s - begin] = write_leaf(wide_.child_index[s]);
    uint32_t deepest = 0;
    for (uint32_t s = begin; s < end; ++s) {
      if (wide_.child_is_leaf[s]) continue;
      uint32_t need = 0;
      words[s - begin] = write(wide_.child_index[s], need);
      deepest = std::max(deepest, need);
    }
    // Arena may have moved: take the node's address only now.
    fill_node(*arena_.template at<Node>(self), begin, end, words);
    stack_need = deepest + (end - begin) - 1;
    ++nodes_;
    return self;
  }

  ArenaWriter& arena() { return arena_; }
  size_t nodes() const { return nodes_; }
  size_t blocks() const { return blocks_; }

 private:
  uint32_t write_leaf(uint32_t leaf) {
    const uint32_t first = wide_.leaf_begin[leaf], count = wide_.leaf_begin[leaf + 1] - first;
    const uint32_t blocks = (count + 3) / 4;
    if (blocks == 0 || blocks > kWideMaxBlocks) throw Error("wide layout: a leaf of " + std::to_string(count) + " triangles");
    ArenaWriter& target = arena_;
    const uint32_t unit = target.reserve(blocks * sizeof(TriangleBlock), sizeof(TriangleBlock) % 64 == 0 ? 64 : 32);
    for (uint32_t b = 0; b < blocks; ++b) {
      TriangleBlock& block = target.template at<TriangleBlock>(unit)[b];
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
    blocks_ += blocks;
    return kWideLeafFlag | ((blocks - 1) << 27) | unit;
  }

  void fill_node(Node& node, uint32_t begin, uint32_t end, const uint32_t* words) {
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
    const uint32_t used = end - begin;
    for (int o = 0; o < 8; ++o) {
      const Vec3 s((o & 1) ? -1.0f : 1.0f, (o & 2) ? -1.0f : 1.0f, (o & 4) ? -1.0f : 1.0f);
      uint32_t order[W];
      for (uint32_t c = 0; c < W; ++c) order[c] = c;
      float key[W];
      for (uint32_t c = 0; c < used; ++c) key[c] = dot(centre[c], s);
      for (uint32_t i = 1; i < used; ++i)  // insertion sort: at most 8, stable
        for (uint32_t j = i; j > 0 && key[order[j]] < key[order[j - 1]]; --j) std::swap(order[j], order[j - 1]);
      for (uint32_t k = 0; k < W; ++k) Access::set_order(node, o, k, order[k]);
    }
  }

  const CollapsedBvh& wide_;
  const FlatBvh& bvh_;
  const Mesh& mesh_;
  TriangleTest test_;
  detail::BoxPadding pad_;
  ArenaWriter arena_;
  size_t nodes_ = 0, blocks_ = 0;
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
  auto run = [&](auto& builder) {
    root_ = builder.write(0, stack_entries_);
    stats_.nodes = builder.nodes();
    stats_.blocks = builder.blocks();
    stats_.bytes = builder.arena().size();
    arena_ = std::move(builder.arena().storage());
  };
  if (width_ == 8) {
    LayoutBuilder<8> builder(wide, bvh, mesh, test_);
    run(builder);
  } else {
    LayoutBuilder<4> builder(wide, bvh, mesh, test_);
    run(builder);
  }
  stack_entries_ += 1 + width_;
  stats_.leaves = wide.leaf_count();
  stats_.triangle_slots = 4 * stats_.blocks;
  stats_.sah_cost = wide.sah_cost;
  stats_.layout_seconds = seconds_since(t0);
}

}  // namespace bvhopt
