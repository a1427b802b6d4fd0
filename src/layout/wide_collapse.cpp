// Collapsing a binary tree into a 4- or 8-wide one: the SAH-optimal dynamic program of
// Ylitie, Karras and Laine (2017) and Embree-style greedy widening.
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/wide_bvh.h"

namespace bvhopt {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr uint32_t kNoSet = 0xffffffffu;
constexpr uint32_t kMaxLeafTriangles = 4 * kWideMaxBlocks;

uint32_t left_of(uint32_t n) { return n + 1; }
uint32_t right_of(const FlatBvh& bvh, uint32_t n) { return bvh.nodes[n].index; }

uint32_t blocks_for(uint32_t triangles) { return (triangles + 3) / 4; }

// The distinct triangles under every node whose subtree holds at most `limit` of them
// (kNoSet above), bottom-up by merging the children's sorted sets; binary leaves always get
// theirs, whatever their size, since they cannot be split.
struct DistinctSets {
  std::vector<uint32_t> begin, size;  // per flat node; size kNoSet: more than the limit
  std::vector<uint32_t> pool;

  DistinctSets(const FlatBvh& bvh, uint32_t limit) : begin(bvh.nodes.size(), 0), size(bvh.nodes.size(), kNoSet) {
    std::vector<uint32_t> merged;
    for (size_t i = bvh.nodes.size(); i-- > 0;) {
      const FlatNode& f = bvh.nodes[i];
      merged.clear();
      if (f.is_leaf()) {
        merged.assign(bvh.triangle_ids.begin() + f.index, bvh.triangle_ids.begin() + f.index + f.count);
        std::sort(merged.begin(), merged.end());
        merged.erase(std::unique(merged.begin(), merged.end()), merged.end());
      } else {
        const uint32_t l = left_of(uint32_t(i)), r = right_of(bvh, uint32_t(i));
        if (size[l] == kNoSet || size[r] == kNoSet || size[l] > limit || size[r] > limit) continue;
        std::set_union(pool.begin() + begin[l], pool.begin() + begin[l] + size[l], pool.begin() + begin[r],
                       pool.begin() + begin[r] + size[r], std::back_inserter(merged));
        if (merged.size() > limit) continue;
      }
      begin[i] = uint32_t(pool.size());
      size[i] = uint32_t(merged.size());
      pool.insert(pool.end(), merged.begin(), merged.end());
    }
  }
  // Distinct triangle count when known (binary leaves and small subtrees).
  bool known(uint32_t n) const { return size[n] != kNoSet; }
};

// Builds the output structure from a function giving each wide node's children.
class CollapseWriter {
 public:
  CollapseWriter(const FlatBvh& bvh, const DistinctSets& sets, uint32_t width) : bvh_(bvh), sets_(sets) {
    out_.width = width;
  }

  // `children_of(flat, out)` appends the flat nodes that become the wide node's children;
  // `is_leaf(flat)` says which of them are leaves. Depth-first, children in the order given.
  template <class ChildrenOf, class IsLeaf>
  CollapsedBvh write(ChildrenOf&& children_of, IsLeaf&& is_leaf) {
    struct Pending {
      uint32_t flat;
      uint32_t slot;  // index in out_.child_index to patch with the wide node, kNoSet for the root
    };
    std::vector<Pending> todo{{0, kNoSet}};
    std::vector<uint32_t> kids;
    while (!todo.empty()) {
      const Pending p = todo.back();
      todo.pop_back();
      const uint32_t w = uint32_t(out_.nodes.size());
      if (p.slot != kNoSet) out_.child_index[p.slot] = w;
      out_.nodes.push_back(p.flat);
      kids.clear();
      if (bvh_.nodes[p.flat].is_leaf())
        kids.push_back(p.flat);  // a tree that is one leaf
      else
        children_of(p.flat, kids);
      const size_t first_slot = out_.children.size();
      for (uint32_t c : kids) {
        const bool leaf = bvh_.nodes[c].is_leaf() || is_leaf(c);
        out_.children.push_back(c);
        out_.child_is_leaf.push_back(leaf ? 1 : 0);
        out_.child_index.push_back(leaf ? add_leaf(c) : kNoSet);
      }
      out_.child_begin.push_back(uint32_t(out_.children.size()));
      // Reverse, so the first inner child is numbered next (depth-first).
      for (size_t s = out_.children.size(); s-- > first_slot;)
        if (!out_.child_is_leaf[s]) todo.push_back({out_.children[s], uint32_t(s)});
    }
    return std::move(out_);
  }

