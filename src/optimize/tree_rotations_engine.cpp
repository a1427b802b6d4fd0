#include "optimize/tree_rotations_engine.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <utility>

#include "bvhopt/random_stream.h"

namespace bvhopt::detail {
namespace {

// The stream of one task: its own state, so no task's draws depend on another's.
inline RandomStream task_stream(uint64_t seed, uint32_t pass, uint64_t position) {
  return {mix64(mix64(seed ^ 0x6a09e667f3bcc909ull) + kGoldenGamma * (pass + 1ull) +
                mix64(position + 0x3c6ef372fe94f82bull))};
}

constexpr int kMoves = 6;

inline double area_of(const Box& b) { return b.area_unchecked(); }
inline double merged_area(const Box& a, const Box& b) { return area_of(merge(a, b)); }

}  // namespace

RotationEngine::RotationEngine(const Bvh& bvh, const CostModel& model) : c_t_(model.traversal) {
  size_t inner = 0;
  for (const BvhNode& n : bvh.nodes) inner += !n.is_leaf();  // an upper bound if some are unreachable
  pairs_.resize(1 + inner);
  cost_.assign(pairs_.size() * 2, 0.0);
  size_.assign(pairs_.size() * 2, 1);
  mut(1) = RotNode{Box{}, kRotLeaf, kInvalidNode};

  // Depth-first over the Bvh; each inner node's children get the next free pair.
  uint32_t next_pair = 1;
  std::vector<std::pair<uint32_t, uint32_t>> stack{{bvh.root, 0u}};  // (Bvh node, slot)
  while (!stack.empty()) {
    auto [b, s] = stack.back();
    stack.pop_back();
    const BvhNode& bn = bvh[b];
    RotNode& r = mut(s);
    r.box = bn.box;
    r.orig = b;
    if (bn.is_leaf()) {
      r.first = kRotLeaf;
      cost_[s] = model.intersection * static_cast<double>(bn.area()) * bn.ref_count();
    } else {
      const uint32_t c = 2 * next_pair++;
      r.first = c;
      stack.push_back({bn.right(), c + 1});
      stack.push_back({bn.left(), c});
    }
  }
  pairs_.resize(next_pair);
  cost_.resize(pairs_.size() * 2);
  size_.resize(pairs_.size() * 2);
  recompute();
  // A fixed rule of the tree alone (never of the thread count): pieces of at most 1/128 of
  // the leaves, and no smaller than 2048 leaves, so a pass has enough tasks to balance on
  // any machine and each task's nodes fit in a core's L2.
  cut_size_ = std::max<uint32_t>(2048, size_[0] / 128);
}

void RotationEngine::recompute() {
  // Pre-order, reversed: every child before its parent.
  std::vector<uint32_t> order;
  order.reserve(pairs_.size() * 2);
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    uint32_t x = stack.back();
    stack.pop_back();
    order.push_back(x);
    if (!is_leaf(x)) {
      stack.push_back(node(x).first);
      stack.push_back(node(x).first + 1);
    }
  }
  for (auto it = order.rbegin(); it != order.rend(); ++it)
    if (!is_leaf(*it)) update_inner(*it);
}

