#include "bvhopt/insertion_optimizer.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "bvhopt/random_stream.h"
#include "bvhopt/testing/insertion_hooks.h"
#include "bvhopt/tree_rotations.h"
#include "optimize/find_by_name.h"
#include "optimize/in_subtree.h"
#include "optimize/largest_from_root.h"
#include "optimize/largest_keys.h"
#include "optimize/near_moves.h"
#include "optimize/pass_driver.h"
#include "optimize/rank_windows.h"
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
    case InsertionForm::regional: return "regional";
  }
  return "hybrid";
}

std::vector<InsertionForm> insertion_forms() {
  return {InsertionForm::sequential, InsertionForm::parallel, InsertionForm::hybrid, InsertionForm::regional};
}

InsertionForm resolved_form(InsertionForm form, size_t node_count) {
  return form == InsertionForm::hybrid && node_count >= kRegionalFrom ? InsertionForm::regional : form;
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
  std::vector<detail::AncestorLink> chain;
  std::vector<detail::ShrunkArea> shrunk;
  detail::ancestors_of(bvh, bvh[n].parent, chain);
  return detail::search_reinsertion_after_removal(bvh, box, n, chain, heap, shrunk, freed_area);
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

// How a stage's passes update their candidates: one after another over the whole tree (the
// paper's), one after another within each of many disjoint subtrees at once (regional), or
// planned all at once and applied in order (parallel). Or, with no candidates, a sweep of
// Kensler's rotations over every inner node (rotation).
enum class PassKind { sequential, regional, parallel, rotation };

// One stage: its passes, and whether it ends where selection by the measure stalls (leaving
// the random passes to the next stage) rather than by the paper's rule.
struct Stage {
  PassKind kind;
  bool until_measure_stalls = false;
  // A cap on the passes without progress that end the stage: on the config's random_after
  // for a stage that ends where the measure stalls, else on its stop_after.
  uint32_t max_stalls = std::numeric_limits<uint32_t>::max();
  // The least gain of a pass, as a fraction of the cost, that counts as progress, when more
  // than the config's min_improvement (a stage ending where the measure stalls asks for the
  // hand-over's 0.03 % whatever this says).
  double min_gain = 0.0;
  // Selection by the measure in this many windows of its ranking (detail::RankWindows), not
  // the k largest on every pass; 0: the paper's. Random passes select as ever.
  uint32_t rank_windows = 0;
  detail::RankWindows::Order window_order = detail::RankWindows::Order::ruler;
  // A sequential stage's passes in windows below the top run as regional passes.
  bool regional_below_top_window = false;
};

// One stage of the optimizer (one form) over the tree, and its passes for the pass driver.
class InsertionOptimizer {
 public:
  // `from_root` is shared by the stages of a run: the thresholds it keeps hold from one stage
  // to the next, so only the run's first selection of each size walks best first.
  InsertionOptimizer(Bvh& bvh, const InsertionConfig& config, Stage stage, const testing::AfterMove* after_move,
                     detail::LargestFromRoot& from_root)
      : bvh_(bvh),
        config_(config),
        stage_(stage),
        after_move_(after_move),
        windows_(stage.window_order, stage.rank_windows),
        from_root_(from_root) {
    inner_.reset(bvh_.nodes.size());
    for (uint32_t i = 0; i < bvh_.nodes.size(); ++i) {
      const BvhNode& n = bvh_.nodes[i];
      if (n.is_leaf()) {
        leaf_term_ += leaf_cost(n.area(), n.ref_count());
      } else {
        inner_area_ += n.area();
        inner_.insert(i);
        ++inner_count_;
      }
    }
    root_area_ = bvh_[bvh_.root].area();
  }

  double cost() const { return (config_.cost.traversal * inner_area_ + leaf_term_) / root_area_; }

  bool can_optimize() const { return root_area_ > 0.0 && bvh_.nodes.size() >= 5; }

  // The sequential and regional forms can raise the cost (both children are out at once)
  // and oscillate near the end, so they keep the best tree they have seen. The parallel
  // passes and the rotation sweeps never raise it.
  bool keep_best_before(uint32_t /*pass*/) const {
    return stage_.kind == PassKind::sequential || stage_.kind == PassKind::regional;
  }
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
    // measure after a good random pass would only retry the nodes that just stalled. A
    // regional stage without windows selects at random from the start: it follows a stage
    // that ended where the measure's top stalled. With windows it reaches below that top.
    random_ = random_ || without_improvement_ >= config_.random_after ||
              (stage_.kind == PassKind::regional && stage_.rank_windows == 0);
    if (stage_.kind != PassKind::rotation) select(pass + 1, random_, candidates_);
    uint64_t moves = 0;
    if (stage_.kind == PassKind::rotation) {
      moves = pass_rotations();
    } else if (stage_.kind == PassKind::parallel) {
      moves = pass_parallel(candidates_);
    } else if (stage_.kind == PassKind::regional ||
               (stage_.regional_below_top_window && selected_window_ > 0)) {
      moves = pass_regional();
    } else {
      Scope whole = whole_tree();
      for (size_t i = 0; i < candidates_.size(); ++i) {
        prefetch_ahead(candidates_, i);
        moves += update_sequential(candidates_[i], whole);
        if (undo_.size() >= undo_limit() && !stay_within_log()) break;
      }
    }
    const double c = cost();
    // A relative margin, so that rounding noise in an oscillating tail or the endless tiny
    // gains of the parallel form never count as progress.
    // A stage that hands over to a faster one asks more of a pass: at 0.03 %, on the hall at
    // 1M and 4M triangles, its last slow passes go to the next stage (a better tree from
    // 1.5 build times on), and the converged cost is within the spread of the seed.
    constexpr double kHandOverImprovement = 3e-4;
    const double min_improvement =
        std::max(config_.min_improvement, stage_.until_measure_stalls ? kHandOverImprovement : stage_.min_gain);
    if (c < stage_best * (1.0 - min_improvement))
      without_improvement_ = 0;
    else
      ++without_improvement_;
    const uint32_t patience =
        std::min(stage_.max_stalls, stage_.until_measure_stalls ? config_.random_after : config_.stop_after);
    return {c, moves, 0.0, without_improvement_ >= patience};
  }

 private:
  // Where an update's changes go: the tracked sum of inner areas it changes, the undo lane
  // its records go to (null: the log itself), and the node below which its refits stop and
  // its searches stay (kInvalidNode: the whole tree). Plus its search scratch.
  struct Scratch {
    std::vector<detail::SearchEntry> heap;
    std::vector<uint32_t> path;
    std::vector<uint64_t> sweep;  // a rotation sweep's stack
  };
  struct Scope {
    double* area;
    detail::UndoLog::Lane* lane;
    uint32_t top;
    Scratch* scratch;
  };
  Scope whole_tree() { return {&inner_area_, nullptr, kInvalidNode, &scratch_}; }

  // The undo log holds at most one record per sixteenth of the nodes (2.5 bytes a node,
  // where a copy of the tree took 36; it keeps the optimizer under 100 bytes a triangle): a
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
  void prefetch_ahead(const std::vector<uint32_t>& list, size_t i) const {
    constexpr size_t kNodeAhead = 8, kLinksAhead = 4;
    const BvhNode* nodes = bvh_.nodes.data();
    if (i + kNodeAhead < list.size()) detail::prefetch_node(nodes, list[i + kNodeAhead]);
    if (i + kLinksAhead < list.size()) {
      const BvhNode& c = nodes[list[i + kLinksAhead]];
      if (c.is_leaf()) return;
      detail::prefetch_children(nodes, c);
      if (c.parent != kInvalidNode) detail::prefetch_node(nodes, c.parent);
    }
  }

  // Candidates of one pass: the k inner non-root nodes with the largest measure, largest
  // first, or the stage's next window of that ranking, or k random ones.
  void select(uint32_t pass, bool random, std::vector<uint32_t>& out) {
    out.clear();
    selected_window_ = 0;
    if (inner_count_ == 0) return;
    const size_t k = std::clamp<size_t>(static_cast<size_t>(std::ceil(config_.batch * inner_count_)), 1, inner_count_);
    if (random) {
      // A parallel pass first takes the nodes around the last pass's moves, where a move is
      // three to five times likelier than at a random node (near_moves.h). The moves were
      // applied in candidate order, so these do not depend on the thread count.
      if (stage_.kind == PassKind::parallel) detail::append_near_moves(bvh_, touched_.members(), inner_, k, near_, out);
      // Then uniform over the inner nodes without a list of them: draws that hit a leaf are
      // redrawn, judged by the set of inner nodes, not by the node (a cache miss at 4M).
      RandomStream rng{config_.seed * kGoldenGamma + pass};
      const uint32_t count = static_cast<uint32_t>(bvh_.nodes.size());
      while (out.size() < k) {
        uint32_t n = rng.below(count);
        while (!inner_.contains(n)) n = rng.below(count);
        out.push_back(n);
      }
      return;
    }
    if (stage_.rank_windows == 0) {
      rank(k, out);
    } else {
      const auto is_inner = [&](size_t i) { return !bvh_.nodes[i].is_leaf(); };
      const auto key_of = [&](size_t i) { return key(static_cast<uint32_t>(i)); };
      windows_.next(
          k, [&](size_t n, std::vector<uint32_t>& ids) { rank(std::min(n, inner_count_), ids); },
          [&](uint32_t count, size_t kk, std::vector<uint32_t>& ids, std::vector<size_t>& starts) {
            detail::partition_into_windows(bvh_.nodes.size(), kk, count, is_inner, key_of, ids, starts);
          },
          out);
      selected_window_ = windows_.last_window();
    }
    std::erase(out, bvh_.root);
  }

  // The ids of the k inner nodes with the largest measure, largest first, in `ids`.
  void rank(size_t k, std::vector<uint32_t>& ids) {
    const auto key_of = [&](size_t i) { return key(static_cast<uint32_t>(i)); };
    // Areas never grow from a node to its children: the largest are found from the root
    // down, without reading the whole array. The same keys either way.
    const bool from_root = config_.measure == InsertionMeasure::area &&
                           detail::LargestFromRoot::pays(bvh_.nodes.size(), k) &&
                           from_root_.largest(bvh_, k, key_of, keys_);
    if (!from_root)
      largest_.largest(bvh_.nodes.size(), k, [&](size_t i) { return !bvh_.nodes[i].is_leaf(); }, key_of, keys_);
    ids.clear();
    for (uint64_t kk : keys_) ids.push_back(0xffffffffu - static_cast<uint32_t>(kk));
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
  // In a region (sc.top), N and P must lie strictly inside it, and the children go back
  // inside it: its root keeps its leaves, hence its box, and nothing above it changes.
  uint64_t update_sequential(uint32_t n, Scope& sc) {
    if (n == bvh_.root || bvh_[n].is_leaf()) return 0;
    auto [a, b] = ordered_children(n);
    const uint32_t p = bvh_[n].parent;
    const uint32_t s = bvh_.sibling(n);
    remove(n, sc);
    // Both searches start from N's sibling, which took P's place: the children's old
    // neighbourhood, usually close to their best place, so the bound prunes from the start.
    insert(a, search_from(a, s, sc), n, sc);
    insert(b, search_from(b, s, sc), p, sc);
    if (sc.lane == nullptr) notify_move();
    return 1;
  }

  // The best place for subtree m (out of the tree) by the full search, seeded with `start`.
  // Its cost is taken from start's nearby ancestors only (placement_cost_near): walking them
  // all to the root was a quarter of the update's own time at 1M triangles.
  // In a region, start's ancestors are walked no higher than the region's root: its box
  // contains m's, whose leaves it held.
  uint32_t search_from(uint32_t m, uint32_t start, Scope& sc) {
    const Box& box = bvh_[m].box;
    const ReinsertionCandidate seed{start, detail::placement_cost_near(bvh_, box, start, sc.scratch->path)};
    return detail::search_reinsertion(bvh_, box, kInvalidNode, sc.top, sc.scratch->heap, seed, sc.top).node;
  }

  // The regional pass: the paper's random selection and sequential updates, in many
  // disjoint subtrees (regions: the tree cut at a fixed depth) at once. A candidate whose
  // node and parent lie strictly inside a region is updated there, in candidate order among
  // the region's, its children searched for and put back only inside the region: the
  // region's root keeps its leaves, hence its box, and nothing outside the region changes.
  // Each region has its own undo lane and area change, gathered and added in region order:
  // the tree and its tracked cost do not depend on the thread count. The few candidates at
  // or above the cut follow, one by one over the whole tree.
  //
  // Why it is worth it: once selection is random, 99.9 % of the paper's sequential updates
  // put both children back inside the region they came from (hall 1M, measured), so the
  // restriction changes few outcomes while the updates spread over the threads.
  uint64_t pass_regional() {
    // The lanes write into the log's free room, shared by their numbers of candidates. A log
    // too full for another pass first moves its restore point (or goes back to it).
    constexpr size_t kRecordsPerUpdate = 8;  // measured: about 7
    if (undo_.active() && undo_.size() + kRecordsPerUpdate * candidates_.size() > undo_.capacity()) stay_within_log();
    cut_regions();
    region_of_.resize(candidates_.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, candidates_.size(), 256),
                      [&](const tbb::blocked_range<size_t>& r) { find_regions(r.begin(), r.end()); });
    const size_t regions = region_roots_.size();
    region_lists_.resize(regions);
    for (auto& l : region_lists_) l.clear();
    for (size_t i = 0; i < candidates_.size(); ++i)
      if (region_of_[i] != kInvalidNode) region_lists_[region_of_[i]].push_back(candidates_[i]);
    lane_weights_.resize(regions);
    for (size_t j = 0; j < regions; ++j) lane_weights_[j] = region_lists_[j].size();
    undo_.open_lanes(lane_weights_, lanes_);
    region_area_.assign(regions, 0.0);
    region_moves_.assign(regions, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, regions, 1), [&](const tbb::blocked_range<size_t>& r) {
      Scratch& scratch = region_scratch_.local();
      for (size_t j = r.begin(); j < r.end(); ++j) {
        const uint32_t root = region_roots_[j];
        Scope sc{&region_area_[j], &lanes_[j], root, &scratch};
        const std::vector<uint32_t>& list = region_lists_[j];
        for (size_t i = 0; i < list.size(); ++i) {
          prefetch_ahead(list, i);
          // Earlier updates of the region may have made the candidate a child of its root.
          if (bvh_[list[i]].parent == root) continue;
          region_moves_[j] += update_sequential(list[i], sc);
        }
      }
    });
    undo_.close_lanes(lanes_);
    uint64_t moves = 0;
    for (size_t j = 0; j < regions; ++j) {
      inner_area_ += region_area_[j];
      moves += region_moves_[j];
    }
    notify_move();
    if (undo_.size() >= undo_limit() && !stay_within_log()) return moves;
    Scope whole = whole_tree();
    for (size_t i = 0; i < candidates_.size(); ++i) {
      if (region_of_[i] != kInvalidNode) continue;
      moves += update_sequential(candidates_[i], whole);
      if (undo_.size() >= undo_limit() && !stay_within_log()) break;
    }
    return moves;
  }

  // A sweep of Kensler's hill climbing: at every inner node, once its subtree is done, the
  // one of the six child/grandchild swaps that most lowers the sum of its two children's
  // areas, if any does. A swap keeps the node's leaves, hence its box and everything above
  // it, so the regions are swept at once, each bottom-up, and then the nodes above them;
  // each region's area change is added in region order: the tree and its tracked cost do
  // not depend on the thread count.
  //
  // Why: the insertion passes leave many small local improvements that a swap makes at
  // once. On the hall at 1M triangles, the first sweep after the sequential stage took the
  // cost from 264.1 to 261.9 in about 30 ms on 2 threads, where a regional pass of 15 ms
  // gains about 0.15 (docs/optimization-at-scale.md).
  uint64_t pass_rotations() {
    cut_regions();
    const size_t regions = region_roots_.size();
    region_area_.assign(regions, 0.0);
    region_moves_.assign(regions, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, regions, 1), [&](const tbb::blocked_range<size_t>& r) {
      Scratch& scratch = region_scratch_.local();
      for (size_t j = r.begin(); j < r.end(); ++j)
        region_moves_[j] = rotate_subtree(region_roots_[j], false, region_area_[j], scratch.sweep);
    });
    uint64_t moves = 0;
    for (size_t j = 0; j < regions; ++j) {
      inner_area_ += region_area_[j];
      moves += region_moves_[j];
    }
    moves += rotate_subtree(bvh_.root, true, inner_area_, scratch_.sweep);
    notify_move();
    return moves;
  }

  // Post-order from `top`, each inner node swept after its children; with `above_cut`, only
  // the nodes above the regions' roots. `stack` is scratch.
  uint64_t rotate_subtree(uint32_t top, bool above_cut, double& area, std::vector<uint64_t>& stack) {
    constexpr uint64_t kChildrenDone = uint64_t{1} << 32;  // beside the node's id
    uint64_t moves = 0;
    stack.assign(1, top);
    while (!stack.empty()) {
      const uint64_t e = stack.back();
      stack.pop_back();
      const uint32_t v = static_cast<uint32_t>(e);
      if (e & kChildrenDone) {
        moves += rotate_at(v, area);
        continue;
      }
      const BvhNode& nd = bvh_[v];
      if (nd.is_leaf() || (above_cut && cut_.contains(v))) continue;
      stack.push_back(v | kChildrenDone);
      stack.push_back(nd.right());
      stack.push_back(nd.left());
    }
    return moves;
  }

  // The best swap at s, in the Rotation order (the first of equal gains), if it lowers the
  // children's area sum; its change is added to `area`. The deltas are rotation_cost_delta's
  // (c_T = 1), summed in its order, from the four boxes read once: through that function,
  // which plans each move from the nodes again, a stage of sweeps took 136 ms instead of 105
  // (hall 1M, the same moves).
  uint64_t rotate_at(uint32_t s, double& area) {
    const uint32_t l = bvh_[s].left(), r = bvh_[s].right();
    const BvhNode& L = bvh_[l];
    const BvhNode& R = bvh_[r];
    const bool left_inner = !L.is_leaf(), right_inner = !R.is_leaf();
    if (!left_inner && !right_inner) return 0;
    const double al = L.area(), ar = R.area();
    double best = 0.0;
    int best_move = -1;
    auto consider = [&](Rotation m, double delta) {
      if (delta < best) {
        best = delta;
        best_move = static_cast<int>(m);
      }
    };
    if (right_inner) {
      const Box& rl = bvh_[R.left()].box;
      const Box& rr = bvh_[R.right()].box;
      consider(Rotation::left_with_right_left, double(merge(L.box, rr).area()) - ar);
      consider(Rotation::left_with_right_right, double(merge(rl, L.box).area()) - ar);
    }
    if (left_inner) {
      const Box& ll = bvh_[L.left()].box;
      const Box& lr = bvh_[L.right()].box;
      consider(Rotation::right_with_left_left, double(merge(R.box, lr).area()) - al);
      consider(Rotation::right_with_left_right, double(merge(ll, R.box).area()) - al);
      if (right_inner) {
        const Box& rl = bvh_[R.left()].box;
        const Box& rr = bvh_[R.right()].box;
        consider(Rotation::left_left_with_right_left,
                 (double(merge(rl, lr).area()) + double(merge(ll, rr).area())) - (al + ar));
        consider(Rotation::left_left_with_right_right,
                 (double(merge(rr, lr).area()) + double(merge(rl, ll).area())) - (al + ar));
      }
    }
    if (best_move < 0) return 0;
    apply_rotation(bvh_, s, static_cast<Rotation>(best_move));
    // The changed children's areas as refitted: what a recount of the tree sums.
    area += (bvh_[l].area() - al) + (bvh_[r].area() - ar);
    return 1;
  }

  // The regions: the inner nodes at depth region_depth(), in depth-first order.
  void cut_regions() {
    const uint32_t depth = region_depth();
    region_roots_.clear();
    cut_.reset(bvh_.nodes.size());
    cut_stack_.assign(1, {bvh_.root, 0});
    while (!cut_stack_.empty()) {
      const auto [v, d] = cut_stack_.back();
      cut_stack_.pop_back();
      const BvhNode& nd = bvh_[v];
      if (nd.is_leaf()) continue;
      if (d == depth) {
        region_roots_.push_back(v);
        cut_.insert(v);
        continue;
      }
      cut_stack_.push_back({nd.right(), d + 1});
      cut_stack_.push_back({nd.left(), d + 1});
    }
    root_index_.resize(region_roots_.size());
    for (uint32_t j = 0; j < region_roots_.size(); ++j) root_index_[j] = {region_roots_[j], j};
    std::sort(root_index_.begin(), root_index_.end());
  }

  // region_of_[i] for candidates [begin, end): the region whose root lies strictly above the
  // candidate and its parent, or kInvalidNode. Each is a walk up the tree, a chain of cache
  // misses (a tenth of the run at 1M triangles when walked one by one), so kWalks of them
  // advance in turn, each asking for its next node before the others take their step.
  void find_regions(size_t begin, size_t end) {
    constexpr size_t kWalks = 16;
    const BvhNode* nodes = bvh_.nodes.data();
    struct Walk {
      size_t i;
      uint32_t at;
    };
    Walk walks[kWalks];
    size_t active = 0, next = begin;
    auto finish = [&](size_t i, uint32_t root) {
      region_of_[i] = root == kInvalidNode ? kInvalidNode
                                           : std::lower_bound(root_index_.begin(), root_index_.end(),
                                                              std::pair<uint32_t, uint32_t>{root, 0})
                                                 ->second;
    };
    while (active > 0 || next < end) {
      // Start walks: at the candidate's parent (a candidate on the cut, or whose parent is,
      // stays out of the regions).
      while (active < kWalks && next < end) {
        const size_t i = next++;
        const uint32_t n = candidates_[i];
        const uint32_t p = nodes[n].parent;
        if (cut_.contains(n) || p == kInvalidNode || cut_.contains(p)) {
          region_of_[i] = kInvalidNode;
          continue;
        }
        detail::prefetch_node(nodes, p);
        walks[active++] = {i, p};
      }
      for (size_t w = 0; w < active;) {
        const uint32_t up = nodes[walks[w].at].parent;
        if (up == kInvalidNode || cut_.contains(up)) {
          finish(walks[w].i, up);
          walks[w] = walks[--active];
          continue;
        }
        detail::prefetch_node(nodes, up);
        walks[w++].at = up;
      }
    }
  }

  // About 32k nodes a region, and at least four regions. The count depends on the tree
  // alone, never on the threads. Smaller regions restrict more moves (measured at 1M
  // triangles: 16k nodes end 0.03 % higher, 64k 0.03 % lower, at the same speed); larger
  // ones would leave many-core machines few regions to share.
  uint32_t region_depth() const {
    const double regions = static_cast<double>(bvh_.nodes.size()) / 32768.0;
    return std::clamp<uint32_t>(static_cast<uint32_t>(std::ceil(std::log2(std::max(regions, 1.0)))), 2, 16);
  }

  // by_id_: the candidates' indices in the order of their ids, to a few thousand ids. Ids
  // follow the tree's depth-first order closely (a move reuses the ids it frees, near where
  // they were), so work done in that order walks the same ancestors and neighbourhoods while
  // they are in cache: a parallel pass at 4M triangles took 52 ms instead of 73. Buckets of
  // ids are as local as a full order and take one counting pass (a sort of the 40k
  // candidates at 4M took a tenth of a first-stage pass).
  void order_by_id(const std::vector<uint32_t>& candidates) {
    constexpr unsigned kBucketBits = 12;
    const unsigned id_bits = std::bit_width(bvh_.nodes.size());
    const unsigned shift = id_bits > kBucketBits ? id_bits - kBucketBits : 0;
    bucket_start_.assign((size_t{1} << kBucketBits) + 1, 0);
    for (uint32_t c : candidates) ++bucket_start_[(c >> shift) + 1];
    for (size_t b = 1; b < bucket_start_.size(); ++b) bucket_start_[b] += bucket_start_[b - 1];
    by_id_.resize(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i)
      by_id_[bucket_start_[candidates[i] >> shift]++] = static_cast<uint32_t>(i);
  }

  // Meister-Bittner style: search every candidate against the current tree on all threads,
  // then apply in candidate order.
  uint64_t pass_parallel(const std::vector<uint32_t>& candidates) {
    plans_.assign(candidates.size(), Plan{});
    // Planned in the order of the candidates' ids (order_by_id); each plan reads the tree as
    // the pass found it, so the plans are the same in any order.
    order_by_id(candidates);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, candidates.size(), kPlanWalks),
                      [&](const tbb::blocked_range<size_t>& r) {
                        PlanScratch scratch;
                        for (size_t j = r.begin(); j < r.end(); j += kPlanWalks)
                          plan_group(candidates, j, std::min(r.end(), j + kPlanWalks), scratch);
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
  // saving each node before it changes). In a region it stops below the region's root, whose
  // box is stale only while both children of an update are out.
  void refit_up(uint32_t n, Scope& sc) {
    for (; n != sc.top; n = bvh_[n].parent) {
      BvhNode& nd = bvh_[n];
      const Box b = merge(bvh_[nd.left()].box, bvh_[nd.right()].box);
      if (b == nd.box) return;
      save(n, sc);
      const double old_area = nd.area();
      nd.set_box(b);
      *sc.area += nd.area() - old_area;
    }
  }
  void save(uint32_t n, Scope& sc) {
    if (n == kInvalidNode) return;
    if (sc.lane)
      undo_.save(bvh_, n, *sc.lane);
    else
      undo_.save(bvh_, n);
  }

  // Figure 3: N and its parent P leave the tree, N's sibling takes P's place.
  void remove(uint32_t n, Scope& sc) { detach(n, sc, bvh_[n].area()); }

  // Figure 5: `free_node` becomes the parent of X and L, in X's old place.
  void insert(uint32_t l, uint32_t x, uint32_t free_node, Scope& sc) {
    const uint32_t q = bvh_[x].parent;
    for (uint32_t v : {free_node, q, x, l}) save(v, sc);
    BvhNode& f = bvh_[free_node];
    f.make_inner(x, l);
    f.parent = q;
    f.set_box(merge(bvh_[x].box, bvh_[l].box));
    *sc.area += f.area();
    if (q == kInvalidNode)
      bvh_.root = free_node;
    else
      bvh_[q].set_child(bvh_.child_slot(x), free_node);
    bvh_[x].parent = free_node;
    bvh_[l].parent = free_node;
    if (q != kInvalidNode) refit_up(q, sc);
  }

  // The plans of candidates by_id_[begin, end) (at most kPlanWalks). Each starts with a walk
  // up to the root, a chain of cache misses (25 ancestors at 4M triangles, the lower ones out
  // of every cache), so their walks go first, in turn, each asking for its next node before
  // the others take their step. A polish pass took 47-48 ms at 4M triangles instead of
  // 58-59 (1M: 10.2-10.7 against 12.6-13.4); 4 walks at once gained less, 16 no more, and
  // the searches' pops taken in turn too (a state per search) a little less.
  static constexpr size_t kPlanWalks = 8;
  struct PlanScratch {
    std::vector<detail::SearchEntry> heap;
    std::vector<detail::ShrunkArea> shrunk;
    std::vector<detail::AncestorLink> chains[kPlanWalks];
  };
  void plan_group(const std::vector<uint32_t>& candidates, size_t begin, size_t end, PlanScratch& sc) {
    const BvhNode* nodes = bvh_.nodes.data();
    const size_t count = end - begin;
    struct Walk {
      uint32_t from, at;
    };
    Walk walks[kPlanWalks];
    bool walking = false;
    for (size_t w = 0; w < count; ++w) {
      const uint32_t n = candidates[by_id_[begin + w]];
      sc.chains[w].clear();
      // The root and leaves have no plan; every other node has a parent.
      const bool plans = n != bvh_.root && !nodes[n].is_leaf();
      walks[w] = {n, plans ? nodes[n].parent : kInvalidNode};
      if (plans) {
        detail::prefetch_node(nodes, walks[w].at);
        detail::prefetch_children(nodes, nodes[n]);
        walking = true;
      }
    }
    // The links ancestors_of gives, found for all the group's candidates in turn.
    while (walking) {
      walking = false;
      for (size_t w = 0; w < count; ++w) {
        Walk& k = walks[w];
        if (k.at == kInvalidNode) continue;
        const BvhNode& a = nodes[k.at];
        const uint32_t off = a.left() == k.from ? a.right() : a.left();
        sc.chains[w].push_back({k.at, off});
        detail::prefetch_node(nodes, off);
        k.from = k.at;
        k.at = a.parent;
        if (k.at != kInvalidNode) {
          detail::prefetch_node(nodes, k.at);
          walking = true;
        }
      }
    }
    // Each search starts at the candidate's other child, whose children it reads next.
    for (size_t w = 0; w < count; ++w) {
      if (sc.chains[w].empty()) continue;
      const BvhNode& n = nodes[candidates[by_id_[begin + w]]];
      for (int side = 0; side < 2; ++side)
        if (!nodes[n.child(side)].is_leaf()) detail::prefetch_children(nodes, nodes[n.child(side)]);
    }
    for (size_t w = 0; w < count; ++w) {
      const size_t i = by_id_[begin + w];
      plans_[i] = sc.chains[w].empty() ? Plan{} : plan(candidates[i], sc.chains[w], sc);
    }
  }

  // The parallel form moves one subtree at a time (as Meister and Bittner do), so every
  // plan's gain is exact against the tree it saw: of candidate N's two children, the one
  // whose best move gains more. `chain`: N's ancestors (ancestors_of), which both children's
  // searches walk.
  Plan plan(uint32_t n, const std::vector<detail::AncestorLink>& chain, PlanScratch& sc) const {
    Plan best;
    for (int side = 0; side < 2; ++side) {
      const uint32_t m = bvh_[n].child(side);
      double freed = 0.0;
      ReinsertionCandidate c =
          detail::search_reinsertion_after_removal(bvh_, bvh_[m].box, m, chain, sc.heap, sc.shrunk, &freed);
      if (c.node == kInvalidNode) continue;
      // The search counts m's own area as freed; m stays a subtree, only its parent is freed.
      const double delta = c.cost - (freed - bvh_[m].area());
      if (delta < best.delta) best = {m, c.node, delta};
    }
    return best;
  }

  bool is_touched(uint32_t n) const { return n != kInvalidNode && touched_.contains(n); }

  // Takes `m` and its parent out (the parent becomes free, the sibling takes its place);
  // m keeps its subtree.
  // `also_removed`: the area of m itself when m leaves the tree's inner nodes too (remove).
  uint32_t detach(uint32_t m, Scope& sc, double also_removed = 0.0) {
    const uint32_t p = bvh_[m].parent;
    const uint32_t s = bvh_.sibling(m);
    const uint32_t g = bvh_[p].parent;
    for (uint32_t v : {m, p, s, g}) save(v, sc);
    *sc.area -= also_removed + bvh_[p].area();
    if (g == kInvalidNode) {
      bvh_.root = s;
      bvh_[s].parent = kInvalidNode;
    } else {
      bvh_[g].set_child(bvh_.child_slot(p), s);
      bvh_[s].parent = g;
      refit_up(g, sc);
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
    if (detail::in_subtree(bvh_, x, m)) return 0;

    BvhNode saved[6];
    for (int i = 0; i < 6; ++i)
      if (involved[i] != kInvalidNode) saved[i] = bvh_[involved[i]];
    const uint32_t saved_root = bvh_.root;
    const double saved_area = inner_area_;

    Scope whole = whole_tree();
    const uint32_t free_node = detach(m, whole);
    insert(m, x, free_node, whole);

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
  const Stage stage_;
  const testing::AfterMove* after_move_;  // may be null
  bool random_ = false;                   // selection has turned random for the rest of the stage
  detail::RankWindows windows_;           // the stage's windows of the ranking, if any
  uint32_t selected_window_ = 0;          // the window of this pass's candidates (0: the top)
  uint32_t without_improvement_ = 0;      // passes since the last one that counted as progress
  std::vector<uint32_t> candidates_;
  double inner_area_ = 0.0;
  double leaf_term_ = 0.0;
  double root_area_ = 0.0;
  Scratch scratch_;  // the whole tree's searches
  // Moves reuse the freed nodes as inner nodes, so the set of inner node ids never changes;
  // only which of them is the root does (the root is skipped when met).
  detail::NodeBits inner_;
  size_t inner_count_ = 0;
  std::vector<uint64_t> keys_;
  detail::LargestKeys largest_;
  detail::LargestFromRoot& from_root_;
  std::vector<Plan> plans_;
  std::vector<uint32_t> by_id_;         // the candidates' indices, by their ids' buckets
  std::vector<uint32_t> bucket_start_;  // order_by_id's counts
  detail::NodeSet touched_;  // nodes a move of this parallel pass changed
  detail::NodeSet near_;     // append_near_moves's scratch
  detail::UndoLog undo_;
  // The regional passes': the cut (region roots, by id too, and as a set), each candidate's
  // region, and each region's candidates, undo lane, area change and moves.
  std::vector<uint32_t> region_roots_;
  std::vector<std::pair<uint32_t, uint32_t>> root_index_;  // (root, region), by root
  std::vector<std::pair<uint32_t, uint32_t>> cut_stack_;
  detail::NodeSet cut_;
  std::vector<uint32_t> region_of_;
  std::vector<std::vector<uint32_t>> region_lists_;
  std::vector<detail::UndoLog::Lane> lanes_;
  std::vector<size_t> lane_weights_;
  std::vector<double> region_area_;
  std::vector<uint64_t> region_moves_;
  tbb::enumerable_thread_specific<Scratch> region_scratch_;

  double leaf_cost(double area, uint32_t count) const { return config_.cost.intersection * area * count; }
};

// A stage's name in the report: what its passes do.
std::string_view stage_name(const Stage& st) {
  switch (st.kind) {
    case PassKind::sequential: return "sequential";
    case PassKind::regional: return "regional";
    case PassKind::parallel: return "parallel";
    case PassKind::rotation: return "sweeps";
  }
  return "sequential";
}

// A stage of sweeps of rotations, until one gains less than a hand-over's 0.03 %.
Stage sweep_stage() { return {PassKind::rotation, true, 1}; }

// The stages of each form.
std::vector<Stage> stages_of(InsertionForm form, size_t node_count, bool rotations, bool parallel_start) {
  // The sequential stage hands over after two passes without progress, not five: by then its
  // passes by the measure only oscillate (hall 4M: five passes of 0.1 s each above the best
  // cost), while the regional passes after it gain about as much per pass in 0.06 s. Against
  // five, two runs each at 1M and 4M triangles (runs limited to 1x the build time: 1M
  // 260.9-261.1 against 261.3-261.5, 4M 367.87 against 369.3-370.6), lower within 5x too and
  // converged sooner (1M 7.1-7.2 s against 8.2-9.2, 4M 31.2-31.8 against 33.9-36.8), at
  // 252.26 against 252.12 and the same 354.59. One pass cut the stage at its first
  // oscillation (1M converged at 257.24); three landed between.
  //
  // Rotation sweeps follow the insertion stages of the default forms, each until a sweep gains
  // less than a hand-over's 0.03 %. After the sequential stage and after the regional one they
  // make at once what many random passes would; at the end they only lower the final tree. One
  // before the sequential stage instead led it to a worse tree (hall 1M: converged 254.36
  // against 252.26), so there is none there. With sweeps after it, the regional stage of a
  // large tree hands over once five passes in a row each gain less than 0.005 %, not after
  // the paper's ten without any gain: its slow tail is what the sweep then makes at once
  // (hall 4M: converged at 353.98 in 29.0 s, against 353.69 in 38.7 s; within 5x the build
  // time 355.20 against 357.12). A smaller tree, optimized in seconds, keeps the paper's rule:
  // with it --form regional ended lower on 7 of the 11 shared scenes (Conference 96.73
  // against 97.15).
  //
  // The regional form's sequential and regional stages select in windows of the measure's
  // ranking (detail::RankWindows), not the k largest or k random nodes. The sequential one
  // takes the top 8 % by the ruler, its top window's passes over the whole tree and its lower
  // ones' as regional passes (on all threads; below the top 1 %, a node's best place is
  // mostly near it); the regional one cycles over the top 32 %. bench/scale_bench, hall,
  // 2 threads, three runs (with the closing sweeps of run_insertion): within 1x the build
  // time 1M 255.72-255.76 and 4M 361.23-361.31, against 260.16-260.37 and 366.64-367.11
  // before (two runs); converged 251.79 in 3.7-4.2 s against 252.02 in 6.3-7.2 s, and
  // 353.35 in 18.6-20.7 s against 353.98 in 29.0-29.9 s. Ruled out, one or two runs each
  // within about 1x: windows in the parallel first stage (1M 260.78, 4M 366.7-368.6;
  // converged 1M 257.21), a sequential stage over the whole tree in every window (1M
  // 256.85-257.55, 4M 361.5-365.2) or in none (1M 260.6-262.0), windows in turn instead of
  // the ruler there (1M 259.8-262.4).
  const Stage sweep = sweep_stage();
  Stage sequential_passes{PassKind::sequential, true, 2};
  sequential_passes.rank_windows = 8;
  sequential_passes.window_order = detail::RankWindows::Order::ruler;
  sequential_passes.regional_below_top_window = true;
  Stage regional_passes{PassKind::regional};
  regional_passes.rank_windows = 32;
  regional_passes.window_order = detail::RankWindows::Order::cycle;
  if (rotations && node_count >= kRegionalFrom) {
    regional_passes.min_gain = 5e-5;
    regional_passes.max_stalls = 5;
  }
  std::vector<Stage> stages;
  auto then = [&](Stage st) {
    if (st.kind != PassKind::rotation || rotations) stages.push_back(st);
  };
  switch (resolved_form(form, node_count)) {
    case InsertionForm::sequential: return {{PassKind::sequential}};
    case InsertionForm::parallel: return {{PassKind::parallel}};
    case InsertionForm::regional:
      if (parallel_start) then({PassKind::parallel, true});
      then(sequential_passes);
      then(sweep);
      then(regional_passes);
      then(sweep);
      then({PassKind::parallel});
      then(sweep);
      return stages;
    case InsertionForm::hybrid: break;
  }
  then({PassKind::sequential});
  then({PassKind::parallel});
  then(sweep);
  return stages;
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
  const std::vector<Stage> stages = stages_of(config.form, bvh.nodes.size(), config.rotations, config.parallel_start);
  // Each stage starts afresh from the tree the last one left (its tracked sums included).
  // The first one also tells the initial cost: its sums are a scan of the whole array (4M
  // triangles: 67 ms), not worth making twice.
  detail::LargestFromRoot from_root;
  std::optional<InsertionOptimizer> stage(std::in_place, bvh, config, stages.front(), after_move, from_root);
  // A zero-area root has no ratio to track: its cost is the limit sah_cost defines, as
  // every optimizer reports it.
  driver.set_initial_cost(stage->can_optimize() ? stage->cost() : sah_cost(bvh, config.cost));
  if (!stage->can_optimize()) {
    driver.stop(StopReason::nothing_to_optimize);
    return driver.finish();
  }
  // The final renumbering's time, kept from a time budget. It moves every node to a
  // scattered place, and a node costs more the larger the tree (the caches and the TLB cover
  // less of it): on the hall, 2 threads, 43 ns a node at 1M triangles (2M nodes, 0.09 s),
  // 39-57 at 4M, 65 at 10M (1.3 s) and 110 at 50M (11.0 s). 65 ns times the cube root of
  // the nodes over 20M, at least 45, follows all four; a flat 65 ns had a bake at 50M end
  // 4 s past its 66 s budget.
  const double node_count = static_cast<double>(bvh.nodes.size());
  const double renumbering = node_count * std::max(45e-9, 65e-9 * std::cbrt(node_count / 20e6));
  // With a time budget, its end goes to sweeps of rotations: an insertion stage the budget
  // stops is followed by a closing stage of sweeps, and keeps time for two of them. The
  // first sweep after insertion passes makes at once much of what they leave undone (hall
  // 4M: 3.7 units in 0.09 s, where a pass before it gained 0.4 in 0.2 s), and a budget that
  // ended a stage before its sweeps lost that: the 4M hall within 3.6 s ended at 365.18 with
  // its sequential stage still gaining. A sweep took 9.5 ns a node at 4M triangles on 2
  // threads, 12-17 at 1M: 15 ns is kept on 2 threads, twice that on one.
  // (Only in the forms that sweep: the paper's sequential and parallel forms never do.)
  const bool closing_sweeps =
      config.limits.time_budget > 0.0 &&
      std::any_of(stages.begin(), stages.end(), [](const Stage& st) { return st.kind == PassKind::rotation; });
  const double sweep_seconds = node_count * 30e-9 / std::clamp(tbb::this_task_arena::max_concurrency(), 1, 2);
  // A stage of sweeps is never followed by the closing one: it keeps only the renumbering's.
  const auto reserve_for = [&](const Stage& st) {
    driver.reserve_for_finish(renumbering + (closing_sweeps && st.kind != PassKind::rotation ? 2.0 * sweep_seconds : 0.0));
  };
  {
    // The node array stays on the pages it has. It used to be collapsed into 2 MiB pages on
    // a thread of its own while the passes ran (MADV_COLLAPSE), for their TLB misses; once
    // a parallel pass's walks went several at a time (plan_group), that no longer paid back
    // the passes it stalled: converged without it, whole process, 0.93 at 4M triangles and
    // 0.95 at 1M (medians of six and eight pairs), 40.6 s against 44.9 at 10M (one pair).
    size_t k = 0;
    for (; k < stages.size(); ++k) {
      if (k > 0) stage.emplace(bvh, config, stages[k], after_move, from_root);
      reserve_for(stages[k]);
      driver.run(*stage, stage_name(stages[k]));
      if (driver.stop_reason() != StopReason::converged) break;
    }
    if (closing_sweeps && k < stages.size() && stages[k].kind != PassKind::rotation &&
        driver.stop_reason() == StopReason::time_limit) {
      driver.expect_first_pass(sweep_seconds);
      stage.emplace(bvh, config, sweep_stage(), after_move, from_root);
      reserve_for(sweep_stage());
      driver.run(*stage, stage_name(sweep_stage()));
      // A sweep that gains too little ends the stage; the run stopped for its budget.
      if (driver.stop_reason() == StopReason::converged) driver.stop(StopReason::time_limit);
    }
  }
  stage.reset();  // its undo log and scratch, before renumbering allocates its own
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
