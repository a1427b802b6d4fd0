// Binned SAH (Wald 2007).
#pragma once

#include <cstdint>

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

// Bins per axis a node can use: the bins live on the stack of each node's split.
inline constexpr uint32_t kMinBinCount = 2;
inline constexpr uint32_t kMaxBinCount = 128;
// Largest node the exact-sweep path takes (its scratch is on the stack too).
inline constexpr uint32_t kMaxExactSweepBelow = 256;

// What only the binned builder has; BuildOptions carries it next to the shared settings.
struct BinnedSahParams {
  uint32_t bin_count = 32;  // bins per axis over the node's centroid bounds (2 to 128)
  // Large nodes get more bins and small ones fewer: a node of n references uses
  // min(clamp(n / refs_per_bin, bin_count, max(bin_count, max_bin_count)), 4 + n / 5) bins.
  // In large nodes the pass over the references costs far more than sweeping the bins,
  // and the top splits weigh most in the cost: on the shared scenes this lowers the cost
  // by up to 15% at no measurable time; in small nodes most bins would stay empty.
  // refs_per_bin = 0 gives bin_count bins everywhere (plain Wald 2007).
  uint32_t refs_per_bin = 256;
  uint32_t max_bin_count = 128;  // 2 to 128
  // Nodes of at most this many references (0 to 256) are split by an exact sweep over
  // their sorted references instead of bins: near the leaves sorting a few references is
  // cheaper than clearing and sweeping 3 x bin_count bins, and finds the best split.
  uint32_t exact_sweep_below = 16;
  // Nodes with at least this many references bin and partition them in parallel (the
  // top few levels, which otherwise bound the speed-up: each is one long pass).
  uint32_t parallel_binning_threshold = 65536;
};

struct BinnedSahConfig : BuilderConfig, BinnedSahParams {};

// Throws Error naming a setting out of its range (bin_count and max_bin_count 2 to 128,
// exact_sweep_below 0 to 256, and those of validate(const BuilderConfig&)).
void validate(const BinnedSahConfig& config);

// Top-down: each node's references are binned on all three axes by the centre of their
// boxes (which make_references stores as the centroid) over the node's centroid bounds,
// and split at the bin boundary of lowest SAH. Deterministic: the same tree on any
// number of threads. With all centroids of a node equal, the node is halved by id.
Bvh build_binned_sah(const PrimitiveRefs& refs, const BinnedSahConfig& config = {});

}  // namespace bvhopt