void RotationEngine::relayout() {
  std::vector<RotPair> pairs(pairs_.size());
  std::vector<double> cost(cost_.size());
  std::vector<uint32_t> size(size_.size());
  pairs[0].n[1] = node(1);
  // Depth-first allocation without a shared counter: a subtree of k leaves takes k - 1
  // pairs, its root's children get the first, the left subtree the next ones and the right
  // subtree the rest. So subtrees are laid out independently, the pieces in parallel (this
  // is the only serial part of a pass otherwise).
  struct Task {
    uint32_t old_slot, new_slot, first_pair;
  };
  auto lay_out = [&](Task root, std::vector<Task>* pieces, std::vector<Task>& stack) {
    stack.clear();
    stack.push_back(root);
    while (!stack.empty()) {
      const Task t = stack.back();
      stack.pop_back();
      RotNode r = node(t.old_slot);
      cost[t.new_slot] = cost_[t.old_slot];
      size[t.new_slot] = size_[t.old_slot];
      if (r.first != kRotLeaf) {
        const uint32_t l = r.first;
        const uint32_t c = 2 * t.first_pair;
        const uint32_t left_pairs = is_leaf(l) ? 0 : size_[l] - 1;
        const Task kids[2] = {{l, c, t.first_pair + 1}, {l + 1, c + 1, t.first_pair + 1 + left_pairs}};
        for (int i = 1; i >= 0; --i) {
          if (pieces && !is_leaf(kids[i].old_slot) && size_[kids[i].old_slot] <= cut_size_)
            pieces->push_back(kids[i]);
          else
            stack.push_back(kids[i]);
        }
        r.first = c;
      }
      pairs[t.new_slot >> 1].n[t.new_slot & 1] = r;
    }
  };
  std::vector<Task> pieces, stack;
  lay_out(Task{0, 0, 1}, &pieces, stack);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pieces.size(), 1), [&](const tbb::blocked_range<size_t>& range) {
    std::vector<Task> local;
    for (size_t k = range.begin(); k != range.end(); ++k) lay_out(pieces[k], nullptr, local);
  });
  pairs_ = std::move(pairs);
  cost_ = std::move(cost);
  size_ = std::move(size);
}

void RotationEngine::restore(const Snapshot& s) {
  pairs_ = s.pairs;
  cost_ = s.cost;
  size_ = s.size;
}

inline void RotationEngine::update_inner(uint32_t s) {
  RotNode& nd = mut(s);
  const uint32_t c = nd.first;
  const RotPair& kids = pairs_[c >> 1];
  nd.box = merge(kids.n[0].box, kids.n[1].box);
  cost_[s] = c_t_ * static_cast<double>(area_of(nd.box)) + cost_[c] + cost_[c + 1];
  size_[s] = size_[c] + size_[c + 1];
}

inline void RotationEngine::exchange(uint32_t a, uint32_t b) {
  std::swap(mut(a), mut(b));
  std::swap(cost_[a], cost_[b]);
  std::swap(size_[a], size_[b]);
}

void RotationEngine::refresh_cost(uint32_t s) {
  const uint32_t c = node(s).first;
  cost_[s] = c_t_ * static_cast<double>(area_of(node(s).box)) + cost_[c] + cost_[c + 1];
}

double RotationEngine::tree_cost() const { return cost_[0] / static_cast<double>(node(0).box.area()); }

double RotationEngine::area_delta(uint32_t s, int m) const {
  constexpr double kNone = std::numeric_limits<double>::infinity();
  if (is_leaf(s)) return kNone;
  const uint32_t l = node(s).first, r = l + 1;
  const bool li = !is_leaf(l), ri = !is_leaf(r);
  const Box& bl = box(l);
  const Box& br = box(r);
  const double al = area_of(bl), ar = area_of(br);
  switch (m) {
    case 0: return ri ? merged_area(bl, box(child(r, 1))) - ar : kNone;
    case 1: return ri ? merged_area(bl, box(child(r, 0))) - ar : kNone;
    case 2: return li ? merged_area(br, box(child(l, 1))) - al : kNone;
    case 3: return li ? merged_area(br, box(child(l, 0))) - al : kNone;
    case 4:
    case 5: {
      if (!li || !ri) return kNone;
      const Box& ll = box(child(l, 0));
      const Box& lr = box(child(l, 1));
      const Box& rl = box(child(r, 0));
      const Box& rr = box(child(r, 1));
      if (m == 4) return (double(merged_area(rl, lr)) + double(merged_area(ll, rr))) - (al + ar);
      return (double(merged_area(rr, lr)) + double(merged_area(rl, ll))) - (al + ar);
    }
    default: return kNone;
  }
}

