#include "bvhopt/build.h"

#include "bvhopt/error.h"

namespace bvhopt {

SweepSahConfig sweep_sah_config(const BuildOptions& options) {
  return SweepSahConfig{static_cast<const BuilderConfig&>(options), options.sweep};
}

BinnedSahConfig binned_sah_config(const BuildOptions& options) {
  return BinnedSahConfig{static_cast<const BuilderConfig&>(options), options.binned};
}

MedianConfig median_config(const BuildOptions& options) {
  return MedianConfig{static_cast<const BuilderConfig&>(options)};
}

SpatialSplitConfig spatial_split_config(const BuildOptions& options) {
  return SpatialSplitConfig{static_cast<const BuilderConfig&>(options), options.sbvh};
}

void validate(const BuildOptions& options) {
  switch (options.kind) {
    case BuilderKind::sweep_sah: return validate(sweep_sah_config(options));
    case BuilderKind::binned_sah: return validate(binned_sah_config(options));
    case BuilderKind::spatial_median:
    case BuilderKind::object_median: return validate(median_config(options));
    case BuilderKind::spatial_split: return validate(spatial_split_config(options));
  }
}

Bvh build_bvh(const PrimitiveRefs& refs, const BuildOptions& options) {
  switch (options.kind) {
    case BuilderKind::sweep_sah: return build_sweep_sah(refs, sweep_sah_config(options));
    case BuilderKind::binned_sah: return build_binned_sah(refs, binned_sah_config(options));
    case BuilderKind::spatial_median: return build_spatial_median(refs, median_config(options));
    case BuilderKind::object_median: return build_object_median(refs, median_config(options));
    case BuilderKind::spatial_split:
      throw Error("the sbvh builder clips triangles and adds references: build it with build_tree(mesh, refs, options)");
  }
  return {};
}

BuiltTree build_tree(const Mesh& mesh, PrimitiveRefs refs, const BuildOptions& options) {
  if (options.kind != BuilderKind::spatial_split) {
    Bvh bvh = build_bvh(refs, options);
    return BuiltTree{std::move(bvh), std::move(refs), std::nullopt};
  }
  SpatialSplitResult r = build_spatial_split(mesh, refs, spatial_split_config(options));
  return BuiltTree{std::move(r.bvh), std::move(r.refs), r.stats};
}

std::string_view builder_name(BuilderKind kind) {
  switch (kind) {
    case BuilderKind::sweep_sah: return "sweep";
    case BuilderKind::binned_sah: return "binned";
    case BuilderKind::spatial_median: return "spatial-median";
    case BuilderKind::object_median: return "object-median";
    case BuilderKind::spatial_split: return "sbvh";
  }
  return "?";
}

std::optional<BuilderKind> parse_builder(std::string_view name) {
  for (BuilderKind k : all_mesh_builders())
    if (builder_name(k) == name) return k;
  return std::nullopt;
}

std::vector<BuilderKind> all_builders() {
  return {BuilderKind::sweep_sah, BuilderKind::binned_sah, BuilderKind::spatial_median, BuilderKind::object_median};
}

std::vector<BuilderKind> all_mesh_builders() {
  std::vector<BuilderKind> kinds = all_builders();
  kinds.push_back(BuilderKind::spatial_split);
  return kinds;
}

}  // namespace bvhopt
