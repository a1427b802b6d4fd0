#include "bvhopt/insertion_optimizer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <functional>
#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

#include "optimize/reinsertion_search.h"

namespace bvhopt {

std::string_view measure_name(InsertionMeasure m) {
  switch (m) {
    case InsertionMeasure::area: return "area";
    case InsertionMeasure::sum: return "sum";
    case InsertionMeasure::min: return "min";
    case InsertionMeasure::comb: return "comb";
  }
  return "area";
}

std::optional<InsertionMeasure> parse_measure(std::string_view name) {
  for (InsertionMeasure m : {InsertionMeasure::area, InsertionMeasure::sum, InsertionMeasure::min, InsertionMeasure::comb})
    if (measure_name(m) == name) return m;
  return std::nullopt;
}

std::string_view form_name(InsertionForm f) {
  switch (f) {
    case InsertionForm::sequential: return "sequential";
    case InsertionForm::parallel: return "parallel";
    case InsertionForm::hybrid: return "hybrid";
  }
  return "hybrid";
}

std::optional<InsertionForm> parse_form(std::string_view name) {
  for (InsertionForm f : {InsertionForm::sequential, InsertionForm::parallel, InsertionForm::hybrid})
    if (form_name(f) == name) return f;
  return std::nullopt;
}

ReinsertionCandidate find_reinsertion(const Bvh& bvh, const Box& box, uint32_t skip, uint32_t pass_through) {
  std::vector<detail::SearchEntry> heap;
  return detail::search_reinsertion(bvh, box, skip, pass_through, heap);
}

ReinsertionCandidate find_reinsertion_after_removal(const Bvh& bvh, const Box& box, uint32_t n, double* freed_area) {
  std::vector<detail::SearchEntry> heap;
  std::vector<std::pair<uint32_t, Box>> path;
  return detail::search_reinsertion_after_removal(bvh, box, n, heap, path, freed_area);
}

ReinsertionCandidate find_reinsertion_brute_force(const Bvh& bvh, const Box& box, uint32_t skip,
                                                  uint32_t pass_through) {
  ReinsertionCandidate best{kInvalidNode, std::numeric_limits<double>::infinity()};
  if (bvh.empty()) return best;
  std::vector<detail::SearchEntry> stack{{0.0, bvh.root}};
  while (!stack.empty()) {
    const detail::SearchEntry e = stack.back();
    stack.pop_back();
    if (e.node == skip) continue;
    const BvhNode& x = bvh[e.node];
    const double direct = merge(x.box, box).area();
    const double total = e.induced + direct;
    if (total < best.cost && e.node != pass_through) best = {e.node, total};
    if (x.is_leaf()) continue;
    const double child_induced = e.induced + (direct - static_cast<double>(x.area));
    stack.push_back({child_induced, x.right()});
    stack.push_back({child_induced, x.left()});
  }
  return best;
}

namespace {

// splitmix64: a tiny generator whose sequence is the same on every platform (the standard
// distributions are not).
struct Random {
  uint64_t state;
  uint64_t next() {
    uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  uint32_t below(uint32_t n) { return static_cast<uint32_t>((next() >> 32) * n >> 32); }
};

// One planned move of a parallel pass: node N out, its children to x_first and x_second.
// One planned move of a parallel pass: subtree `moved` leaves its parent (which is freed,
// the sibling taking its place) and goes above `target`, with the exact change of the sum
// of inner areas in the tree as the plan saw it.
struct Plan {
  uint32_t moved = kInvalidNode;
  uint32_t target = kInvalidNode;
  double delta = 0.0;
};

class InsertionOptimizer {
 public:
  InsertionOptimizer(Bvh& bvh, const InsertionConfig& config) : bvh_(bvh), config_(config) {
    for (const BvhNode& n : bvh_.nodes) {
      if (n.is_leaf())
        leaf_term_ += leaf_cost(n.area, n.ref_count());
      else
        inner_area_ += n.area;
    }
    root_area_ = bvh_[bvh_.root].area;
  }