 private:
  uint32_t add_leaf(uint32_t flat) {
    if (!sets_.known(flat)) throw Error("collapse: internal error, leaf without its triangle set");
    const uint32_t n = sets_.size[flat];
    if (n > kMaxLeafTriangles)
      throw Error("collapse: a leaf of " + std::to_string(n) + " distinct triangles; wide leaves hold at most " +
                  std::to_string(kMaxLeafTriangles) + " (build with a smaller leaf size)");
    out_.leaf_triangles.insert(out_.leaf_triangles.end(), sets_.pool.begin() + sets_.begin[flat],
                               sets_.pool.begin() + sets_.begin[flat] + n);
    out_.leaf_begin.push_back(uint32_t(out_.leaf_triangles.size()));
    return uint32_t(out_.leaf_begin.size() - 2);
  }

  const FlatBvh& bvh_;
  const DistinctSets& sets_;
  CollapsedBvh out_;
};

// The dynamic program. cost[n][i-1] = C(n, i), the least cost of the subtree of n as at
// most i subtrees (each a leaf or a wide node); C(n, 1) = min(C_leaf, C_internal). Floats:
// the argmins are what matters, and the final cost is re-evaluated in double.
class OptimalCollapse {
 public:
  OptimalCollapse(const FlatBvh& bvh, const DistinctSets& sets, const CollapseOptions& o)
      : bvh_(bvh), width_(o.width), cost_(bvh.nodes.size() * o.width), choice_(bvh.nodes.size() * o.width),
        internal_split_(bvh.nodes.size()), leaf_(bvh.nodes.size()) {
    const uint32_t n = uint32_t(bvh.nodes.size());
    const uint32_t w = width_;
    // Areas relative to the root's: the float table then holds the same numbers at every
    // scale of the scene (absolute areas overflow a float above extents of about 1e19).
    const double root_area = n ? bvh.nodes[0].box.area() : 0.0;
    const double per_area = root_area > 0.0 ? 1.0 / root_area : 1.0;
    for (uint32_t i = n; i-- > 0;) {
      const FlatNode& f = bvh.nodes[i];
      const float area = float(f.box.area() * per_area);
      float* c = &cost_[size_t(i) * w];
      uint8_t* ch = &choice_[size_t(i) * w];
      float leaf_cost = kInf;
      if (sets.known(i) && (f.is_leaf() || sets.size[i] <= o.max_leaf_triangles))
        leaf_cost = float(o.cost.block) * area * float(blocks_for(sets.size[i]));
      if (f.is_leaf()) {
        std::fill(c, c + w, leaf_cost);
        std::fill(ch, ch + w, uint8_t(0));
        leaf_[i] = 1;
        continue;
      }
      const float* cl = &cost_[size_t(left_of(i)) * w];
      const float* cr = &cost_[size_t(right_of(bvh, i)) * w];
      // distribute(j): the best split of j slots over the two children, k to the left.
      auto distribute = [&](uint32_t j, uint8_t& best_k) {
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
      const float internal = float(o.cost.node) * area + distribute(w, internal_split_[i]);
      leaf_[i] = leaf_cost <= internal ? 1 : 0;
      c[0] = std::min(leaf_cost, internal);
      ch[0] = 0;
      for (uint32_t j = 2; j <= w; ++j) {
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
  }

  // The wide children of flat inner node n: the subtrees of its two children's best
  // distribution of all `width` slots.
  void children_of(uint32_t n, std::vector<uint32_t>& out) const {
    const uint32_t k = internal_split_[n];
    gather(left_of(n), k, out);
    gather(right_of(bvh_, n), width_ - k, out);
  }
  bool is_leaf(uint32_t n) const { return leaf_[n] != 0; }

 private:
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

  const FlatBvh& bvh_;
  uint32_t width_;
  std::vector<float> cost_;
  std::vector<uint8_t> choice_;
  std::vector<uint8_t> internal_split_;
  std::vector<uint8_t> leaf_;
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
  const uint32_t limit = std::min(options.max_leaf_triangles, kMaxLeafTriangles);
  const DistinctSets sets(bvh, limit);
  CollapseWriter writer(bvh, sets, options.width);
  CollapsedBvh out;
  if (options.method == CollapseMethod::greedy) {
    out = writer.write([&](uint32_t n, std::vector<uint32_t>& kids) { greedy_children(bvh, n, options.width, kids); },
                       [](uint32_t) { return false; });
  } else {
    CollapseOptions o = options;
    o.max_leaf_triangles = limit;
    const OptimalCollapse dp(bvh, sets, o);
    out = writer.write([&](uint32_t n, std::vector<uint32_t>& kids) { dp.children_of(n, kids); },
                       [&](uint32_t n) { return dp.is_leaf(n); });
  }
  out.sah_cost = wide_sah_cost(out, bvh, options.cost);
  return out;
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
  const double root = double(bvh.nodes[0].box.area());
  const double total = cost.node * nodes + cost.block * blocks;
  return root > 0.0 ? total / root : total;
}

}  // namespace bvhopt
