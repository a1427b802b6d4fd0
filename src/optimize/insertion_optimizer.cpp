#include "bvhopt/insertion_optimizer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <utility>
#include <vector>

#include "bvhopt/random_stream.h"
#include "bvhopt/testing/insertion_hooks.h"
#include "optimize/find_by_name.h"
#include "optimize/huge_page_backing.h"
#include "optimize/largest_keys.h"
#include "optimize/pass_driver.h"
#include "optimize/reinsertion_search.h"
#include "optimize/node_set.h"
#include "optimize/undo_log.h"

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

std::vector<InsertionMeasure> insertion_measures() {
  return {InsertionMeasure::area, InsertionMeasure::sum, InsertionMeasure::min, InsertionMeasure::comb};
}

std::optional<InsertionMeasure> parse_measure(std::string_view name) {
  return detail::find_by_name(insertion_measures(), measure_name, name);
}

std::string_view form_name(InsertionForm f) {
  switch (f) {
    case InsertionForm::sequential: return "sequential";
    case InsertionForm::parallel: return "parallel";
    case InsertionForm::hybrid: return "hybrid";
  }
  return "hybrid";
}

std::vector<InsertionForm> insertion_forms() {
  return {InsertionForm::sequential, InsertionForm::parallel, InsertionForm::hybrid};
}