  double cost() const { return (config_.cost.traversal * inner_area_ + leaf_term_) / root_area_; }

  bool can_optimize() const { return root_area_ > 0.0 && bvh_.nodes.size() >= 5; }

  // Candidates of one pass: the k inner non-root nodes with the largest measure, largest
  // first, or k random ones.
  void select(uint32_t pass, bool random, std::vector<uint32_t>& out) {
    out.clear();
    // Moves reuse the freed nodes as inner nodes, so the set of inner node ids never
    // changes; only which of them is the root does (the root is skipped when met).
    if (inner_.empty())
      for (uint32_t i = 0; i < bvh_.nodes.size(); ++i)
        if (!bvh_[i].is_leaf()) inner_.push_back(i);
    if (inner_.empty()) return;
    const size_t k = std::clamp<size_t>(static_cast<size_t>(std::ceil(config_.batch * inner_.size())), 1, inner_.size());
    if (random) {
      Random rng{config_.seed * 0x9e3779b97f4a7c15ull + pass};
      for (size_t i = 0; i < k; ++i) out.push_back(inner_[rng.below(static_cast<uint32_t>(inner_.size()))]);
      return;
    }
    // One 64-bit key per node: the measure's float bits (non-negative floats order as their
    // bits do) above the complemented index, so ties go to the lower index and the order
    // never depends on the selection algorithm.
    keys_.resize(inner_.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, inner_.size(), 8192), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const uint32_t n = inner_[i];
        const float m = n == bvh_.root ? 0.0f : static_cast<float>(measure(n));
        keys_[i] = (static_cast<uint64_t>(std::bit_cast<uint32_t>(m)) << 32) | (0xffffffffu - n);
      }
    });
    std::nth_element(keys_.begin(), keys_.begin() + (k - 1), keys_.end(), std::greater<uint64_t>());
    std::sort(keys_.begin(), keys_.begin() + k, std::greater<uint64_t>());
    for (size_t i = 0; i < k; ++i) {
      const uint32_t n = 0xffffffffu - static_cast<uint32_t>(keys_[i]);
      if (n != bvh_.root) out.push_back(n);
    }
  }

  // The paper's step 2 for one node: remove N and its parent, reinsert both children
  // (larger first) at the best places in the tree as it is after the removal.
  uint64_t update_sequential(uint32_t n) {
    if (n == bvh_.root || bvh_[n].is_leaf()) return 0;
    auto [a, b] = ordered_children(n);
    const uint32_t p = bvh_[n].parent;
    remove(n);
    ReinsertionCandidate ca = detail::search_reinsertion(bvh_, bvh_[a].box, kInvalidNode, kInvalidNode, heap_);
    insert(a, ca.node, n);
    ReinsertionCandidate cb = detail::search_reinsertion(bvh_, bvh_[b].box, kInvalidNode, kInvalidNode, heap_);
    insert(b, cb.node, p);
    if (config_.after_move) config_.after_move(bvh_, cost());
    return 1;
  }

  // Meister-Bittner style: search every candidate against the current tree on all threads,
  // then apply in candidate order.
  uint64_t pass_parallel(const std::vector<uint32_t>& candidates) {
    plans_.assign(candidates.size(), Plan{});
    tbb::parallel_for(tbb::blocked_range<size_t>(0, candidates.size(), 8), [&](const tbb::blocked_range<size_t>& r) {
      std::vector<detail::SearchEntry> heap;
      std::vector<std::pair<uint32_t, Box>> path;
      for (size_t i = r.begin(); i < r.end(); ++i) plans_[i] = plan(candidates[i], heap, path);
    });
    if (touched_.size() != bvh_.nodes.size()) touched_.assign(bvh_.nodes.size(), 0);
    ++stamp_;
    uint64_t moves = 0;
    for (const Plan& pl : plans_)
      if (pl.moved != kInvalidNode) moves += apply(pl);
    return moves;
  }

