// Every builder config is checked here, so that a setting out of range is an Error that
// names it rather than a value silently clamped somewhere in a builder.
#include <cmath>
#include <string>

#include "bvhopt/binned_sah_builder.h"
#include "bvhopt/error.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/spatial_split_builder.h"
#include "bvhopt/sweep_sah_builder.h"

namespace bvhopt {
namespace {

void check_range(const char* name, uint64_t value, uint64_t lo, uint64_t hi) {
  if (value < lo || value > hi)
    throw Error(std::string(name) + " is " + std::to_string(value) + ", must be " + std::to_string(lo) + " to " +
                std::to_string(hi));
}

void check_cost(const char* name, double value) {
  if (!std::isfinite(value) || value < 0.0)
    throw Error(std::string(name) + " is " + std::to_string(value) + ", must be finite and >= 0");
}

}  // namespace

void validate(const BuilderConfig& config) {
  if (config.leaf.max_leaf_size < 1) throw Error("leaf.max_leaf_size is 0, must be at least 1");
  check_cost("cost.traversal (c_T)", config.cost.traversal);
  check_cost("cost.intersection (c_I)", config.cost.intersection);
}

void validate(const SweepSahConfig& config) { validate(static_cast<const BuilderConfig&>(config)); }

void validate(const MedianConfig& config) { validate(static_cast<const BuilderConfig&>(config)); }

void validate(const BinnedSahConfig& config) {
  validate(static_cast<const BuilderConfig&>(config));
  check_range("bin_count", config.bin_count, kMinBinCount, kMaxBinCount);
  check_range("max_bin_count", config.max_bin_count, kMinBinCount, kMaxBinCount);
  check_range("exact_sweep_below", config.exact_sweep_below, 0, kMaxExactSweepBelow);
}

void validate(const SpatialSplitConfig& config) {
  validate(static_cast<const BuilderConfig&>(config));
  if (!std::isfinite(config.budget) || config.budget < 1.0)
    throw Error("budget is " + std::to_string(config.budget) + ", must be finite and >= 1 (references per triangle)");
  check_cost("alpha", config.alpha);
  check_cost("node_alpha", config.node_alpha);
  check_range("spatial_bins", config.spatial_bins, kMinBinCount, kMaxBinCount);
  check_range("object_bins", config.object_bins, kMinBinCount, kMaxBinCount);
  check_range("exact_sweep_below", config.exact_sweep_below, 0, 65536);
}

}  // namespace bvhopt
