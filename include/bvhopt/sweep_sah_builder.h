// Exact sweep SAH: every reference centroid on every axis is a candidate split.
#pragma once

#include <cstdint>

#include "bvhopt/build_config.h"
#include "bvhopt/bvh.h"
#include "bvhopt/mesh.h"
#include "bvhopt/references.h"

namespace bvhopt {

// What only the sweep builder has; BuildOptions carries it next to the shared settings.
struct SweepSahParams {
  // Nodes with at least this many references split each axis's sweep, and each list's
  // partition, into chunks on all threads: the top nodes are long sequential passes
  // otherwise. The tree is the same either way, and no more scratch is needed.
  uint32_t parallel_split_threshold = 32768;
};

struct SweepSahConfig : BuilderConfig, SweepSahParams {};

// Throws Error on a setting out of range (see validate(const BuilderConfig&)).
void validate(const SweepSahConfig& config);

// References are sorted once per axis by (centroid, id); each node sweeps the three sorted
// lists and partitions them stably, so the whole build is O(n log n). Every position
// between two references on every axis is a candidate; the split minimises
// SA(L) n_L + SA(R) n_R, ties going to the more balanced split, then to the lower axis
// and position. A node whose centroids all coincide is halved in id order. Deterministic:
// the same tree on any number of threads. Memory: the references (40 bytes each), the tree
// (76 bytes per reference with leaves of one) and 17 bytes per reference of scratch.
Bvh build_sweep_sah(const PrimitiveRefs& refs, const SweepSahConfig& config = {});

// The same tree, node for node, as build_sweep_sah(make_references(mesh), config), built
// without the references: the triangles' boxes are kept inside the node array until the
// leaves are made, and centroids are taken from them when needed. The peak is then the
// tree and its scratch alone, 93 bytes per triangle with leaves of one, against 133 with
// the references made first, in the same time. With max_leaf_size > 1 it makes the
// references and builds from them. Reference ids are triangle ids, as make_references(mesh)
// numbers them.
Bvh build_sweep_sah(const Mesh& mesh, const SweepSahConfig& config = {});

}  // namespace bvhopt