void RotationEngine::apply(uint32_t s, int m) {
  const uint32_t l = node(s).first, r = l + 1;
  switch (m) {
    case 0: exchange(l, node(r).first); update_inner(r); break;          // L <-> RL: R = (L, RR)
    case 1: exchange(l, node(r).first + 1); update_inner(r); break;      // L <-> RR: R = (RL, L)
    case 2: exchange(r, node(l).first); update_inner(l); break;          // R <-> LL: L = (R, LR)
    case 3: exchange(r, node(l).first + 1); update_inner(l); break;      // R <-> LR: L = (LL, R)
    case 4:                                                              // LL <-> RL
      exchange(node(l).first, node(r).first);
      update_inner(l);
      update_inner(r);
      break;
    case 5:                                                              // LL <-> RR
      exchange(node(l).first, node(r).first + 1);
      update_inner(l);
      update_inner(r);
      break;
    default: return;
  }
  refresh_cost(s);
}

// The work at one inner node: Kensler's candidate loop, then the chosen move. Candidates are
// tried in the Rotation order; `best` starts at "no move" (delta 0), and a candidate d
// replaces it when d < best or, annealing, with probability exp(-(d - best) * k) (k = energy
// scale over T, per unit of area relative to this node). That test, xi < exp(-(d - best) k)
// for a uniform xi, is the same event as d - E / k < best for E = -ln(xi), an exponential
// variate that does not depend on best: so all candidates' deltas and variates are computed
// first, independently of each other, and only a compare-and-select chain remains. One xi is
// drawn per applicable candidate (Kensler draws only when d >= best; the acceptance
// probabilities are the same).
template <bool kAnneal>
inline bool RotationEngine::visit(uint32_t s, double t_over_energy, RandomStream& rng) {
  const RotNode& nd = node(s);
  const uint32_t c = nd.first;
  const RotPair& kids = pairs_[c >> 1];
  const RotNode& ln = kids.n[0];
  const RotNode& rn = kids.n[1];
  const bool li = ln.first != kRotLeaf, ri = rn.first != kRotLeaf;
  const double an = area_of(nd.box);
  int best_move = -1;
  if ((li || ri) && an > 0.0) {
    double d[kMoves];
    int from = 0, to = 0;
    const double al = area_of(ln.box), ar = area_of(rn.box);
    if (ri) {
      const RotPair& rk = pairs_[rn.first >> 1];
      const Box& rl = rk.n[0].box;
      const Box& rr = rk.n[1].box;
      d[0] = merged_area(ln.box, rr) - ar;
      d[1] = merged_area(ln.box, rl) - ar;
      to = 2;
      if (li) {
        const RotPair& lk = pairs_[ln.first >> 1];
        const Box& ll = lk.n[0].box;
        const Box& lr = lk.n[1].box;
        d[2] = merged_area(rn.box, lr) - al;
        d[3] = merged_area(rn.box, ll) - al;
        d[4] = (double(merged_area(rl, lr)) + double(merged_area(ll, rr))) - (al + ar);
        d[5] = (double(merged_area(rr, lr)) + double(merged_area(rl, ll))) - (al + ar);
        to = 6;
      }
    } else {
      const RotPair& lk = pairs_[ln.first >> 1];
      d[2] = merged_area(rn.box, lk.n[1].box) - al;
      d[3] = merged_area(rn.box, lk.n[0].box) - al;
      from = 2;
      to = 4;
    }
    double best = 0.0;
    if constexpr (kAnneal) {
      // The area change that an exponential variate's worth of energy buys at this node.
      const double unit = t_over_energy * static_cast<double>(an);
      double slack[kMoves];
      for (int m = from; m < to; ++m) slack[m] = -std::log(rng.open_uniform()) * unit;
      for (int m = from; m < to; ++m) {
        if (d[m] - slack[m] < best) {
          best = d[m];
          best_move = m;
        }
      }
    } else {
      for (int m = from; m < to; ++m) {
        if (d[m] < best) {
          best = d[m];
          best_move = m;
        }
      }
    }
  }
  if (best_move >= 0) {
    apply(s, best_move);
    return true;
  }
  cost_[s] = c_t_ * static_cast<double>(an) + cost_[c] + cost_[c + 1];
  return false;
}

