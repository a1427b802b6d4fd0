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

// Every setting of every builder: the shared ones (cost, leaf, parallel_threshold) once,
// and each builder's own next to them, so that build_bvh hands the chosen builder its
// full config and nothing set here is dropped.
struct BuildOptions : BuilderConfig {
  BuilderKind kind = BuilderKind::sweep_sah;
  SweepSahParams sweep;    // sweep SAH only
  BinnedSahParams binned;  // binned SAH only
};

// The config build_bvh passes to each builder.
SweepSahConfig sweep_sah_config(const BuildOptions& options);
BinnedSahConfig binned_sah_config(const BuildOptions& options);
MedianConfig median_config(const BuildOptions& options);

// Validates the chosen builder's config (throws Error), as build_bvh does.
void validate(const BuildOptions& options);

Bvh build_bvh(const PrimitiveRefs& refs, const BuildOptions& options = {});

// "sweep", "binned", "spatial-median", "object-median".
std::string_view builder_name(BuilderKind kind);
std::optional<BuilderKind> parse_builder(std::string_view name);
std::vector<BuilderKind> all_builders();

}  // namespace bvhopt
