#include <sstream>

#include "bvhopt/edge_volume_subdivision.h"
#include "cli_common.h"

namespace bvhopt::cli {

void EvhOption::add_to(CLI::App* app) {
  app->add_flag("--evh", enabled, "Subdivide triangles with fat edge boxes into several references (edge volume heuristic)");
  app->add_option("--evh-t", t, "Edge volume threshold exponent t: split while an edge box exceeds V / 2^t")
      ->check(CLI::Range(0, 62))
      ->capture_default_str();
  app->add_option("--evh-max-ratio", max_ratio,
                  "At most this many references per triangle in all; t is lowered until it fits (0: no limit)")
      ->check(finite_number())
      ->check(non_negative_number())
      ->capture_default_str();
}

PrimitiveRefs EvhOption::make_refs(const Mesh& mesh, std::string* report) const {
  if (!enabled) return make_references(mesh);
  EdgeVolumeConfig config;
  config.t = t;
  config.max_reference_ratio = max_ratio;
  EdgeVolumeResult result = subdivide_edge_volume(mesh, config);
  if (report) {
    const EdgeVolumeStats& st = result.stats;
    std::ostringstream line;
    line << st.references << " references for " << st.triangles << " triangles (x" << format_double(st.ratio, 3)
         << ", t " << st.effective_t << ")";
    if (st.budget_hit) line << "; t lowered from " << t << " to fit --evh-max-ratio " << max_ratio;
    if (st.depth_limit_hit) line << "; " << st.depth_limited << " pieces stopped at the depth limit";
    *report = line.str();
  }
  return std::move(result.refs);
}

}  // namespace bvhopt::cli
