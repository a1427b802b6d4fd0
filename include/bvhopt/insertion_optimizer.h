// Insertion-based optimization (Bittner, Hapala and Havran 2013): remove inefficient inner
// nodes and reinsert their children where they cost least, found by an exact branch and
// bound search over the whole tree.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "bvhopt/box.h"
#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/optimize_report.h"
#include "bvhopt/optimizer_config.h"

namespace bvhopt {

// Which inner nodes a pass updates first (section 2.4 and the extended paper).
enum class InsertionMeasure {
  area,  // M_AREA(N) = SA(N): the paper's choice, and the default
  sum,   // M_SUM(N) = SA(N) / ((SA(L) + SA(R)) / 2)
  min,   // M_MIN(N) = SA(N) / min(SA(L), SA(R))
  comb,  // M_COMB(N) = M_AREA * M_SUM * M_MIN
};

std::string_view measure_name(InsertionMeasure m);
// "area", "sum", "min", "comb"; nullopt for anything else.
std::optional<InsertionMeasure> parse_measure(std::string_view name);
// Every measure, in the order above.
std::vector<InsertionMeasure> insertion_measures();

// How the passes are run.
enum class InsertionForm {
  // The paper's form: one candidate at a time, both children removed and reinserted at the
  // best place in the tree as it then is. One thread. May raise the cost for a pass; the
  // best tree seen is kept.
  sequential,
  // Beyond the paper (after Meister and Bittner 2018): each pass finds, on all threads and
  // against the tree as it stands, the best single-subtree move of each candidate's two
  // children (the child and its parent out, the child back at the best place; the search
  // sees the tree as it would be after that removal, so the gain is exact), keeps the better
  // of the two if it gains, then applies the plans in candidate order, skipping a plan that
  // touches a node an earlier move of the pass changed and undoing one that raised the cost
  // (its boxes had changed). Once its selection turns random, a pass takes first the nodes
  // the last pass's moves changed, with their parents and grandparents, then random ones
  // (a move is several times likelier there). Never raises the cost; the tree does not
  // depend on the thread count.
  parallel,
  // The sequential form until it stops, then the parallel form from its best tree: the fast
  // large gains of the first, then the monotone polish of the second; then rotation sweeps
  // (InsertionConfig::rotations), which only lower the final tree. The default: lowest
  // final cost of the three on 10 of the 11 shared scenes (bench/insertion_bench), mostly in
  // about the time of the parallel form alone. On trees of kRegionalFrom nodes or more
  // (half a million triangles), the regional form instead.
  hybrid,
  // For large trees, the paper's sequential passes on all threads. Four insertion stages:
  // parallel passes by the measure until it stalls; sequential ones until it stalls again,
  // each pass taking a batch from the measure's ranking instead of its top every time (the
  // top 1 % every other pass, the batches below it down to 8 % in between, those as
  // regional passes); then regional passes, batch after batch down the top third of the
  // ranking (the tree is cut at a fixed depth into disjoint subtrees of about 32k nodes, and
  // each candidate inside one is updated there, its children reinserted at the best place
  // inside that subtree; the subtrees run at once, each on its own candidates in order);
  // then the parallel form as a polish. Rotation sweeps (InsertionConfig::rotations) follow
  // the sequential stage, the regional one and the polish, and close a run its time budget
  // stops. The tree does not depend on the thread count. Hall at 1M and 4M triangles, 2
  // threads: ahead of sequential-then-parallel from one build time on, and converges lower
  // in less time (docs/optimization-at-scale.md).
  regional,
};

// Trees of at least this many nodes take the regional form under `hybrid`. Smaller trees
// optimize in seconds, where the regional form's gain is within the spread of the seed (on
// the 11 shared scenes, all below this size, it ended from 0.22 % lower to 0.23 % higher).
inline constexpr size_t kRegionalFrom = size_t{1} << 20;
// The form a run takes on a tree of `node_count` nodes: hybrid is regional from
// kRegionalFrom nodes on; every other form is itself. What `optimize --json` and `bake
// --json` report as "insertion_form".
InsertionForm resolved_form(InsertionForm form, size_t node_count);

std::string_view form_name(InsertionForm f);
// "sequential", "parallel", "hybrid", "regional"; nullopt for anything else.
std::optional<InsertionForm> parse_form(std::string_view name);
// Every form, in the order above.
std::vector<InsertionForm> insertion_forms();

// cost: only scales the reported cost, the search minimizes c_T * sum SA(inner). limits: hard
// limits over all stages, which also bound the run when the cost oscillates; unlike the
// rotations' configs, a cap of 1000 passes by default. seed: of the random selection passes.
struct InsertionConfig : OptimizerConfig {
  InsertionConfig() { limits.max_passes = 1000; }