 private:
  double measure(uint32_t i) const {
    const BvhNode& n = bvh_[i];
    const double a = n.area;
    const double la = bvh_[n.left()].area, ra = bvh_[n.right()].area;
    // Zero-area children (conference's flat triangles) would divide by zero.
    constexpr double tiny = 1e-30;
    switch (config_.measure) {
      case InsertionMeasure::area: return a;
      case InsertionMeasure::sum: return a / std::max(0.5 * (la + ra), tiny);
      case InsertionMeasure::min: return a / std::max(std::min(la, ra), tiny);
      case InsertionMeasure::comb:
        return a * (a / std::max(0.5 * (la + ra), tiny)) * (a / std::max(std::min(la, ra), tiny));
    }
    return a;
  }

  std::pair<uint32_t, uint32_t> ordered_children(uint32_t n) const {
    uint32_t a = bvh_[n].left(), b = bvh_[n].right();
    if (bvh_[b].area > bvh_[a].area) std::swap(a, b);
    return {a, b};
  }

  // Refits from `n` up, adding each area change to the tracked sum. Stops at the first box
  // that does not change: the boxes above it cannot change either.
  void refit_up(uint32_t n) {
    while (n != kInvalidNode) {
      BvhNode& nd = bvh_[n];
      const Box b = merge(bvh_[nd.left()].box, bvh_[nd.right()].box);
      if (b == nd.box) return;
      const float old_area = nd.area;
      nd.set_box(b);
      inner_area_ += static_cast<double>(nd.area) - old_area;
      n = nd.parent;
    }
  }

  // Figure 3: N and its parent P leave the tree, N's sibling takes P's place.
  void remove(uint32_t n) { detach(n, bvh_[n].area); }

  // Figure 5: `free_node` becomes the parent of X and L, in X's old place.
  void insert(uint32_t l, uint32_t x, uint32_t free_node) {
    const uint32_t q = bvh_[x].parent;
    BvhNode& f = bvh_[free_node];
    f.make_inner(x, l);
    f.parent = q;
    f.set_box(merge(bvh_[x].box, bvh_[l].box));
    inner_area_ += f.area;
    if (q == kInvalidNode)
      bvh_.root = free_node;
    else
      bvh_[q].set_child(bvh_.child_slot(x), free_node);
    bvh_[x].parent = free_node;
    bvh_[l].parent = free_node;
    if (q != kInvalidNode) refit_up(q);
  }

  // The parallel form moves one subtree at a time (as Meister and Bittner do), so every
  // plan's gain is exact against the tree it saw: of candidate N's two children, the one
  // whose best move gains more.
  Plan plan(uint32_t n, std::vector<detail::SearchEntry>& heap, std::vector<std::pair<uint32_t, Box>>& path) const {
    Plan best;
    if (n == bvh_.root || bvh_[n].is_leaf()) return best;
    for (int side = 0; side < 2; ++side) {
      const uint32_t m = bvh_[n].child(side);
      double freed = 0.0;
      ReinsertionCandidate c = detail::search_reinsertion_after_removal(bvh_, bvh_[m].box, m, heap, path, &freed);
      if (c.node == kInvalidNode) continue;
      // The search counts m's own area as freed; m stays a subtree, only its parent is freed.
      const double delta = c.cost - (freed - bvh_[m].area);
      if (delta < best.delta) best = {m, c.node, delta};
    }
    return best;
  }

  bool is_touched(uint32_t n) const { return n != kInvalidNode && touched_[n] == stamp_; }
  bool inside(uint32_t x, uint32_t subtree_root) const {
    for (; x != kInvalidNode; x = bvh_[x].parent)
      if (x == subtree_root) return true;
    return false;
  }