// Post-order over the inner nodes below `start`. With kStopAtPieces, inner children with at
// most cut_size_ leaves are not entered (their piece has been walked already). The high bit
// of a stack entry marks a node whose children are already on the stack.
template <bool kAnneal, bool kStopAtPieces>
uint64_t RotationEngine::walk(uint32_t start, double t_over_energy, RandomStream rng, std::vector<uint32_t>& stack) {
  constexpr uint32_t kExpanded = 0x80000000u;
  uint64_t moves = 0;
  stack.clear();
  stack.push_back(start);
  while (!stack.empty()) {
    const uint32_t e = stack.back();
    if (e & kExpanded) {
      stack.pop_back();
      moves += visit<kAnneal>(e & ~kExpanded, t_over_energy, rng);
      continue;
    }
    stack.back() = e | kExpanded;
    const uint32_t c = node(e).first;
    const RotPair& kids = pairs_[c >> 1];
    // The right child is expanded only after the whole left subtree; start fetching its
    // children now so that the walk does not wait for them then.
    if (kids.n[1].first != kRotLeaf) __builtin_prefetch(&pairs_[kids.n[1].first >> 1]);
    // Right pushed first so the left subtree is walked first.
    if (kids.n[1].first != kRotLeaf && (!kStopAtPieces || size_[c + 1] > cut_size_)) stack.push_back(c + 1);
    if (kids.n[0].first != kRotLeaf && (!kStopAtPieces || size_[c] > cut_size_)) stack.push_back(c);
  }
  return moves;
}

uint64_t RotationEngine::run_pass(double temperature, double energy_scale, uint64_t seed, uint32_t pass) {
  if (is_leaf(0)) return 0;
  const bool anneal = temperature > 0.0;
  const double t_over_energy = anneal ? temperature / energy_scale : 0.0;

  // The pieces: inner nodes with at most cut_size_ leaves whose parent has more, in
  // depth-first order; their position in that order names their random stream. A move in a
  // piece changes only slots inside it, so pieces run in parallel; the nodes above them
  // (the top) are walked afterwards, which is still a post-order walk of the whole tree.
  std::vector<uint32_t> pieces;
  const bool split = size_[0] > cut_size_;
  if (!split) {
    pieces.push_back(0);
  } else {
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
      const uint32_t x = stack.back();
      stack.pop_back();
      const uint32_t c = node(x).first;
      for (uint32_t k = c; k < c + 2; ++k)
        if (!is_leaf(k) && size_[k] <= cut_size_) pieces.push_back(k);
      for (uint32_t k = c + 2; k-- > c;)
        if (!is_leaf(k) && size_[k] > cut_size_) stack.push_back(k);
    }
  }

  std::vector<uint64_t> moves(pieces.size() + 1, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pieces.size(), 1), [&](const tbb::blocked_range<size_t>& range) {
    std::vector<uint32_t> stack;
    stack.reserve(128);
    for (size_t k = range.begin(); k != range.end(); ++k) {
      const RandomStream rng = task_stream(seed, pass, k);
      moves[k] = anneal ? walk<true, false>(pieces[k], t_over_energy, rng, stack)
                        : walk<false, false>(pieces[k], 0.0, rng, stack);
    }
  });
  if (split) {
    std::vector<uint32_t> stack;
    const RandomStream rng = task_stream(seed, pass, 0xffffffffull);
    moves.back() = anneal ? walk<true, true>(0, t_over_energy, rng, stack) : walk<false, true>(0, 0.0, rng, stack);
  }
  uint64_t total = 0;
  for (uint64_t m : moves) total += m;
  return total;
}

void RotationEngine::write_to(Bvh& bvh) const {
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t s = stack.back();
    stack.pop_back();
    const RotNode& nd = node(s);
    if (nd.first == kRotLeaf) continue;
    BvhNode& b = bvh.nodes[nd.orig];
    const uint32_t l = node(nd.first).orig, r = node(nd.first + 1).orig;
    b.make_inner(l, r);
    b.set_box(nd.box);
    bvh.nodes[l].parent = nd.orig;
    bvh.nodes[r].parent = nd.orig;
    stack.push_back(nd.first);
    stack.push_back(nd.first + 1);
  }
  bvh.nodes[node(0).orig].parent = kInvalidNode;
  bvh.root = node(0).orig;
}

}  // namespace bvhopt::detail
