// One function that checks every invariant of a tree and says what is broken and where.
#pragma once

#include <string>
#include <vector>

#include "bvhopt/bvh.h"
#include "bvhopt/references.h"

namespace bvhopt {

struct ValidationReport {
  std::vector<std::string> problems;  // one line each, naming the node and what is wrong
  bool ok() const { return problems.empty(); }
  std::string summary() const;        // all problems joined (the first 20, then a count)
};

// Checks: the root has no parent; parent and child links agree; no node is reached twice
// (no cycles, no sharing); every inner node's box equals the union of its children's;
// every leaf's box contains its references' boxes;
// leaves are non-empty; every reference box has min <= max (no NaN); every reference id appears in exactly one leaf slot, and the slots
// in use are exactly 0..ref_indices.size()-1, once each.
struct ValidationOptions {
  // Accept a reference that is in no leaf when some leaf holds another reference to the
  // same triangle: what dedup_leaf_references (leaf_dedup.h) leaves behind in a tree over
  // subdivided references. Off, every reference must be in exactly one leaf.
  bool allow_dropped_duplicates = false;
};

ValidationReport validate(const Bvh& bvh, const PrimitiveRefs& refs, const ValidationOptions& options = {});

}  // namespace bvhopt