  // Takes `m` and its parent out (the parent becomes free, the sibling takes its place);
  // m keeps its subtree.
  // `also_removed`: the area of m itself when m leaves the tree's inner nodes too (remove).
  uint32_t detach(uint32_t m, double also_removed = 0.0) {
    const uint32_t p = bvh_[m].parent;
    const uint32_t s = bvh_.sibling(m);
    const uint32_t g = bvh_[p].parent;
    inner_area_ -= also_removed + bvh_[p].area;
    if (g == kInvalidNode) {
      bvh_.root = s;
      bvh_[s].parent = kInvalidNode;
    } else {
      bvh_[g].set_child(bvh_.child_slot(p), s);
      bvh_[s].parent = g;
      refit_up(g);
    }
    bvh_[m].parent = kInvalidNode;
    bvh_[p].parent = kInvalidNode;
    return p;
  }

  uint64_t apply(const Plan& pl) {
    const uint32_t m = pl.moved, x = pl.target;
    // Read links only through untouched nodes: an untouched node still has the links the
    // plan saw.
    if (is_touched(m) || is_touched(x)) return 0;
    const uint32_t p = bvh_[m].parent;
    if (p == kInvalidNode || is_touched(p)) return 0;
    const uint32_t s = bvh_.sibling(m);
    const uint32_t g = bvh_[p].parent;
    const uint32_t q = bvh_[x].parent;
    const uint32_t involved[] = {m, p, g, s, x, q};
    for (uint32_t v : involved)
      if (is_touched(v)) return 0;
    // Earlier moves may have carried the target into m's subtree; linking there would make a cycle.
    if (inside(x, m)) return 0;

    BvhNode saved[6];
    for (int i = 0; i < 6; ++i)
      if (involved[i] != kInvalidNode) saved[i] = bvh_[involved[i]];
    const uint32_t saved_root = bvh_.root;
    const double saved_area = inner_area_;

    const uint32_t free_node = detach(m);
    insert(m, x, free_node);

    if (inner_area_ >= saved_area) {
      // Boxes that earlier moves of the pass changed made the plan wrong; undo it. Restoring
      // the records and refitting every path to the root gives back exactly the old boxes,
      // since each is the union of its children.
      for (int i = 0; i < 6; ++i)
        if (involved[i] != kInvalidNode) bvh_[involved[i]] = saved[i];
      bvh_.root = saved_root;
      for (uint32_t v : involved)
        if (v != kInvalidNode) refit_to_root(v);
      inner_area_ = saved_area;
      if (config_.after_move) config_.after_move(bvh_, cost());
      return 0;
    }
    for (uint32_t v : involved)
      if (v != kInvalidNode) touched_[v] = stamp_;
    if (config_.after_move) config_.after_move(bvh_, cost());
    return 1;
  }

  void refit_to_root(uint32_t n) {
    for (; n != kInvalidNode; n = bvh_[n].parent) {
      BvhNode& nd = bvh_[n];
      if (!nd.is_leaf()) nd.set_box(merge(bvh_[nd.left()].box, bvh_[nd.right()].box));
    }
  }

  Bvh& bvh_;
  const InsertionConfig& config_;
  double inner_area_ = 0.0;
  double leaf_term_ = 0.0;
  double root_area_ = 0.0;
  std::vector<detail::SearchEntry> heap_;
  std::vector<uint32_t> inner_;
  std::vector<uint64_t> keys_;
  std::vector<Plan> plans_;
  std::vector<uint32_t> touched_;
  uint32_t stamp_ = 0;

  double leaf_cost(float area, uint32_t count) const { return config_.cost.intersection * area * count; }
};

}  // namespace