std::optional<InsertionForm> parse_form(std::string_view name) {
  return detail::find_by_name(insertion_forms(), form_name, name);
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

namespace {

// One planned move of a parallel pass: subtree `moved` leaves its parent (which is freed,
// the sibling taking its place) and goes above `target`, with the exact change of the sum
// of inner areas in the tree as the plan saw it.
struct Plan {
  uint32_t moved = kInvalidNode;
  uint32_t target = kInvalidNode;
  double delta = 0.0;
};

// One stage of the optimizer (one form) over the tree, and its passes for the pass driver.
class InsertionOptimizer {
 public:
  InsertionOptimizer(Bvh& bvh, const InsertionConfig& config, bool parallel, const testing::AfterMove* after_move)
      : bvh_(bvh), config_(config), parallel_(parallel), after_move_(after_move) {
    for (const BvhNode& n : bvh_.nodes) {
      if (n.is_leaf())
        leaf_term_ += leaf_cost(n.area(), n.ref_count());
      else
        inner_area_ += n.area();
    }
    root_area_ = bvh_[bvh_.root].area();
  }

  double cost() const { return (config_.cost.traversal * inner_area_ + leaf_term_) / root_area_; }

  bool can_optimize() const { return root_area_ > 0.0 && bvh_.nodes.size() >= 5; }

  // The sequential form can raise the cost (both children are out at once) and oscillates
  // near the end, so it keeps the best tree it has seen. The parallel form never raises it.
  bool keep_best_before(uint32_t /*pass*/) const { return !parallel_; }
  // The best tree is kept as an undo log from it, not a copy: only one restore point is
  // ever live (the driver takes the next only after dropping the last), so the token is empty.
  struct Snapshot {};
  Snapshot snapshot() {
    if (undo_.capacity() == 0) undo_.reserve(undo_limit() + kUndoSlack);
    undo_.begin(bvh_, inner_area_);
    return {};
  }
  void restore(Snapshot) { undo_.restore(bvh_, inner_area_); }

  detail::PassResult run_pass(uint32_t pass, double stage_best) {
    // Once the measure has stalled, selection stays random (section 2.5): going back to the
    // measure after a good random pass would only retry the nodes that just stalled.
    random_ = random_ || without_improvement_ >= config_.random_after;
    select(pass + 1, random_, candidates_);
    uint64_t moves = 0;
    if (parallel_) {
      moves = pass_parallel(candidates_);
    } else {
      for (size_t i = 0; i < candidates_.size(); ++i) {
        prefetch_ahead(i);
        moves += update_sequential(candidates_[i]);
        if (undo_.size() >= undo_limit() && !stay_within_log()) break;
      }
    }
    const double c = cost();
    // A relative margin, so that rounding noise in an oscillating tail or the endless tiny
    // gains of the parallel form never count as progress.
    if (c < stage_best * (1.0 - config_.min_improvement))
      without_improvement_ = 0;
    else
      ++without_improvement_;
    return {c, moves, 0.0, without_improvement_ >= config_.stop_after};
  }

 private:

  // The undo log holds at most one record per sixteenth of the nodes (2.75 bytes a node,
  // where a copy of the tree took 40; it keeps the optimizer under 100 bytes a triangle): a
  // pass changes about 3 % of them, a stretch of passes without a new best up to a quarter.
  // One move adds at most twice the tree's depth, the slack reserved beyond the limit.
  size_t undo_limit() const { return std::max<size_t>(bvh_.nodes.size() / 16, 64); }
  static constexpr size_t kUndoSlack = 1024;

  // The log is full. If the tree now costs less than the restore point, it becomes the
  // restore point (a better tree than the driver's best: kept). Otherwise the tree goes back
  // to the restore point and the pass ends there: the next pass starts again from the best
  // tree, with other candidates.
  bool stay_within_log() {
    if (inner_area_ < undo_.restore_point_sum()) {
      undo_.begin(bvh_, inner_area_);
      return true;
    }
    undo_.restore(bvh_, inner_area_);
    notify_move();
    return false;
  }

  // Each update starts with misses on its candidate, the candidate's children and parent:
  // asked for a few updates ahead (the node first, its neighbours once it has arrived).
  void prefetch_ahead(size_t i) const {
    constexpr size_t kNodeAhead = 8, kLinksAhead = 4;
    const BvhNode* nodes = bvh_.nodes.data();
    if (i + kNodeAhead < candidates_.size()) detail::prefetch_node(nodes, candidates_[i + kNodeAhead]);
    if (i + kLinksAhead < candidates_.size()) {
      const BvhNode& c = nodes[candidates_[i + kLinksAhead]];
      if (c.is_leaf()) return;
      detail::prefetch_children(nodes, c);
      if (c.parent != kInvalidNode) detail::prefetch_node(nodes, c.parent);
    }
  }

  // Candidates of one pass: the k inner non-root nodes with the largest measure, largest
  // first, or k random ones.
  void select(uint32_t pass, bool random, std::vector<uint32_t>& out) {
    out.clear();
    // Moves reuse the freed nodes as inner nodes, so the set of inner node ids never
    // changes; only which of them is the root does (the root is skipped when met).
    if (inner_count_ == 0)
      for (const BvhNode& nd : bvh_.nodes) inner_count_ += !nd.is_leaf();
    if (inner_count_ == 0) return;
    const size_t k = std::clamp<size_t>(static_cast<size_t>(std::ceil(config_.batch * inner_count_)), 1, inner_count_);
    if (random) {
      // Uniform over the inner nodes without a list of them: draws that hit a leaf are redrawn.
      RandomStream rng{config_.seed * kGoldenGamma + pass};
      const uint32_t count = static_cast<uint32_t>(bvh_.nodes.size());
      for (size_t i = 0; i < k; ++i) {
        uint32_t n = rng.below(count);
        while (bvh_[n].is_leaf()) n = rng.below(count);
        out.push_back(n);
      }
      return;
    }
    largest_.largest(
        bvh_.nodes.size(), k, [&](size_t i) { return !bvh_.nodes[i].is_leaf(); },
        [&](size_t i) { return key(static_cast<uint32_t>(i)); }, keys_);
    for (uint64_t kk : keys_) {
      const uint32_t n = 0xffffffffu - static_cast<uint32_t>(kk);
      if (n != bvh_.root) out.push_back(n);
    }
  }

  // One 64-bit key per inner node: the measure's float bits (non-negative floats order as
  // their bits do) above the complemented index, so ties go to the lower index and the
  // order never depends on the selection algorithm.
  uint64_t key(uint32_t n) const {
    const float m = n == bvh_.root ? 0.0f : static_cast<float>(measure(n));
    return (static_cast<uint64_t>(std::bit_cast<uint32_t>(m)) << 32) | (0xffffffffu - n);
  }

  // The paper's step 2 for one node: remove N and its parent, reinsert both children
  // (larger first) at the best places in the tree as it is after the removal.
  uint64_t update_sequential(uint32_t n) {
    if (n == bvh_.root || bvh_[n].is_leaf()) return 0;
    auto [a, b] = ordered_children(n);
    const uint32_t p = bvh_[n].parent;
    const uint32_t s = bvh_.sibling(n);
    remove(n);
    // Both searches start from N's sibling, which took P's place: the children's old
    // neighbourhood, usually close to their best place, so the bound prunes from the start.
    insert(a, search_from(a, s), n);
    insert(b, search_from(b, s), p);
    notify_move();
    return 1;
  }

  // The best place for subtree m (out of the tree) by the full search, seeded with `start`.
  // Its cost is taken from start's nearby ancestors only (placement_cost_near): walking them
  // all to the root was a quarter of the update's own time at 1M triangles.
  uint32_t search_from(uint32_t m, uint32_t start) {
    const Box& box = bvh_[m].box;
    const ReinsertionCandidate seed{start, detail::placement_cost_near(bvh_, box, start, path_)};
    return detail::search_reinsertion(bvh_, box, kInvalidNode, kInvalidNode, heap_, seed).node;
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
    touched_.reset(bvh_.nodes.size());
    uint64_t moves = 0;
    for (const Plan& pl : plans_)
      if (pl.moved != kInvalidNode) moves += apply(pl);
    return moves;
  }

  void notify_move() const {
    if (after_move_) (*after_move_)(bvh_, cost());
  }

  double measure(uint32_t i) const {
    // Relative to the root's area, so that the float keys of select() neither overflow nor
    // depend on the scene's scale.
    const BvhNode& n = bvh_[i];
    const double a = n.area() / root_area_;
    // The default measure needs the node alone: its children, two cache misses in a scan of
    // every inner node each pass, are read only for the others.
    if (config_.measure == InsertionMeasure::area) return a;
    const double la = bvh_[n.left()].area() / root_area_, ra = bvh_[n.right()].area() / root_area_;
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
    if (bvh_[b].area() > bvh_[a].area()) std::swap(a, b);
    return {a, b};
  }

  // Refits from `n` up, adding each area change to the tracked sum (Bvh::refit_upwards,
  // saving each node before it changes).
  void refit_up(uint32_t n) {
    for (; n != kInvalidNode; n = bvh_[n].parent) {
      BvhNode& nd = bvh_[n];
      const Box b = merge(bvh_[nd.left()].box, bvh_[nd.right()].box);
      if (b == nd.box) return;
      undo_.save(bvh_, n);
      const double old_area = nd.area();
      nd.set_box(b);
      inner_area_ += nd.area() - old_area;
    }
  }
  void save(uint32_t n) {
    if (n != kInvalidNode) undo_.save(bvh_, n);
  }

  // Figure 3: N and its parent P leave the tree, N's sibling takes P's place.
  void remove(uint32_t n) { detach(n, bvh_[n].area()); }

  // Figure 5: `free_node` becomes the parent of X and L, in X's old place.
  void insert(uint32_t l, uint32_t x, uint32_t free_node) {
    const uint32_t q = bvh_[x].parent;
    for (uint32_t v : {free_node, q, x, l}) save(v);
    BvhNode& f = bvh_[free_node];
    f.make_inner(x, l);
    f.parent = q;
    f.set_box(merge(bvh_[x].box, bvh_[l].box));
    inner_area_ += f.area();
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
      const double delta = c.cost - (freed - bvh_[m].area());
      if (delta < best.delta) best = {m, c.node, delta};
    }
    return best;
  }

  bool is_touched(uint32_t n) const { return n != kInvalidNode && touched_.contains(n); }
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
    for (uint32_t v : {m, p, s, g}) save(v);
    inner_area_ -= also_removed + bvh_[p].area();
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
        if (v != kInvalidNode) bvh_.refit_upwards(v, Bvh::RefitScope::to_root);
      inner_area_ = saved_area;
      notify_move();
      return 0;
    }
    for (uint32_t v : involved)
      if (v != kInvalidNode) touched_.insert(v);
    notify_move();
    return 1;
  }

  Bvh& bvh_;
  const InsertionConfig& config_;
  const bool parallel_;
  const testing::AfterMove* after_move_;  // may be null
  bool random_ = false;                   // selection has turned random for the rest of the stage
  uint32_t without_improvement_ = 0;      // passes since the last one that counted as progress
  std::vector<uint32_t> candidates_;
  double inner_area_ = 0.0;
  double leaf_term_ = 0.0;
  double root_area_ = 0.0;
  std::vector<detail::SearchEntry> heap_;
  std::vector<uint32_t> path_;
  size_t inner_count_ = 0;
  std::vector<uint64_t> keys_;
  detail::LargestKeys largest_;
  std::vector<Plan> plans_;
  detail::NodeSet touched_;  // nodes a move of this parallel pass changed
  detail::UndoLog undo_;

  double leaf_cost(double area, uint32_t count) const { return config_.cost.intersection * area * count; }
};

