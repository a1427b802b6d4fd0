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
  app->add_option("--split-alpha", params.alpha,
                  "sbvh: try spatial splits where the object split's children overlap by more than this "
                  "fraction of the root's area (Stich et al.'s alpha; 0: everywhere)")
      ->check(finite_number())
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app->add_option("--split-node-alpha", params.node_alpha,
                  "sbvh: and only where they also overlap by more than this fraction of the node's own area (0: "
                  "--split-alpha's test alone)")
      ->check(finite_number())
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app->add_option("--spatial-bins", params.spatial_bins,
                  "sbvh: most bins per axis for spatial splits (a node of n references uses at most 4 + n/2)")
      ->check(whole_number(kMinBinCount, kMaxBinCount))
      ->capture_default_str();
  app->add_option("--spatial-from", params.spatial_from,
                  "sbvh: nodes of fewer references take object splits only (0: spatial splits everywhere)")
      ->check(whole_number(0, kMaxReferences))
      ->capture_default_str();
  app->add_option("--spatial-max", params.spatial_max,
                  "sbvh: nodes of more references take object splits only (0: no limit)")
      ->check(whole_number(0, kMaxReferences))
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

BuiltTree SceneBuilderOption::build(const Mesh& mesh, PrimitiveRefs refs, const CostModel& cost,
                                     uint32_t max_leaf_size) const {
  BuildOptions options;
  options.kind = *parse_builder(name);
  options.cost = cost;
  options.leaf.max_leaf_size = max_leaf_size;
  options.sbvh = sbvh;
  return build_tree(mesh, std::move(refs), options);
}

}  // namespace bvhopt::cli
