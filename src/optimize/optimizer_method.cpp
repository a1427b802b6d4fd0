#include "bvhopt/optimizer_method.h"

#include "optimize/find_by_name.h"

namespace bvhopt {

std::string_view optimizer_method_name(OptimizerMethod m) {
  switch (m) {
    case OptimizerMethod::hill_climb: return "hill-climb";
    case OptimizerMethod::anneal: return "anneal";
    case OptimizerMethod::insertion: return "insertion";
  }
  return "anneal";
}

std::vector<OptimizerMethod> optimizer_methods() {
  return {OptimizerMethod::hill_climb, OptimizerMethod::anneal, OptimizerMethod::insertion};
}

std::optional<OptimizerMethod> parse_optimizer_method(std::string_view name) {
  return detail::find_by_name(optimizer_methods(), optimizer_method_name, name);
}

}  // namespace bvhopt