// The stages of each form: false for a sequential stage, true for a parallel one.
std::vector<bool> stages_of(InsertionForm form) {
  switch (form) {
    case InsertionForm::sequential: return {false};
    case InsertionForm::parallel: return {true};
    case InsertionForm::hybrid: return {false, true};
  }
  return {false, true};
}

OptimizeReport run_insertion(Bvh& bvh, const InsertionConfig& config, const testing::AfterMove* after_move) {
  detail::PassDriver driver(config.limits);
  if (bvh.empty()) {
    driver.stop(StopReason::empty_tree);
    return driver.finish();
  }
  // Numbering every reachable node densely lets a pass scan the node array for inner
  // nodes; the refit makes every box exactly the union of its children, which undoing a
  // parallel move relies on.
  bvh.renumber_depth_first();
  // Depth-first numbers put every child after its parent: refit from the last node back.
  for (size_t i = bvh.nodes.size(); i-- > 0;)
    if (!bvh.nodes[i].is_leaf()) bvh.refit_node(static_cast<uint32_t>(i));
  {
    InsertionOptimizer probe(bvh, config, false, after_move);
    // A zero-area root has no ratio to track: its cost is the limit sah_cost defines, as
    // every optimizer reports it.
    driver.set_initial_cost(probe.can_optimize() ? probe.cost() : sah_cost(bvh, config.cost));
    if (!probe.can_optimize()) {
      driver.stop(StopReason::nothing_to_optimize);
      return driver.finish();
    }
  }
  {
    const detail::HugePageBacking huge_pages(bvh.nodes);
    for (bool parallel : stages_of(config.form)) {
      // Each stage starts afresh from the tree the last one left (its tracked sums included).
      InsertionOptimizer stage(bvh, config, parallel, after_move);
      driver.run(stage);
      if (driver.stop_reason() != StopReason::converged) break;
    }
  }
  bvh.renumber_depth_first();
  return driver.finish();
}

}  // namespace

OptimizeReport optimize_insertion(Bvh& bvh, const InsertionConfig& config) { return run_insertion(bvh, config, nullptr); }

OptimizeReport testing::optimize_insertion_observed(Bvh& bvh, const InsertionConfig& config,
                                                    const AfterMove& after_move) {
  return run_insertion(bvh, config, &after_move);
}

}  // namespace bvhopt
