#include "bvhopt/build.h"

namespace bvhopt {

Bvh build_bvh(const PrimitiveRefs& refs, const BuildOptions& options) {
  switch (options.kind) {
    case BuilderKind::sweep_sah:
      return build_sweep_sah(refs, SweepSahConfig{options.cost, options.leaf});
    case BuilderKind::binned_sah:
      return build_binned_sah(refs, BinnedSahConfig{options.cost, options.leaf, options.bin_count});
    case BuilderKind::spatial_median:
      return build_spatial_median(refs, MedianConfig{options.leaf});
    case BuilderKind::object_median:
      return build_object_median(refs, MedianConfig{options.leaf});
  }
  return {};
}

std::string_view builder_name(BuilderKind kind) {
  switch (kind) {
    case BuilderKind::sweep_sah: return "sweep";
    case BuilderKind::binned_sah: return "binned";
    case BuilderKind::spatial_median: return "spatial-median";
    case BuilderKind::object_median: return "object-median";
  }
  return "?";
}

std::optional<BuilderKind> parse_builder(std::string_view name) {
  for (BuilderKind k : all_builders())
    if (builder_name(k) == name) return k;
  return std::nullopt;
}

std::vector<BuilderKind> all_builders() {
  return {BuilderKind::sweep_sah, BuilderKind::binned_sah, BuilderKind::spatial_median, BuilderKind::object_median};
}

}  // namespace bvhopt
