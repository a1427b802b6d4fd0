// Collapsing a binary tree into a 4- or 8-wide one: the SAH-optimal dynamic program of
// Ylitie, Karras and Laine (2017) and Embree-style greedy widening.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr uint32_t kNoSet = 0xffffffffu;

uint32_t left_of(uint32_t n) { return n + 1; }
uint32_t right_of(const FlatBvh& bvh, uint32_t n) { return bvh.nodes[n].index; }

uint32_t blocks_for(uint32_t triangles) { return (triangles + 3) / 4; }

// The distinct triangles under flat node n, ascending (every leaf entry of its subtree,
// duplicates from edge volume subdivision merged).
// `todo` is scratch space, kept by the caller across calls.
void distinct_triangles(const FlatBvh& bvh, uint32_t n, std::vector<uint32_t>& out, std::vector<uint32_t>& todo) {
  out.clear();
  todo.assign(1, n);
  while (!todo.empty()) {
    const FlatNode& f = bvh.nodes[todo.back()];
    const uint32_t i = todo.back();
    todo.pop_back();
    if (f.is_leaf()) {
      out.insert(out.end(), bvh.triangle_ids.begin() + f.index, bvh.triangle_ids.begin() + f.index + f.count);
    } else {
      todo.push_back(right_of(bvh, i));
      todo.push_back(left_of(i));
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

// Per flat node, the number of distinct triangles under it when at most `limit` (binary
// leaves: always, up to kSaturated - 1), else kSaturated. Computed bottom-up by merging the
// children's sorted sets; only the sets of the path being walked are kept (a stack: in
// reverse depth-first order a node's two children are the top two entries), so the memory
// is the tree's depth times the limit, not a set per node.
constexpr uint8_t kSaturated = 0xff;

// True when no triangle id appears twice among the leaves' entries (no edge volume or
// split references): then a subtree's distinct triangles are its entries.
bool entries_are_distinct(const FlatBvh& bvh) {
  uint32_t triangles = 0;
  for (uint32_t t : bvh.triangle_ids) triangles = std::max(triangles, t + 1);
  // Bytes, not bits: a bit's read-modify-write made this loop twice as long.
  std::vector<uint8_t> seen(triangles, 0);
  uint8_t repeated = 0;
  for (uint32_t t : bvh.triangle_ids) {
    repeated |= seen[t];
    seen[t] = 1;
  }
  return repeated == 0;
}

std::vector<uint8_t> distinct_counts(const FlatBvh& bvh, uint32_t limit) {
  std::vector<uint8_t> count(bvh.nodes.size(), kSaturated);
  struct Entry {
    size_t begin;  // in pool
    uint32_t size;
    bool known;
  };
  std::vector<Entry> stack;
  std::vector<uint32_t> pool, merged;
  for (size_t i = bvh.nodes.size(); i-- > 0;) {
    const FlatNode& f = bvh.nodes[i];
    merged.clear();
    bool known = true;
    size_t base = pool.size();
    if (f.is_leaf()) {
      merged.assign(bvh.triangle_ids.begin() + f.index, bvh.triangle_ids.begin() + f.index + f.count);
      std::sort(merged.begin(), merged.end());
      merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
    } else {
      const Entry l = stack.back();
      stack.pop_back();
      const Entry r = stack.back();
      stack.pop_back();
      base = r.begin;  // the right child's set lies below the left's
      known = l.known && r.known && l.size <= limit && r.size <= limit;
      if (known)
        std::set_union(pool.begin() + l.begin, pool.begin() + l.begin + l.size, pool.begin() + r.begin,
                       pool.begin() + r.begin + r.size, std::back_inserter(merged));
      known = known && merged.size() <= limit;
    }
    pool.resize(base);
    if (known) {
      pool.insert(pool.end(), merged.begin(), merged.end());
      count[i] = uint8_t(std::min<size_t>(merged.size(), kSaturated));
    }
    stack.push_back({base, known ? uint32_t(merged.size()) : 0, known});
  }
  return count;
}

// The wide SAH cost from its sums of node areas and of leaf areas times blocks.
double normalized_wide_cost(double nodes, double blocks, const FlatBvh& bvh, const WideCostModel& cost) {
  const double root = double(bvh.nodes[0].box.area());
  const double total = cost.node * nodes + cost.block * blocks;
  return root > 0.0 ? total / root : total;
}

// Builds the output structure from a function giving each wide node's children. Wide nodes
// are numbered depth-first. The walk is cut into segments in depth-first order: wide nodes
// near the root are segments of one node each, walked here, and every subtree below them
// of fewer than a sixth of the flat nodes is a segment walked whole, numbered from 0; the
// segments are then put one after the other: the same numbering as one walk. (Cut only
// below the root, the largest segment held 61 % of Conference's wide nodes, and the walk
// took as long on 2 threads as on one; cut into 64ths, the collapse took longer than with a
// sixth on every scene measured, each segment costing its own vectors and task.) One
// parallel loop over the segments walks each, fills its leaves' triangles and sums its part
// of the cost: each phase of its own was under a millisecond and paid for starting its
// threads. Each leaf is sized from `distinct(flat)` (its distinct triangles, when known).
// On 2 threads these changes took the collapse from 6.7 to 5.5 ms on Conference, 2.3 to
// 2.2 ms on 2CylinderEngine.
class CollapseWriter {
 public:
  CollapseWriter(const FlatBvh& bvh, uint32_t width, bool entries_distinct)
      : bvh_(bvh), entries_distinct_(entries_distinct) {
    out_.width = width;
  }

  // `children_of(flat, out)` appends the flat nodes that become the wide node's children;
  // `is_leaf(flat)` says which of them are leaves; `distinct(flat)` is the number of distinct
  // triangles under a leaf, or kSaturated when not known. Depth-first, children in the order
  // given.
  template <class ChildrenOf, class IsLeaf, class Distinct>
  CollapsedBvh write(ChildrenOf&& children_of, IsLeaf&& is_leaf, Distinct&& distinct, const WideCostModel& cost) {
    std::vector<Piece> segments;
    std::vector<Link> links;
    std::vector<uint8_t> walked;  // per segment: walked here (one node) or not yet (a subtree)
    const uint32_t flat_nodes = uint32_t(bvh_.nodes.size());
    const uint32_t cut_below = std::max(kMinSegmentNodes, flat_nodes / 6);
    struct Todo {
      uint32_t flat;
      uint32_t segment, slot;  // the parent's slot to point at this segment (kNoSet: the root)
    };
    std::vector<Todo> todo{{0, kNoSet, kNoSet}};
    std::vector<Pending> inner;
    while (!todo.empty()) {
      const Todo at = todo.back();
      todo.pop_back();
      const uint32_t s = uint32_t(segments.size());
      segments.emplace_back();
      segments[s].root = at.flat;
      if (at.segment != kNoSet) links.push_back({at.segment, at.slot, s});
      walked.push_back(!bvh_.nodes[at.flat].is_leaf() && subtree_end(at.flat) - at.flat >= cut_below);
      if (!walked[s]) continue;
      inner.clear();
      walk(at.flat, segments[s], &inner, children_of, is_leaf, distinct);
      for (size_t k = inner.size(); k-- > 0;) todo.push_back({inner[k].flat, s, inner[k].slot});
    }
    tbb::parallel_for(size_t(0), segments.size(), [&](size_t k) {
      // Each into a piece of the task's own, moved into place at the end: the segments lie
      // next to one another, and every push_back writes its vector's end, so walking them in
      // place has the threads write the same cache lines.
      Piece p = std::move(segments[k]);
      if (!walked[k]) walk(p.root, p, nullptr, children_of, is_leaf, distinct);
      fill_leaves(p);
      segments[k] = std::move(p);
    });
    join(segments, links);
    // The cost's two sums, the segments' parts in order: the same double on any number of
    // threads.
    double node_area = 0.0, block_area = 0.0;
    for (const Piece& p : segments) {
      node_area += p.node_area;
      block_area += p.block_area;
    }
    out_.sah_cost = normalized_wide_cost(node_area, block_area, bvh_, cost);
    return std::move(out_);
  }

 private:
  // Below this many flat nodes a subtree is never cut: its walk would not outweigh its task
  // and its vectors.
  static constexpr uint32_t kMinSegmentNodes = 1024;

  struct Pending {
    uint32_t flat;
    uint32_t slot;  // index in child_index to patch with the wide node, kNoSet for the root
  };
  // Segment `target`'s root is the inner child in slot `slot` of segment `segment`.
  struct Link {
    uint32_t segment, slot, target;
  };
  // A subtree's wide nodes, numbered from 0 (its root), children and leaves (their flat
  // nodes and sizes).
  struct Piece {
    uint32_t root = 0;  // its flat root
    std::vector<uint32_t> nodes, child_begin{0}, children, child_index, leaf_begin{0}, leaf_flat, leaf_triangles;
    std::vector<uint8_t> child_is_leaf;
    double node_area = 0.0, block_area = 0.0;  // its part of the cost's two sums
  };

  // One past the last flat node of n's subtree (flat nodes are numbered depth-first, so it is
  // one past its rightmost leaf).
  uint32_t subtree_end(uint32_t n) const {
    while (!bvh_.nodes[n].is_leaf()) n = right_of(bvh_, n);
    return n + 1;
  }

  // Depth-first from flat node `root` into `p`. With `stop`, only the root: its inner children
  // are left to `stop` instead of walked.
  template <class ChildrenOf, class IsLeaf, class Distinct>
  void walk(uint32_t root, Piece& p, std::vector<Pending>* stop, ChildrenOf& children_of, IsLeaf& is_leaf,
            Distinct& distinct) const {
    std::vector<Pending> todo{{root, kNoSet}};
    std::vector<uint32_t> kids, set, scratch;
    while (!todo.empty()) {
      const Pending at = todo.back();
      todo.pop_back();
      const uint32_t w = uint32_t(p.nodes.size());
      if (at.slot != kNoSet) p.child_index[at.slot] = w;
      p.nodes.push_back(at.flat);
      kids.clear();
      if (bvh_.nodes[at.flat].is_leaf())
        kids.push_back(at.flat);  // a tree that is one leaf
      else
        children_of(at.flat, kids);
      const size_t first_slot = p.children.size();
      for (uint32_t c : kids) {
        const bool leaf = bvh_.nodes[c].is_leaf() || is_leaf(c);
        p.children.push_back(c);
        p.child_is_leaf.push_back(leaf ? 1 : 0);
        p.child_index.push_back(leaf ? add_leaf(p, c, distinct(c), set, scratch) : kNoSet);
      }
      p.child_begin.push_back(uint32_t(p.children.size()));
      if (stop) {
        for (size_t s = first_slot; s < p.children.size(); ++s)
          if (!p.child_is_leaf[s]) stop->push_back({p.children[s], uint32_t(s)});
        return;
      }
      // Reverse, so the first inner child is numbered next (depth-first).
      for (size_t s = p.children.size(); s-- > first_slot;)
        if (!p.child_is_leaf[s]) todo.push_back({p.children[s], uint32_t(s)});
    }
  }

  // The segments one after the other, their numbers offset by what comes before; then each
  // link's slot points at its segment's first node.
  void join(const std::vector<Piece>& segments, const std::vector<Link>& links) {
    const size_t n = segments.size();
    std::vector<size_t> node_at(n + 1), slot_at(n + 1), leaf_at(n + 1);
    std::vector<uint32_t> triangle_at(n + 1);
    for (size_t k = 0; k < n; ++k) {
      node_at[k + 1] = node_at[k] + segments[k].nodes.size();
      slot_at[k + 1] = slot_at[k] + segments[k].children.size();
      leaf_at[k + 1] = leaf_at[k] + segments[k].leaf_flat.size();
      triangle_at[k + 1] = triangle_at[k] + segments[k].leaf_begin.back();
    }
    out_.nodes.resize(node_at[n]);
    out_.child_begin.resize(node_at[n] + 1);
    out_.children.resize(slot_at[n]);
    out_.child_is_leaf.resize(slot_at[n]);
    out_.child_index.resize(slot_at[n]);
    out_.leaf_begin.resize(leaf_at[n] + 1);
    out_.leaf_triangles.resize(triangle_at[n]);
    auto place = [&](const Piece& p, size_t node, size_t slot, size_t leaf, uint32_t triangle) {
      std::copy(p.nodes.begin(), p.nodes.end(), out_.nodes.begin() + node);
      for (size_t i = 1; i < p.child_begin.size(); ++i) out_.child_begin[node + i] = uint32_t(slot + p.child_begin[i]);
      std::copy(p.children.begin(), p.children.end(), out_.children.begin() + slot);
      std::copy(p.child_is_leaf.begin(), p.child_is_leaf.end(), out_.child_is_leaf.begin() + slot);
      for (size_t i = 0; i < p.child_index.size(); ++i)
        out_.child_index[slot + i] = p.child_is_leaf[i] ? uint32_t(leaf + p.child_index[i])
                                     : p.child_index[i] == kNoSet ? kNoSet
                                                                  : uint32_t(node + p.child_index[i]);
      for (size_t i = 1; i < p.leaf_begin.size(); ++i) out_.leaf_begin[leaf + i] = triangle + p.leaf_begin[i];
      std::copy(p.leaf_triangles.begin(), p.leaf_triangles.end(), out_.leaf_triangles.begin() + triangle);
    };
    out_.child_begin[0] = 0;
    out_.leaf_begin[0] = 0;
    tbb::parallel_for(size_t(0), n, [&](size_t k) {
      place(segments[k], node_at[k], slot_at[k], leaf_at[k], triangle_at[k]);
    });
    for (const Link& l : links) out_.child_index[slot_at[l.segment] + l.slot] = uint32_t(node_at[l.target]);
  }

  // Sizes the leaf.
  uint32_t add_leaf(Piece& p, uint32_t flat, uint32_t known, std::vector<uint32_t>& set,
                    std::vector<uint32_t>& scratch) const {
    uint32_t n = known;
    if (n == kSaturated) {
      // Not known (a binary leaf of more entries than the counts keep): counted here. Such a
      // leaf is over the limit below unless its entries repeat.
      if (entries_distinct_) {
        n = bvh_.nodes[flat].count;
      } else {
        distinct_triangles(bvh_, flat, set, scratch);
        n = uint32_t(set.size());
      }
    }
    if (n > kWideMaxLeafTriangles)
      throw Error("collapse: a leaf of " + std::to_string(n) + " distinct triangles; wide leaves hold at most " +
                  std::to_string(kWideMaxLeafTriangles) +
                  " (build with a smaller leaf size, collapse with a leaf limit of at most that: compact or bake "
                  "--max-leaf-size, or trace the binary layout)");
    p.leaf_begin.push_back(p.leaf_begin.back() + n);
    p.leaf_flat.push_back(flat);
    return uint32_t(p.leaf_begin.size() - 2);
  }

  // The piece's leaves' distinct triangles, ascending, into its leaf_triangles; and its part
  // of the cost's sums, in its order.
  void fill_leaves(Piece& p) const {
    p.leaf_triangles.resize(p.leaf_begin.back());
    std::vector<uint32_t> set, scratch;
    for (size_t l = 0; l + 1 < p.leaf_begin.size(); ++l) {
      const uint32_t flat = p.leaf_flat[l];
      uint32_t* out = p.leaf_triangles.data() + p.leaf_begin[l];
      const uint32_t n = p.leaf_begin[l + 1] - p.leaf_begin[l];
      if (entries_distinct_) {
        append_entries(flat, out, scratch);
        std::sort(out, out + n);
      } else {
        distinct_triangles(bvh_, flat, set, scratch);
        std::copy(set.begin(), set.end(), out);
      }
      p.block_area += double(bvh_.nodes[flat].box.area()) * double(blocks_for(n));
    }
    for (uint32_t flat : p.nodes) p.node_area += double(bvh_.nodes[flat].box.area());
  }

  // Every leaf entry under flat node n, written from `out` on, when no triangle repeats
  // (then they are its distinct triangles, and only need sorting).
  void append_entries(uint32_t n, uint32_t* out, std::vector<uint32_t>& todo) const {
    if (bvh_.nodes[n].is_leaf()) {  // most wide leaves are one binary leaf
      const FlatNode& f = bvh_.nodes[n];
      std::copy(bvh_.triangle_ids.begin() + f.index, bvh_.triangle_ids.begin() + f.index + f.count, out);
      return;
    }
    todo.assign(1, n);
    while (!todo.empty()) {
      const uint32_t i = todo.back();
      todo.pop_back();
      const FlatNode& f = bvh_.nodes[i];
      if (f.is_leaf()) {
        out = std::copy(bvh_.triangle_ids.begin() + f.index, bvh_.triangle_ids.begin() + f.index + f.count, out);
      } else {
        todo.push_back(right_of(bvh_, i));
        todo.push_back(left_of(i));
      }
    }
  }

  const FlatBvh& bvh_;
  const bool entries_distinct_;
  CollapsedBvh out_;
};

// The dynamic program. C(n, i), the least cost of the subtree of n as at most i subtrees
// (each a leaf or a wide node); C(n, 1) = min(C_leaf, C_internal). Only the choices are
// kept per node (a byte per i); the cost rows live on a stack, since each is read once, by
// the parent, and in reverse depth-first order a node's children are the top two rows. Large
// subtrees solve their halves in parallel (the collapse was serial, a third of collapse +
// layout on 2 threads).
// Floats: the argmins are what matters, and the final cost is re-evaluated in double.
class OptimalCollapse {
 public:
  OptimalCollapse(const FlatBvh& bvh, const CollapseOptions& o, bool entries_distinct)
      : bvh_(bvh), options_(o), width_(o.width),
        choice_(std::make_unique_for_overwrite<uint8_t[]>(bvh.nodes.size() * o.width)),
        internal_split_(std::make_unique_for_overwrite<uint8_t[]>(bvh.nodes.size())),
        leaf_(std::make_unique_for_overwrite<uint8_t[]>(bvh.nodes.size())),
        entries_distinct_(entries_distinct) {
    // With no triangle repeated the counts are sums, made by the DP's own bottom-up walk
    // (serially before it, they were a seventh of collapse + layout on 2 threads, Conference);
    // else by merging sorted sets beforehand.
    if (entries_distinct) {
      distinct_ = std::make_unique_for_overwrite<uint8_t[]>(bvh.nodes.size());
      size_ = std::make_unique_for_overwrite<uint32_t[]>(bvh.nodes.size());
    } else {
      const std::vector<uint8_t> counts = distinct_counts(bvh, o.max_leaf_triangles);
      distinct_ = std::make_unique_for_overwrite<uint8_t[]>(bvh.nodes.size());
      std::copy(counts.begin(), counts.end(), distinct_.get());
    }
    const uint32_t n = uint32_t(bvh.nodes.size());
    // Areas relative to the root's: the float rows then hold the same numbers at every
    // scale of the scene (absolute areas overflow a float above extents of about 1e19).
    const double root_area = n ? bvh.nodes[0].box.area() : 0.0;
    per_area_ = root_area > 0.0 ? 1.0 / root_area : 1.0;
    float row[kMaxWidth];
    if (n && width_ == 8) solve<8>(0, n, row);
    if (n && width_ == 4) solve<4>(0, n, row);
  }

  // The wide children of flat inner node n: the subtrees of its two children's best
  // distribution of all `width` slots.
  void children_of(uint32_t n, std::vector<uint32_t>& out) const {
    const uint32_t k = internal_split_[n];
    gather(left_of(n), k, out);
    gather(right_of(bvh_, n), width_ - k, out);
  }
  bool is_leaf(uint32_t n) const { return leaf_[n] != 0; }
  // The distinct triangles under flat node n, kSaturated above the leaf limit.
  uint32_t distinct(uint32_t n) const { return distinct_[n]; }

 private:
  static constexpr uint32_t kMaxWidth = 8;

  void gather(uint32_t n, uint32_t slots, std::vector<uint32_t>& out) const {
    while (slots > 1 && choice_[size_t(n) * width_ + slots - 1] == 0) --slots;
    if (slots == 1) {
      out.push_back(n);
      return;
    }
    const uint32_t k = choice_[size_t(n) * width_ + slots - 1];
    gather(left_of(n), k, out);
    gather(right_of(bvh_, n), slots - k, out);
  }

  // Subtrees of at least this many flat nodes solve their two children in parallel tasks.
  // A node depends only on its children's rows, so the choices are the same on any number
  // of threads.
  static constexpr uint32_t kParallelNodes = 4096;

  // The subtree of flat node `top`, nodes [top, end) (depth-first numbering), its cost row
  // written to `row`. Below kParallelNodes, one scan in reverse depth-first order with the
  // rows on a stack: a node's two children are then the top two rows. W is the width as a
  // constant, so that the rows' loops unroll and the rows are moved without calls.
  template <uint32_t W>
  void solve(uint32_t top, uint32_t end, float* row) {
    const FlatNode& f = bvh_.nodes[top];
    if (end - top >= kParallelNodes && !f.is_leaf()) {
      float cl[W], cr[W];
      const uint32_t right = f.index;
      tbb::parallel_invoke([&] { solve<W>(top + 1, right, cl); }, [&] { solve<W>(right, end, cr); });
      solve_node<W>(top, cl, cr, row);
      return;
    }
    std::vector<float> rows(64 * W);  // the stack, W floats per entry
    size_t depth = 0;                         // entries on the stack
    for (uint32_t i = end; i-- > top;) {
      float c[W];
      if (bvh_.nodes[i].is_leaf()) {
        solve_node<W>(i, nullptr, nullptr, c);
        if ((depth + 1) * W > rows.size()) rows.resize(2 * rows.size());
      } else {
        depth -= 2;
        solve_node<W>(i, &rows[(depth + 1) * W], &rows[depth * W], c);
      }
      for (uint32_t j = 0; j < W; ++j) rows[depth * W + j] = c[j];
      ++depth;
    }
    for (uint32_t j = 0; j < W; ++j) row[j] = rows[j];
  }

  // Node i's row `c` and choices from its children's rows (unread for a leaf).
  template <uint32_t W>
  void solve_node(uint32_t i, const float* cl, const float* cr, float* c) {
    const FlatNode& f = bvh_.nodes[i];
    if (entries_distinct_) count_entries(i, f);
    const float area = float(f.box.area() * per_area_);
    uint8_t* ch = &choice_[size_t(i) * W];
    float leaf_cost = kInf;
    if (distinct_[i] != kSaturated && (f.is_leaf() || distinct_[i] <= options_.max_leaf_triangles))
      leaf_cost = float(options_.cost.block) * area * float(blocks_for(distinct_[i]));
    if (f.is_leaf()) {
      for (uint32_t j = 0; j < W; ++j) c[j] = leaf_cost;
      for (uint32_t j = 0; j < W; ++j) ch[j] = 0;
      leaf_[i] = 1;
      return;
    }
    // distribute(j): the best split of j slots over the two children, k to the left (the
    // first of equal sums). A row never grows with more slots, and a float sum never
    // shrinks as one term grows, so when the left child is a leaf (its row one value) the
    // first split, k = 1, is the best: the loop is skipped for a large share of the nodes
    // (not when that sum is NaN, which the loop never takes).
    const bool left_is_leaf = bvh_.nodes[i + 1].is_leaf();
    auto distribute = [&](uint32_t j, uint8_t& best_k) {
      if (left_is_leaf) {
        const float first = cl[0] + cr[j - 2];
        if (first == first) {
          best_k = 1;
          return first;
        }
      }
      float best = kInf;
      best_k = 1;
      for (uint32_t k = 1; k < j; ++k) {
        const float s = cl[k - 1] + cr[j - k - 1];
        if (s < best) {
          best = s;
          best_k = uint8_t(k);
        }
      }
      return best;
    };
    const float internal = float(options_.cost.node) * area + distribute(W, internal_split_[i]);
    leaf_[i] = leaf_cost <= internal ? 1 : 0;
    c[0] = std::min(leaf_cost, internal);
    ch[0] = 0;
    for (uint32_t j = 2; j <= W; ++j) {
      uint8_t k = 0;
      const float d = distribute(j, k);
      // choice 0: as at most j-1 subtrees; k: k slots to the left, j-k to the right.
      if (d < c[j - 2]) {
        c[j - 1] = d;
        ch[j - 1] = k;
      } else {
        c[j - 1] = c[j - 2];
        ch[j - 1] = 0;
      }
    }
  }

  // distinct_[i] from its children's, as entries (none repeats); the children come first.
  void count_entries(uint32_t i, const FlatNode& f) {
    if (f.is_leaf()) {
      size_[i] = f.count;
      distinct_[i] = uint8_t(std::min<uint32_t>(f.count, kSaturated));
      return;
    }
    const uint32_t l = i + 1, r = f.index, limit = options_.max_leaf_triangles;
    const bool known = distinct_[l] != kSaturated && distinct_[r] != kSaturated && size_[l] <= limit &&
                       size_[r] <= limit && size_[l] + size_[r] <= limit;
    size_[i] = known ? size_[l] + size_[r] : 0;
    distinct_[i] = known ? uint8_t(size_[i]) : kSaturated;
  }

  const FlatBvh& bvh_;
  const CollapseOptions options_;
  uint32_t width_;
  // Every entry is written before it is read (so not cleared first).
  std::unique_ptr<uint8_t[]> choice_;
  std::unique_ptr<uint8_t[]> internal_split_;
  std::unique_ptr<uint8_t[]> leaf_;
  const bool entries_distinct_;
  // Per flat node, the distinct triangles under it when at most the leaf limit, else
  // kSaturated; size_ (when entries are distinct) the entries while they are counted.
  std::unique_ptr<uint8_t[]> distinct_;
  std::unique_ptr<uint32_t[]> size_;
  double per_area_ = 1.0;
};

// Greedy widening: open the inner child of largest area until the slots are full.
void greedy_children(const FlatBvh& bvh, uint32_t n, uint32_t width, std::vector<uint32_t>& out) {
  out.push_back(left_of(n));
  out.push_back(right_of(bvh, n));
  while (out.size() < width) {
    int best = -1;
    double best_area = -1.0;
    for (size_t s = 0; s < out.size(); ++s) {
      const FlatNode& f = bvh.nodes[out[s]];
      if (!f.is_leaf() && f.box.area() > best_area) {
        best_area = f.box.area();
        best = int(s);
      }
    }
    if (best < 0) break;
    const uint32_t c = out[size_t(best)];
    out[size_t(best)] = left_of(c);
    out.insert(out.begin() + best + 1, right_of(bvh, c));
  }
}

}  // namespace

CollapsedBvh collapse_to_wide(const FlatBvh& bvh, const CollapseOptions& options) {
  if (options.width != 4 && options.width != 8)
    throw Error("collapse: width " + std::to_string(options.width) + " (4 or 8)");
  if (bvh.nodes.empty()) throw Error("collapse: the tree has no nodes");
  const uint32_t limit = std::min(options.max_leaf_triangles, kWideMaxLeafTriangles);
  const bool entries_distinct = entries_are_distinct(bvh);
  CollapseWriter writer(bvh, options.width, entries_distinct);
  if (options.method == CollapseMethod::greedy)
    return writer.write([&](uint32_t n, std::vector<uint32_t>& kids) { greedy_children(bvh, n, options.width, kids); },
                        [](uint32_t) { return false; }, [](uint32_t) { return uint32_t(kSaturated); }, options.cost);
  CollapseOptions o = options;
  o.max_leaf_triangles = limit;
  const OptimalCollapse dp(bvh, o, entries_distinct);
  return writer.write([&](uint32_t n, std::vector<uint32_t>& kids) { dp.children_of(n, kids); },
                      [&](uint32_t n) { return dp.is_leaf(n); }, [&](uint32_t n) { return dp.distinct(n); },
                      options.cost);
}

double wide_sah_cost(const CollapsedBvh& wide, const FlatBvh& bvh, const WideCostModel& cost) {
  double nodes = 0.0, blocks = 0.0;
  for (uint32_t n : wide.nodes) nodes += double(bvh.nodes[n].box.area());
  for (size_t s = 0; s < wide.children.size(); ++s) {
    if (!wide.child_is_leaf[s]) continue;
    const uint32_t l = wide.child_index[s];
    blocks += double(bvh.nodes[wide.children[s]].box.area()) *
              double(blocks_for(wide.leaf_begin[l + 1] - wide.leaf_begin[l]));
  }
  return normalized_wide_cost(nodes, blocks, bvh, cost);
}

}  // namespace bvhopt