  // Fraction of the inner nodes updated per pass (the paper's k = 1 %); at least one node.
  double batch = 0.01;
  InsertionMeasure measure = InsertionMeasure::area;
  // Passes without a lower cost before selection turns random for the rest of the stage
  // (p_R), and before the stage stops (p_T); the paper's 5 and 10. (The regional form's
  // sequential stage hands over to the regional passes after at most 2.)
  uint32_t random_after = 5;
  uint32_t stop_after = 10;
  // A pass counts as an improvement only when it lowers the best cost by more than this
  // fraction; without it the parallel form, which only ever lowers the cost, would count
  // endless tiny gains and never turn random or stop.
  double min_improvement = 1e-5;
  InsertionForm form = InsertionForm::hybrid;
  // The hybrid and regional forms follow their insertion stages with sweeps of Kensler's
  // rotations (hill climbing: at every inner node the child/grandchild swap that most lowers
  // its children's areas), each stage of sweeps until one gains less than 0.03 %: after the
  // sequential stage, after the regional one, and at the end; with a time budget
  // (limits.time_budget), also after the insertion stage the budget stops, whose end keeps
  // time for two sweeps. false: the insertion stages alone. (The sequential and parallel
  // forms never sweep.)
  bool rotations = true;
  // The regional form's first stage: parallel passes by the measure (true), or none, so that
  // the sequential passes by the measure start at once (false). Those gain far more in the
  // first seconds on very large trees, the parallel start ends lower in longer runs: hall,
  // 10M triangles, 2 threads, 9 s (about one build time): 468.29 without it, 481.98 with it
  // (477.50 for the sequential form); 1M triangles converged: 253.97 without, 251.88 with.
  // bake --quality fast starts without it.
  bool parallel_start = true;
};

// Optimizes `bvh` in place. Works on a tree from any builder and with any leaf sizes: leaves
// move as whole subtrees and are never split, so the leaf term of the cost stays fixed (the
// references are not needed: leaf boxes are kept, inner boxes refitted from them). The tree
// is compacted (depth-first numbering) before and after.
OptimizeReport optimize_insertion(Bvh& bvh, const InsertionConfig& config = {});

// The best place for a subtree with box `box` (Algorithm 1): the node X minimizing
// SA(X u box) plus the growth of every box above X, with that total (surface area, not
// normalized). `skip` (and its subtree) and `pass_through` (itself only) are never chosen;
// kInvalidNode for none. node = kInvalidNode when the tree offers no place.
struct ReinsertionCandidate {
  uint32_t node = kInvalidNode;
  double cost = 0.0;
};
ReinsertionCandidate find_reinsertion(const Bvh& bvh, const Box& box, uint32_t skip = kInvalidNode,
                                      uint32_t pass_through = kInvalidNode);
// The same search in the tree as it would be after removing the inner non-root node `n` and
// its parent (Figure 3: the parent's other child takes the parent's place, the boxes above
// shrink), without changing the tree. `freed_area`, if given, receives the surface area the
// removal frees. Equals find_reinsertion on the tree after an actual removal.
ReinsertionCandidate find_reinsertion_after_removal(const Bvh& bvh, const Box& box, uint32_t n,
                                                    double* freed_area = nullptr);

}  // namespace bvhopt
