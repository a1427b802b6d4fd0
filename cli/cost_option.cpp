#include "cli_common.h"

namespace bvhopt::cli {

void CostOption::add_to(CLI::App* app) {
  app->add_option("--ct", traversal, "SAH cost of traversing an inner node (c_T)")
      ->check(finite_number())
      ->check(positive_number())
      ->capture_default_str();
  app->add_option("--ci", intersection, "SAH cost of intersecting a reference (c_I)")
      ->check(finite_number())
      ->check(positive_number())
      ->capture_default_str();
}

}  // namespace bvhopt::cli
