// Exact sweep SAH: every reference centroid on every axis is a candidate split.
#pragma once

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

struct SweepSahConfig {
  CostModel cost;     // c_T and c_I weigh a split against a leaf
  LeafConfig leaf;
  // Nodes with fewer references than this are built by one task (no further spawning).
  uint32_t parallel_threshold = 4096;
};

// References are sorted once per axis by centroid; each node sweeps the three sorted
// lists and partitions them stably, so the whole build is O(n log n). Deterministic:
// the same tree on any number of threads.
Bvh build_sweep_sah(const PrimitiveRefs& refs, const SweepSahConfig& config = {});

}  // namespace bvhopt
