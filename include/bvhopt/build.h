// Choosing a builder by name, as the command line and the benchmarks do.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bvhopt/binned_sah_builder.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/sweep_sah_builder.h"

namespace bvhopt {

enum class BuilderKind { sweep_sah, binned_sah, spatial_median, object_median };

struct BuildOptions {
  BuilderKind kind = BuilderKind::sweep_sah;
  CostModel cost;
  LeafConfig leaf;
  uint32_t bin_count = 32;  // binned SAH only
};

Bvh build_bvh(const PrimitiveRefs& refs, const BuildOptions& options = {});

// "sweep", "binned", "spatial-median", "object-median".
std::string_view builder_name(BuilderKind kind);
std::optional<BuilderKind> parse_builder(std::string_view name);
std::vector<BuilderKind> all_builders();

}  // namespace bvhopt
