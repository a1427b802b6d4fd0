// Tree rotations (Kensler 2008): hill climbing and simulated annealing over a built BVH.
//
// At an inner node N with children L and R, six moves exchange two subtrees:
//   the four rotations of the paper's Figure 2 (a child with a grandchild on the other
//   side) and the two grandchild/grandchild swaps the paper adds. No move changes N's box,
//   so no box above N changes either: the change of N's subtree cost is the change of the
//   whole tree's (unnormalized) cost. A move replaces one or two inner nodes' boxes and
//   nothing else, so that change is c_T times the change in those boxes' areas; leaves and
//   c_I never enter it. The optimizers therefore decide from box areas alone, in constant
//   time per move, and track per-node subtree costs (double) only to report the true cost.
#pragma once

#include <cstdint>
#include <string_view>

#include "bvhopt/bvh.h"
#include "bvhopt/cost_model.h"
#include "bvhopt/optimize_report.h"
#include "bvhopt/optimizer_config.h"

namespace bvhopt {

// The six moves at an inner node N = (L, R), L = (LL, LR), R = (RL, RR).
enum class Rotation : uint8_t {
  left_with_right_left,    // L <-> RL: R becomes (L, RR)          needs R inner
  left_with_right_right,   // L <-> RR: R becomes (RL, L)          needs R inner
  right_with_left_left,    // R <-> LL: L becomes (R, LR)          needs L inner
  right_with_left_right,   // R <-> LR: L becomes (LL, R)          needs L inner
  left_left_with_right_left,   // LL <-> RL: L = (RL, LR), R = (LL, RR)  needs both inner
  left_left_with_right_right,  // LL <-> RR: L = (RR, LR), R = (RL, LL)  needs both inner
};
inline constexpr int kRotationCount = 6;
std::string_view rotation_name(Rotation r);

// Whether the move exists at `node` (an inner node whose needed children are inner).
bool rotation_applies(const Bvh& bvh, uint32_t node, Rotation r);

// The change of the whole tree's unnormalized SAH cost if `r` were applied at `node`:
// c_T * (sum of the new boxes' areas - sum of the old ones). Divide by the root's area for
// the change of sah_cost(). The move must apply.
double rotation_cost_delta(const Bvh& bvh, uint32_t node, Rotation r, const CostModel& model = {});

// Applies `r` at `node`: relinks children and parents and refits the one or two inner nodes
// whose children changed. Node indices are kept; no other node changes. The move must apply.
void apply_rotation(Bvh& bvh, uint32_t node, Rotation r);

// cost: only c_T matters for the moves, both for the reported cost. limits: by default, run
// until a pass finds no improving move. seed: unused (hill climbing makes no random choice).
struct HillClimbConfig : OptimizerConfig {};

// Hill climbing (section 3): passes in post-order; at each inner node the move that lowers
// its cost most, if any, is applied. Stops when a pass applies no move (stop_reason
// StopReason::converged), or at a limit. The cost never rises. Parallel over independent subtrees;
// the tree does not depend on the thread count. Changes `bvh` in place (indices kept, so
// leaves and ref_indices are untouched); the tree stays valid.
OptimizeReport hill_climb(Bvh& bvh, const HillClimbConfig& config = {});

// The temperature unit. Kensler's local energy is a node's cost normalized by its own area,
// C_t + (S_L C_L + S_R C_R)/S, in the Manta DynBVH code of the time, which used
// C_t = C_i = 10 (SAH costs of 400-700 in his Table 1 are ten times the usual unit-cost
// figures). A move at N changes that energy by C_t * dA / S(N), where dA is the change of
// the summed areas of N's children. We compute dA exactly as he did and express the energy
// in his units, dE = energy_scale * dA / S(N) with energy_scale = 10, so the paper's
// temperatures (h from 0.8 to 2.2) carry over unchanged, whatever c_T and c_I our cost model
// uses. In our own cost units (c_T of the model, 3 by default) the same temperature is
// h * c_T / energy_scale, i.e. 0.3 h: set energy_scale = c_T to give h in our units.
// (Evidence for 10: a Manta DynBVH revision sets BVH_C_trav = BVH_C_isec = 10, and on our
// scenes the paper's h range works with scale 10 while anything near 10x hotter, which
// scale 1 would mean, only undoes the hill climbing: h = 3 already ends where hill
// climbing did on Sponza.) The paper prints the acceptance test as P(dE, T) < xi; a move
// must be accepted with probability P, so we accept when xi < P.
// cost: for the reported cost only, the moves depend on areas alone. limits: a pass or time
// limit may cut the schedule or the quench short.
struct AnnealConfig : OptimizerConfig {
  // Schedule T(i) = max(0, -sin(2 pi i / period)) * (schedule_passes - i) * h / schedule_passes
  // for passes i = 0 .. schedule_passes - 1, then T = 0 (the quench) until a pass applies
  // no move. Defaults N = 1250 and f = 50 as in the paper.
  uint32_t schedule_passes = 1250;
  uint32_t period = 50;
  // Hottest temperature, in Kensler's units (see above). 1.5 chosen by bench/rotations_bench
  // over 1.0, 1.5 and 2.2 (cost after / before, sweep SAH start, seed 1):
  //   Sponza 84.8 / 84.9 / 86.0 %, Conference 89.9 / 89.1 / 89.0 %, built-in 93.0 / 92.4 / 93.4 %.
  double h = 1.5;
  double energy_scale = 10.0;
  // Return the best tree seen at the end of any pass (or the input, if no pass beat it)
  // rather than the last one. Only hot passes can raise the cost, so the best tree is copied
  // just before a hot pass, and only if it is the current one.
  bool keep_best = true;
};

// Kensler's schedule above; 0 for i >= schedule_passes.
double annealing_temperature(uint32_t pass, uint32_t schedule_passes, uint32_t period, double h);

// Simulated annealing (section 4): the hill-climbing walk, except that at each node a
// candidate move no better than the best found so far there becomes the best anyway with
// probability min(1, exp(-dE/T)), dE the difference of local energies. Parallel over
// independent subtrees with random streams derived from the seed, the pass and the
// subtree's position: the same seed gives the same tree on any number of threads.
OptimizeReport anneal(Bvh& bvh, const AnnealConfig& config = {});

}  // namespace bvhopt
