// "Remove references to the same triangle in each leaf" (Dammertz and Keller 2008, 2.3):
// after a build over subdivided references, a leaf holding several pieces of one triangle
// keeps one reference to it, since traversal intersects the whole triangle anyway.
#pragma once

#include <cstddef>

#include "bvhopt/bvh.h"
#include "bvhopt/references.h"
#include "bvhopt/validate.h"

namespace bvhopt {

struct LeafDedupStats {
  size_t leaves = 0;
  size_t leaves_changed = 0;  // leaves that held some triangle more than once
  size_t slots_before = 0;    // leaf slots (references in leaves) before
  size_t slots_after = 0;     // and after
};

// In each leaf, keeps the first slot of every triangle id (slot order, so deterministic)
// and drops the others; leaf boxes are left as they are, the union of all the pieces the
// leaf held, because the kept reference now stands for the triangle's part in all of them.
// Then bvh.renumber_depth_first() (the tree is renumbered depth-first, as every optimizer leaves it).
// Run it last, after every optimizer and before finalize: a later Bvh::refit would shrink
// the leaf boxes to the kept pieces' boxes and lose the others' parts of the triangle.
// The tree then no longer passes validate() (dropped references appear in no leaf); check
// it with validate_deduplicated().
LeafDedupStats dedup_leaf_references(Bvh& bvh, const PrimitiveRefs& refs);

// The checks of validate() that still hold after dedup_leaf_references, plus its own:
// every slot names a reference in range; no reference is in two slots; every triangle id
// that has a reference in `refs` appears in some leaf; no leaf holds one triangle twice.
// Structure, inner boxes and "leaf box contains its references' boxes" are
// checked by validate() on a copy whose references are renumbered to the kept ones.
ValidationReport validate_deduplicated(const Bvh& bvh, const PrimitiveRefs& refs);

}  // namespace bvhopt