OptimizeReport optimize_insertion(Bvh& bvh, const InsertionConfig& config, const PassCallback& on_pass) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point start = Clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };

  OptimizeReport report;
  if (bvh.empty()) {
    report.stop_reason = "empty tree";
    return report;
  }
  // Numbering every reachable node densely lets a pass scan the node array for inner
  // nodes; the refit makes every box exactly the union of its children, which undoing a
  // parallel move relies on.
  bvh.renumber_depth_first();
  for (uint32_t n : bvh.post_order()) {
    BvhNode& nd = bvh[n];
    if (!nd.is_leaf()) nd.set_box(merge(bvh[nd.left()].box, bvh[nd.right()].box));
  }

  {
    InsertionOptimizer probe(bvh, config);
    report.initial_cost = report.final_cost = probe.cost();
    if (!probe.can_optimize()) {
      report.stop_reason = "nothing to optimize";
      report.seconds = elapsed();
      return report;
    }
  }

  std::vector<bool> stages;  // true = parallel form
  switch (config.form) {
    case InsertionForm::sequential: stages = {false}; break;
    case InsertionForm::parallel: stages = {true}; break;
    case InsertionForm::hybrid: stages = {false, true}; break;
  }
  double best = report.initial_cost;
  uint32_t pass = 0;
  std::vector<uint32_t> candidates;
  report.stop_reason = "pass limit";
  bool out_of_budget = false;
  for (size_t stage = 0; stage < stages.size() && !out_of_budget; ++stage) {
    const bool parallel = stages[stage];
    // Each stage starts afresh from the tree the last one left (its tracked sums included).
    InsertionOptimizer opt(bvh, config);
    uint32_t without_improvement = 0;
    bool random = false;
    // The sequential form can raise the cost (both children are out at once) and oscillates
    // near the end, so it keeps the best tree it has seen. The parallel form never raises it.
    const bool keep_best = !parallel;
    double stage_best = opt.cost();
    std::vector<BvhNode> best_nodes;
    if (keep_best) best_nodes = bvh.nodes;
    uint32_t best_root = bvh.root;
    bool converged = false;
    while (true) {
      if (pass >= config.max_passes) {
        report.stop_reason = "pass limit";
        out_of_budget = true;
        break;
      }
      ++pass;
      // Once the measure has stalled, selection stays random (section 2.5): going back to
      // the measure after a good random pass would only retry the nodes that just stalled.
      random = random || without_improvement >= config.random_after;
      opt.select(pass, random, candidates);
      uint64_t moves = 0;
      if (parallel) {
        moves = opt.pass_parallel(candidates);
      } else {
        for (uint32_t n : candidates) moves += opt.update_sequential(n);
      }
      PassRecord rec;
      rec.pass = pass;
      rec.cost = opt.cost();
      // A relative margin, so that rounding noise in an oscillating tail or the endless tiny
      // gains of the parallel form never count as progress.
      if (rec.cost < stage_best * (1.0 - config.min_improvement))
        without_improvement = 0;
      else
        ++without_improvement;
      if (rec.cost < stage_best) {
        stage_best = rec.cost;
        if (keep_best) {
          best_nodes = bvh.nodes;
          best_root = bvh.root;
        }
      }
      best = std::min(best, rec.cost);
      rec.best_cost = best;
      rec.moves = moves;
      rec.seconds = elapsed();
      report.trace.push_back(rec);
      report.passes = pass;
      report.moves += moves;
      if (on_pass) on_pass(rec);
      if (without_improvement >= config.stop_after) {
        converged = true;
        break;
      }
      if (config.time_limit_seconds > 0.0 && rec.seconds >= config.time_limit_seconds) {
        report.stop_reason = "time limit";
        out_of_budget = true;
        break;
      }
    }
    report.final_cost = opt.cost();
    if (keep_best && stage_best < report.final_cost) {
      bvh.nodes = std::move(best_nodes);
      bvh.root = best_root;
      report.final_cost = stage_best;
    }
    if (converged) report.stop_reason = "converged";
  }
  bvh.renumber_depth_first();
  report.seconds = elapsed();
  return report;
}

}  // namespace bvhopt
