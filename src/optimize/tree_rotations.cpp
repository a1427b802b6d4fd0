#include "bvhopt/tree_rotations.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "bvhopt/cost.h"
#include "optimize/pass_driver.h"
#include "optimize/tree_rotations_engine.h"

namespace bvhopt {

std::string_view rotation_name(Rotation r) {
  switch (r) {
    case Rotation::left_with_right_left: return "L<->RL";
    case Rotation::left_with_right_right: return "L<->RR";
    case Rotation::right_with_left_left: return "R<->LL";
    case Rotation::right_with_left_right: return "R<->LR";
    case Rotation::left_left_with_right_left: return "LL<->RL";
    case Rotation::left_left_with_right_right: return "LL<->RR";
  }
  return "?";
}

bool rotation_applies(const Bvh& bvh, uint32_t node, Rotation r) {
  const BvhNode& n = bvh[node];
  if (n.is_leaf()) return false;
  const bool li = !bvh[n.left()].is_leaf(), ri = !bvh[n.right()].is_leaf();
  switch (r) {
    case Rotation::left_with_right_left:
    case Rotation::left_with_right_right: return ri;
    case Rotation::right_with_left_left:
    case Rotation::right_with_left_right: return li;
    default: return li && ri;
  }
}

namespace {

// The new child boxes a move gives N: which slot of N changes (-1: both children change).
struct MovePlan {
  Box new_left, new_right;
  bool left_changes = false, right_changes = false;
};

MovePlan plan(const Bvh& bvh, uint32_t node, Rotation r) {
  const BvhNode& n = bvh[node];
  const BvhNode& L = bvh[n.left()];
  const BvhNode& R = bvh[n.right()];
  auto box = [&](uint32_t i) -> const Box& { return bvh[i].box; };
  MovePlan p;
  switch (r) {
    case Rotation::left_with_right_left:
      p.new_right = merge(L.box, box(R.right()));
      p.right_changes = true;
      break;
    case Rotation::left_with_right_right:
      p.new_right = merge(box(R.left()), L.box);
      p.right_changes = true;
      break;
    case Rotation::right_with_left_left:
      p.new_left = merge(R.box, box(L.right()));
      p.left_changes = true;
      break;
    case Rotation::right_with_left_right:
      p.new_left = merge(box(L.left()), R.box);
      p.left_changes = true;
      break;
    case Rotation::left_left_with_right_left:
      p.new_left = merge(box(R.left()), box(L.right()));
      p.new_right = merge(box(L.left()), box(R.right()));
      p.left_changes = p.right_changes = true;
      break;
    case Rotation::left_left_with_right_right:
      p.new_left = merge(box(R.right()), box(L.right()));
      p.new_right = merge(box(R.left()), box(L.left()));
      p.left_changes = p.right_changes = true;
      break;
  }
  return p;
}

}  // namespace

double rotation_cost_delta(const Bvh& bvh, uint32_t node, Rotation r, const CostModel& model) {
  MovePlan p = plan(bvh, node, r);
  const BvhNode& n = bvh[node];
  // Summed in the optimizers' order (new areas, then old ones) so both see the same sign.
  double now = 0.0, before = 0.0;
  if (p.left_changes) {
    now += double(p.new_left.area());
    before += double(bvh[n.left()].area());
  }
  if (p.right_changes) {
    now += double(p.new_right.area());
    before += double(bvh[n.right()].area());
  }
  return model.traversal * (now - before);
}

void apply_rotation(Bvh& bvh, uint32_t node, Rotation r) {
  BvhNode& n = bvh[node];
  const uint32_t l = n.left(), rt = n.right();
  // Exchanges the subtree in slot `sa` of node a with the one in slot `sb` of node b.
  auto exchange = [&](uint32_t a, int sa, uint32_t b, int sb) {
    uint32_t x = bvh[a].child(sa), y = bvh[b].child(sb);
    bvh[a].set_child(sa, y);
    bvh[b].set_child(sb, x);
    bvh[y].parent = a;
    bvh[x].parent = b;
  };
  switch (r) {
    case Rotation::left_with_right_left: exchange(node, 0, rt, 0); bvh.refit_node(rt); break;
    case Rotation::left_with_right_right: exchange(node, 0, rt, 1); bvh.refit_node(rt); break;
    case Rotation::right_with_left_left: exchange(node, 1, l, 0); bvh.refit_node(l); break;
    case Rotation::right_with_left_right: exchange(node, 1, l, 1); bvh.refit_node(l); break;
    case Rotation::left_left_with_right_left: exchange(l, 0, rt, 0); bvh.refit_node(l); bvh.refit_node(rt); break;
    case Rotation::left_left_with_right_right: exchange(l, 0, rt, 1); bvh.refit_node(l); bvh.refit_node(rt); break;
  }
}

double annealing_temperature(uint32_t pass, uint32_t schedule_passes, uint32_t period, double h) {
  if (pass >= schedule_passes || period == 0) return 0.0;
  const double i = pass;
  const double s = -std::sin(2.0 * std::numbers::pi * i / period);
  return std::max(0.0, s) * (schedule_passes - i) * h / schedule_passes;
}

namespace {

// Passes between two relayouts of the working copy: a relayout costs about one cold pass
// and keeps the walk's reads near sequential.
constexpr uint32_t kRelayoutPeriod = 16;

struct Schedule {
  uint32_t passes = 0;  // 0: hill climbing
  uint32_t period = 50;
  double h = 0.0;
  double energy_scale = 10.0;
  uint64_t seed = 0;
  bool keep_best = false;
};

// The passes of either optimizer over the engine's working copy, for the pass driver.
class RotationPasses {
 public:
  RotationPasses(detail::RotationEngine& engine, const Schedule& schedule) : engine_(engine), schedule_(schedule) {}

