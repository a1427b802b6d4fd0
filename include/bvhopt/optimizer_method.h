// The optimizers by name, as the command line and the experiment files spell them.
#pragma once

#include <optional>
#include <string_view>
#include <vector>

namespace bvhopt {

enum class OptimizerMethod {
  hill_climb,  // tree rotations, hill climbing (tree_rotations.h)
  anneal,      // tree rotations, simulated annealing (tree_rotations.h)
  insertion,   // insertion-based optimization (insertion_optimizer.h)
};

// "hill-climb", "anneal", "insertion".
std::string_view optimizer_method_name(OptimizerMethod m);
std::optional<OptimizerMethod> parse_optimizer_method(std::string_view name);
// Every method, in the order above.
std::vector<OptimizerMethod> optimizer_methods();

}  // namespace bvhopt
