// The working copy of a tree that the rotation optimizers walk (private to the library and
// its tests).
//
// Layout: 32-byte records (box, index of the first child, the node's index in the Bvh) in
// slots; the two children of every inner node sit in one 64-byte-aligned pair of slots, so
// reading both children is one cache line. A move never relinks anything: exchanging two
// subtrees is exchanging the two records (each carries its own child pointer along), so
// every node's children stay a pair for good. Pairs are laid out in depth-first order of
// their parents at the start; moves only exchange records between a node's children and
// grandchildren, so a post-order walk keeps reading memory nearly in order. Per-slot subtree
// costs (double) and leaf counts live in plain arrays beside the records and move with them.
// The root is slot 0; slot 1 is unused padding.
#pragma once

#include <cstdint>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/random_stream.h"

namespace bvhopt::detail {

inline constexpr uint32_t kRotLeaf = 0xffffffffu;

struct RotNode {
  Box box;
  uint32_t first;  // slot of the left child (the right one is first + 1); kRotLeaf for leaves
  uint32_t orig;   // the node's index in the Bvh
};
static_assert(sizeof(RotNode) == 32);

struct alignas(64) RotPair {
  RotNode n[2];
};

class RotationEngine {
 public:
  // Inner boxes are recomputed as the union of their children, so a tree with loose boxes
  // is tightened first. The tree must be non-empty.
  RotationEngine(const Bvh& bvh, const CostModel& model);

  uint32_t slot_count() const { return static_cast<uint32_t>(pairs_.size() * 2); }
  uint32_t root() const { return 0; }
  const RotNode& node(uint32_t s) const { return pairs_[s >> 1].n[s & 1]; }
  bool is_leaf(uint32_t s) const { return node(s).first == kRotLeaf; }
  uint32_t child(uint32_t s, int i) const { return node(s).first + static_cast<uint32_t>(i); }
  const Box& box(uint32_t s) const { return node(s).box; }
  double node_cost(uint32_t s) const { return cost_[s]; }
  uint32_t leaf_count(uint32_t s) const { return size_[s]; }
  uint32_t bvh_index(uint32_t s) const { return node(s).orig; }

  // Normalized SAH cost: root subtree cost over root area (the root area must be > 0).
  double tree_cost() const;
  double root_area() const { return node(0).box.area(); }

  // Change of the summed inner-node areas if move m (Rotation order) were applied at s;
  // +infinity if the move does not apply there.
  double area_delta(uint32_t s, int m) const;
  // Applies move m at s and updates the boxes, costs and leaf counts of the changed children
  // and s's cost. Callers walking bottom-up keep every cost exact this way.
  void apply(uint32_t s, int m);
  // Recomputes s's cost from its children's (what a pass does at a node it leaves alone).
  void refresh_cost(uint32_t s);

  // One post-order pass over the tree. temperature <= 0: hill climbing. Otherwise Kensler's
  // acceptance with dE = energy_scale * dA / S(N). Random streams derive from (seed, pass,
  // subtree position). Returns the number of moves applied.
  uint64_t run_pass(double temperature, double energy_scale, uint64_t seed, uint32_t pass);

  // Moves scatter the pairs a walk reads in turn; this lays them out again in depth-first
  // order of their parents. The tree, and so every later pass, stays the same.
  void relayout();

  struct Snapshot {
    std::vector<RotPair> pairs;
    std::vector<double> cost;
    std::vector<uint32_t> size;
  };
  Snapshot snapshot() const { return {pairs_, cost_, size_}; }
  void restore(const Snapshot& s);

  // Writes the current tree into bvh (same node indices as the Bvh it was made from).
  void write_to(Bvh& bvh) const;

 private:
  RotNode& mut(uint32_t s) { return pairs_[s >> 1].n[s & 1]; }
  void recompute();
  void update_inner(uint32_t s);
  void exchange(uint32_t a, uint32_t b);
  template <bool kAnneal>
  bool visit(uint32_t s, double t_over_energy, RandomStream& rng);
  template <bool kAnneal, bool kStopAtPieces>
  uint64_t walk(uint32_t start, double t_over_energy, RandomStream rng, std::vector<uint32_t>& stack);

  std::vector<RotPair> pairs_;
  std::vector<double> cost_;      // subtree cost, not normalized
  std::vector<uint32_t> size_;    // leaves in the subtree
  double c_t_ = 3.0;
  uint32_t cut_size_ = 0;         // subtrees of at most this many leaves are walked as one task
};

}  // namespace bvhopt::detail