  double cost() const { return engine_.tree_cost(); }
  // Only a hot pass can raise the cost.
  bool keep_best_before(uint32_t pass) const { return schedule_.keep_best && temperature(pass) > 0.0; }
  detail::RotationEngine::Snapshot snapshot() const { return engine_.snapshot(); }
  void restore(const detail::RotationEngine::Snapshot& s) { engine_.restore(s); }

  detail::PassResult run_pass(uint32_t pass, double /*stage_best*/) {
    const double t = temperature(pass);
    // A cold pass that moved nothing left the tree as it was, and a cold pass uses no random
    // numbers: the next cold pass would find nothing either, so it is skipped (it still
    // counts and is reported). This saves most of the cold half of every schedule period.
    uint64_t moves = 0;
    if (!(t == 0.0 && settled_)) {
      if (pass > 0 && pass % kRelayoutPeriod == 0) engine_.relayout();
      moves = engine_.run_pass(t, schedule_.energy_scale, schedule_.seed, pass);
    }
    settled_ = t == 0.0 && moves == 0;
    const bool converged = pass + 1 >= schedule_.passes && settled_;
    return {engine_.tree_cost(), moves, t, converged};
  }

 private:
  double temperature(uint32_t pass) const {
    return annealing_temperature(pass, schedule_.passes, schedule_.period, schedule_.h);
  }

  detail::RotationEngine& engine_;
  const Schedule& schedule_;
  bool settled_ = false;  // the last pass was cold and applied no move
};

// `name`: the method, which names its one stage in the report.
OptimizeReport run(Bvh& bvh, const OptimizerConfig& config, const Schedule& schedule, std::string_view name) {
  detail::PassDriver driver(config.limits);
  driver.set_initial_cost(sah_cost(bvh, config.cost));
  // Nothing to rotate, or a tree of zero area where every move changes nothing.
  if (bvh.empty() || bvh[bvh.root].is_leaf() || !(bvh[bvh.root].area() > 0.0)) return driver.finish();
  detail::RotationEngine engine(bvh, config.cost);
  driver.set_initial_cost(engine.tree_cost());
  RotationPasses passes(engine, schedule);
  driver.run(passes, name);
  engine.write_to(bvh);
  return driver.finish();
}

}  // namespace

OptimizeReport hill_climb(Bvh& bvh, const HillClimbConfig& config) {
  return run(bvh, config, Schedule{}, "hill-climb");
}

OptimizeReport anneal(Bvh& bvh, const AnnealConfig& config) {
  Schedule s;
  s.passes = config.schedule_passes;
  s.period = config.period;
  s.h = config.h;
  s.energy_scale = config.energy_scale;
  s.seed = config.seed;
  s.keep_best = config.keep_best;
  return run(bvh, config, s, "anneal");
}

}  // namespace bvhopt
