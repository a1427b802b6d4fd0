// A second way from a Bvh to a FlatBvh, for the tests.
#pragma once

#include "bvhopt/bvh.h"
#include "bvhopt/finalize.h"
#include "bvhopt/references.h"

namespace bvhopt {

// A flat tree straight from a Bvh and its references, independent of finalize: children
// ordered lower-first on the axis of widest centre separation, recorded in `axis`. The tests
// trace trees through it, and through finalize, so a fault in either shows separately.
FlatBvh flatten_for_tracing(const Bvh& bvh, const PrimitiveRefs& refs);

}  // namespace bvhopt
