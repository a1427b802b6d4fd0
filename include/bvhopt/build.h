// Choosing a builder by name, as the command line and the benchmarks do.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bvhopt/binned_sah_builder.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/mesh.h"
#include "bvhopt/spatial_split_builder.h"
#include "bvhopt/sweep_sah_builder.h"

namespace bvhopt {

// spatial_split (the SBVH) needs the triangles and adds references: build_tree runs it,
// build_bvh does not.
enum class BuilderKind { sweep_sah, binned_sah, spatial_median, object_median, spatial_split };

// Every setting of every builder: the shared ones (cost, leaf, parallel_threshold) once,
// and each builder's own next to them, so that build_bvh hands the chosen builder its
// full config and nothing set here is dropped.
struct BuildOptions : BuilderConfig {
  BuilderKind kind = BuilderKind::sweep_sah;
  SweepSahParams sweep;    // sweep SAH only
  BinnedSahParams binned;  // binned SAH only
  SpatialSplitParams sbvh; // spatial splits only
};

// The config build_bvh passes to each builder.
SweepSahConfig sweep_sah_config(const BuildOptions& options);
BinnedSahConfig binned_sah_config(const BuildOptions& options);
MedianConfig median_config(const BuildOptions& options);
SpatialSplitConfig spatial_split_config(const BuildOptions& options);

// Validates the chosen builder's config (throws Error), as build_bvh does.
void validate(const BuildOptions& options);

// A builder over references alone (every kind in all_builders()). Throws Error for
// spatial_split, which needs the triangles: use build_tree.
Bvh build_bvh(const PrimitiveRefs& refs, const BuildOptions& options = {});

// A tree and the references its leaves name. Every builder but spatial_split returns the
// references it was given; spatial_split returns the clipped pieces it made of them
// (SpatialSplitResult), each with its triangle's id.
struct BuiltTree {
  Bvh bvh;
  PrimitiveRefs refs;
  std::optional<SpatialSplitStats> spatial_split;  // spatial_split's counts; empty for the others
};
// Any builder (all_mesh_builders()) over references to `mesh`'s triangles.
BuiltTree build_tree(const Mesh& mesh, PrimitiveRefs refs, const BuildOptions& options = {});

// "sweep", "binned", "spatial-median", "object-median", "sbvh".
std::string_view builder_name(BuilderKind kind);
std::optional<BuilderKind> parse_builder(std::string_view name);
// The builders over references alone, those build_bvh runs.
std::vector<BuilderKind> all_builders();
// Those and the spatial-split builder: what build_tree and the command line accept.
std::vector<BuilderKind> all_mesh_builders();

}  // namespace bvhopt
