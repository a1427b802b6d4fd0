#include <string>
#include <vector>

#include "cli_common.h"

namespace bvhopt::cli {

void add_budget_option(CLI::App* app, SpatialSplitParams& params) {
  app->add_option("--budget", params.budget,
                  "Most references per triangle the sbvh builder may make by splitting (1: none added)")
      ->check(finite_number())
      ->check(CLI::Range(1.0, 64.0))
      ->capture_default_str();
}

void SceneBuilderOption::add_to(CLI::App* app) {
  std::vector<std::string> names;
  std::string help;
  for (BuilderKind kind : all_mesh_builders()) {
    names.emplace_back(builder_name(kind));
    help += (help.empty() ? "" : " | ") + names.back();
  }
  app->add_option("--builder", name, "Builder of a scene's tree (one reference per leaf): " + help)
      ->check(CLI::IsMember(names))
      ->capture_default_str();
  add_budget_option(app, sbvh);
}

BuiltTree SceneBuilderOption::build(const Mesh& mesh, PrimitiveRefs refs, const CostModel& cost) const {
  BuildOptions options;
  options.kind = *parse_builder(name);
  options.cost = cost;
  options.leaf.max_leaf_size = 1;
  options.sbvh = sbvh;
  return build_tree(mesh, std::move(refs), options);
}

}  // namespace bvhopt::cli
