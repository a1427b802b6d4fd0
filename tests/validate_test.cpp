#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include "bvhopt/build.h"
#include "bvhopt/validate.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/median_builder.h"
#include "bvhopt/sweep_sah_builder.h"
#include "test_support.h"

namespace bvhopt {
namespace {

bool has_problem(const ValidationReport& r, const std::string& needle) {
  for (const auto& p : r.problems)
    if (p.find(needle) != std::string::npos) return true;
  return false;
}

struct Fixture {
  PrimitiveRefs refs;
  Bvh bvh;
};

Fixture make(uint32_t count, uint64_t seed, uint32_t leaf_size = 1, BuilderKind kind = BuilderKind::object_median) {
  Fixture f;
  f.refs = make_references(testing::random_mesh(count, seed));
  BuildOptions o;
  o.kind = kind;
  o.leaf.max_leaf_size = leaf_size;
  f.bvh = build_bvh(f.refs, o);
  return f;
}

// A node at depth >= 2 that is an inner node, so its parent and grandparent exist.
uint32_t deep_inner_node(const Bvh& bvh) {
  for (uint32_t n : bvh.depth_first_order())
    if (!bvh[n].is_leaf() && bvh[n].parent != kInvalidNode && bvh[bvh[n].parent].parent != kInvalidNode) return n;
  return kInvalidNode;
}

uint32_t some_leaf(const Bvh& bvh, size_t skip = 3) {
  for (uint32_t n : bvh.depth_first_order())
    if (bvh[n].is_leaf() && skip-- == 0) return n;
  return kInvalidNode;
}

TEST(Validate, PassesOnEveryBuilderOverManyRandomScenes) {
  for (BuilderKind kind : all_builders())
    for (uint32_t leaf : {1u, 4u})
      for (uint64_t seed = 1; seed <= 6; ++seed) {
        Fixture f = make(50 + 97 * static_cast<uint32_t>(seed), seed, leaf, kind);
        ValidationReport r = validate(f.bvh, f.refs);
        EXPECT_TRUE(r.ok()) << builder_name(kind) << " leaf " << leaf << " seed " << seed << ": " << r.summary();
      }
}

TEST(Validate, PassesOnEmptyAndSingleReferenceTrees) {
  PrimitiveRefs none;
  Bvh empty;
  EXPECT_TRUE(validate(empty, none).ok());
  PrimitiveRefs one = make_references({Box({0, 0, 0}, {1, 1, 1})});
  Bvh single = build_bvh(one);
  EXPECT_TRUE(validate(single, one).ok()) << validate(single, one).summary();
  // An empty tree over references leaves them all out.
  EXPECT_TRUE(has_problem(validate(empty, one), "tree is empty"));
}

TEST(Validate, SwappedChildIndex) {
  Fixture f = make(200, 7);
  uint32_t n = deep_inner_node(f.bvh);
  ASSERT_NE(n, kInvalidNode);
  // Point n's left child at its sibling's subtree instead: the sibling is reached twice
  // and the old left subtree is lost with all its references.
  uint32_t sib = f.bvh.sibling(n);
  f.bvh[n].set_child(0, sib);
  ValidationReport r = validate(f.bvh, f.refs);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(has_problem(r, "already reached")) << r.summary();
  EXPECT_TRUE(has_problem(r, "is in no leaf")) << r.summary();
}

TEST(Validate, SwappedChildrenBetweenTwoNodesBreaksParentLinks) {
  Fixture f = make(200, 8);
  uint32_t n = deep_inner_node(f.bvh);
  uint32_t p = f.bvh[n].parent;
  uint32_t sib = f.bvh.sibling(n);
  // Swap n's left child with its sibling: the set of nodes stays a tree, but the parent
  // links no longer agree and the boxes no longer match their children.
  uint32_t l = f.bvh[n].left();
  f.bvh[n].set_child(0, sib);
  f.bvh[p].set_child(f.bvh[p].left() == sib ? 0 : 1, l);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(l) + ": parent link is " + std::to_string(n))) << r.summary();
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(sib) + ": parent link is " + std::to_string(p))) << r.summary();
}

TEST(Validate, BrokenParentLink) {
  Fixture f = make(100, 9);
  uint32_t n = deep_inner_node(f.bvh);
  f.bvh[n].parent = f.bvh.root;
  ValidationReport r = validate(f.bvh, f.refs);
  ASSERT_EQ(r.problems.size(), 1u) << r.summary();
  EXPECT_NE(r.problems[0].find("node " + std::to_string(n) + ": parent link is"), std::string::npos);
}

TEST(Validate, RootWithAParent) {
  Fixture f = make(20, 10);
  f.bvh[f.bvh.root].parent = 3;
  EXPECT_TRUE(has_problem(validate(f.bvh, f.refs), "(root): has parent link 3"));
}

TEST(Validate, ShrunkInnerBox) {
  Fixture f = make(100, 11);
  uint32_t n = deep_inner_node(f.bvh);
  Box b = f.bvh[n].box;
  b.max.x -= 0.25f * (b.max.x - b.min.x);
  f.bvh[n].set_box(b);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(n) + ": box is not the union of its children")) << r.summary();
}

TEST(Validate, GrownInnerBox) {
  Fixture f = make(100, 12);
  uint32_t root = f.bvh.root;
  Box b = f.bvh[root].box;
  b.max.z = std::nextafter(b.max.z, 1e30f);  // one ulp: the union must be exact
  f.bvh[root].set_box(b);
  EXPECT_TRUE(has_problem(validate(f.bvh, f.refs), "node " + std::to_string(root) + ": box is not the union"));
}

TEST(Validate, ShrunkLeafBox) {
  Fixture f = make(100, 13);
  uint32_t leaf = some_leaf(f.bvh);
  Box b = f.bvh[leaf].box;
  b.min.y += 0.5f * (b.max.y - b.min.y);
  f.bvh[leaf].set_box(b);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(leaf) + ": leaf box")) << r.summary();
  EXPECT_TRUE(has_problem(r, "does not contain the box of reference")) << r.summary();
}

TEST(Validate, DuplicatedReferenceSlot) {
  Fixture f = make(100, 15);
  // Slot 10 now holds the same reference as slot 20; slot 10's old reference is lost.
  uint32_t lost = f.bvh.ref_indices[10];
  f.bvh.ref_indices[10] = f.bvh.ref_indices[20];
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "reference " + std::to_string(f.bvh.ref_indices[20]) + " (slot")) << r.summary();
  EXPECT_TRUE(has_problem(r, "is also in leaf node")) << r.summary();
  EXPECT_TRUE(has_problem(r, "reference " + std::to_string(lost) + " is in no leaf")) << r.summary();
}

TEST(Validate, TwoLeavesSharingASlot) {
  Fixture f = make(100, 16);
  uint32_t a = some_leaf(f.bvh, 2), b = some_leaf(f.bvh, 5);
  f.bvh[b].make_leaf(f.bvh[a].first_ref(), 1);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "is also used by leaf node")) << r.summary();
  EXPECT_TRUE(has_problem(r, "is in no leaf")) << r.summary();
}

TEST(Validate, DroppedReference) {
  Fixture f = make(100, 17, 4);
  uint32_t leaf = kInvalidNode;
  for (uint32_t n : f.bvh.depth_first_order())
    if (f.bvh[n].is_leaf() && f.bvh[n].ref_count() >= 2) leaf = n;
  ASSERT_NE(leaf, kInvalidNode);
  const BvhNode& nd = f.bvh[leaf];
  uint32_t last_slot = nd.first_ref() + nd.ref_count() - 1;
  uint32_t dropped = f.bvh.ref_indices[last_slot];
  f.bvh[leaf].make_leaf(nd.first_ref(), nd.ref_count() - 1);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "slot " + std::to_string(last_slot) + " (reference " + std::to_string(dropped) +
                                 ") is in no leaf"))
      << r.summary();
  EXPECT_TRUE(has_problem(r, "reference " + std::to_string(dropped) + " is in no leaf")) << r.summary();
}

TEST(Validate, EmptyLeafAndSlotsOutOfRange) {
  Fixture f = make(30, 18);
  uint32_t a = some_leaf(f.bvh, 1), b = some_leaf(f.bvh, 4);
  f.bvh[a].make_leaf(0, 0);
  f.bvh[b].make_leaf(29, 5);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(a) + ": leaf holds no references")) << r.summary();
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(b) + ": leaf slots [29, 34) out of range (30 slots)"))
      << r.summary();
}

TEST(Validate, ReferenceIdOutOfRange) {
  Fixture f = make(30, 19);
  f.bvh.ref_indices[4] = 1000;
  EXPECT_TRUE(has_problem(validate(f.bvh, f.refs), "holds reference 1000, out of range (30 references)"));
}

TEST(Validate, ChildIndexAndRootOutOfRange) {
  Fixture f = make(30, 20);
  uint32_t n = deep_inner_node(f.bvh);
  f.bvh[n].set_child(1, 123456);
  EXPECT_TRUE(has_problem(validate(f.bvh, f.refs),
                          "node " + std::to_string(n) + ": right child index 123456 out of range"));
  Fixture g = make(30, 20);
  g.bvh.root = 999;
  EXPECT_TRUE(has_problem(validate(g.bvh, g.refs), "root: index 999 out of range"));
}

TEST(Validate, CycleIsReportedAndTerminates) {
  Fixture f = make(300, 21);
  // The deepest inner node's right child becomes the root: without cycle detection
  // the walk would never end.
  uint32_t deepest = kInvalidNode;
  for (uint32_t n : f.bvh.depth_first_order())
    if (!f.bvh[n].is_leaf()) deepest = n;
  f.bvh[deepest].set_child(1, f.bvh.root);
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_TRUE(has_problem(r, "node " + std::to_string(deepest) + ": right child " + std::to_string(f.bvh.root) +
                                 " is already reached"))
      << r.summary();

  // A node that is its own child.
  Fixture g = make(50, 22);
  uint32_t n = deep_inner_node(g.bvh);
  g.bvh[n].set_child(0, n);
  EXPECT_TRUE(has_problem(validate(g.bvh, g.refs), "left child " + std::to_string(n) + " is the node itself"));
}

TEST(Validate, ProblemListIsCappedOnAHopelessTree) {
  Fixture f = make(3000, 23);
  for (auto& s : f.bvh.ref_indices) s = 0;  // every slot holds reference 0
  ValidationReport r = validate(f.bvh, f.refs);
  EXPECT_LE(r.problems.size(), 1001u);
  EXPECT_NE(r.problems.back().find("more problems"), std::string::npos);
  EXPECT_NE(r.summary().find("and "), std::string::npos);
}

// Random corruption of random fields: whatever the links say, validate must return
// (the sanitizer build turns any out-of-bounds read into a failure) and, since every
// change here breaks an invariant, must find something.
TEST(Validate, RandomCorruptionNeverCrashesAndIsAlwaysFound) {
  std::mt19937_64 rng(99);
  for (int trial = 0; trial < 400; ++trial) {
    Fixture f = make(40, 1000 + trial % 7, 1 + trial % 3);
    ASSERT_TRUE(validate(f.bvh, f.refs).ok());
    std::uniform_int_distribution<uint32_t> pick_node(0, static_cast<uint32_t>(f.bvh.nodes.size() - 1));
    uint32_t n = pick_node(rng);
    BvhNode& nd = f.bvh[n];
    const uint32_t values[] = {0u, 1u, n, nd.parent, kInvalidNode, static_cast<uint32_t>(f.bvh.nodes.size()),
                               pick_node(rng), static_cast<uint32_t>(rng())};
    uint32_t v = values[rng() % 8];
    switch (rng() % 3) {
      case 0:
        if (nd.parent == v) v ^= 1;
        nd.parent = v;
        break;
      case 1:
        if (nd.left_or_first == v) v += 1;
        nd.left_or_first = v;
        break;
      case 2:
        if (nd.right_or_count == v) v += 1;
        nd.right_or_count = v;
        break;
    }
    ValidationReport r = validate(f.bvh, f.refs);
    EXPECT_FALSE(r.ok()) << "trial " << trial << " node " << n;
  }
}

}  // namespace
}  // namespace bvhopt

namespace bvhopt {
namespace {

// Two references to triangle 7 and one to triangle 9, all in one leaf; dedup keeps one
// reference per triangle, which only the dropped-duplicates option accepts.
TEST(ValidateOptions, DroppedDuplicatesAcceptedOnlyWhereTheTriangleRemains) {
  PrimitiveRefs refs = make_references({Box({0, 0, 0}, {1, 1, 1}), Box({1, 0, 0}, {2, 1, 1}), Box({3, 0, 0}, {4, 1, 1})});
  refs.triangle_ids = {7, 7, 9};
  MedianConfig config;
  config.leaf.max_leaf_size = 3;
  Bvh bvh = build_object_median(refs, config);
  ASSERT_TRUE(validate(bvh, refs).ok());
  LeafDedupStats st = dedup_leaf_references(bvh, refs);
  (void)st;
  EXPECT_FALSE(validate(bvh, refs).ok());
  EXPECT_TRUE(validate(bvh, refs, ValidationOptions{.allow_dropped_duplicates = true}).ok())
      << validate(bvh, refs, ValidationOptions{.allow_dropped_duplicates = true}).summary();

  // Drop the only reference to triangle 9 as well: now a triangle is lost.
  Bvh broken = bvh;
  BvhNode& leaf = broken[broken.root];
  ASSERT_TRUE(leaf.is_leaf());
  ASSERT_EQ(leaf.ref_count(), 2u);
  std::vector<uint32_t> kept(broken.ref_indices.begin(), broken.ref_indices.begin() + 2);
  uint32_t tri9_slot = refs.triangle_ids[kept[0]] == 9 ? 0 : 1;
  std::swap(broken.ref_indices[tri9_slot], broken.ref_indices[1]);
  leaf.make_leaf(leaf.first_ref(), 1);
  broken.ref_indices.resize(1);
  ValidationReport r = validate(broken, refs, ValidationOptions{.allow_dropped_duplicates = true});
  EXPECT_FALSE(r.ok());
  EXPECT_NE(r.summary().find("triangle 9"), std::string::npos) << r.summary();
}

}  // namespace
}  // namespace bvhopt

namespace bvhopt {
namespace {

// The plain copy of a tree's reachable nodes in depth-first order, leaf slots in that order.
Bvh depth_first_copy(const Bvh& tree) {
  Bvh expected;
  std::vector<uint32_t> order = tree.depth_first_order();
  std::vector<uint32_t> index(tree.nodes.size(), kInvalidNode);
  for (uint32_t i = 0; i < order.size(); ++i) index[order[i]] = i;
  for (uint32_t n : order) {
    BvhNode nd = tree.nodes[n];
    if (nd.parent != kInvalidNode) nd.parent = index[nd.parent];
    if (nd.is_leaf()) {
      const uint32_t first = static_cast<uint32_t>(expected.ref_indices.size());
      for (uint32_t k = 0; k < nd.ref_count(); ++k) expected.ref_indices.push_back(tree.ref_indices[nd.first_ref() + k]);
      nd.make_leaf(first, nd.ref_count());
    } else {
      nd.make_inner(index[nd.left()], index[nd.right()]);
    }
    expected.nodes.push_back(nd);
  }
  return expected;
}

void expect_same_depth_first_tree(const Bvh& got, const Bvh& want) {
  ASSERT_EQ(got.root, 0u);
  ASSERT_EQ(got.nodes.size(), want.nodes.size());
  ASSERT_EQ(0, std::memcmp(got.nodes.data(), want.nodes.data(), want.nodes.size() * sizeof(BvhNode)));
  ASSERT_EQ(got.ref_indices, want.ref_indices);
}

// renumber_depth_first works in place (cycles of swaps); it must give exactly what the plain
// copy in depth-first order gives, also with unreachable nodes to drop.
TEST(Renumber, InPlaceEqualsACopyInDepthFirstOrder) {
  for (uint32_t trial = 0; trial < 40; ++trial) {
    PrimitiveRefs refs = testing::random_refs(50 + trial * 37, 300 + trial);
    Bvh bvh = build_sweep_sah(refs);
    std::mt19937 rng(trial);
    if (trial % 3 == 2) {
      // As collapse_leaves leaves it: some subtrees made leaves of all their slots (the sweep
      // builder gives every subtree a contiguous range), their nodes below unreachable and,
      // after the shuffle, spread among the reachable ones.
      for (uint32_t n = 1; n < bvh.nodes.size(); ++n) {
        if (bvh.nodes[n].is_leaf() || rng() % 8 != 0) continue;
        uint32_t lo = ~0u, hi = 0;
        std::vector<uint32_t> todo{n};
        while (!todo.empty()) {
          const BvhNode& c = bvh.nodes[todo.back()];
          todo.pop_back();
          if (c.is_leaf()) {
            lo = std::min(lo, c.first_ref()), hi = std::max(hi, c.first_ref() + c.ref_count());
          } else {
            todo.push_back(c.left()), todo.push_back(c.right());
          }
        }
        bvh.nodes[n].make_leaf(lo, hi - lo);
      }
    }
    // Shuffle the numbering and leave a few unreachable nodes (a detached subtree's parent).
    std::vector<uint32_t> perm(bvh.nodes.size());
    for (uint32_t i = 0; i < perm.size(); ++i) perm[i] = i;
    std::shuffle(perm.begin(), perm.end(), rng);
    Bvh shuffled = bvh;
    for (uint32_t i = 0; i < perm.size(); ++i) {
      BvhNode nd = bvh.nodes[i];
      if (nd.parent != kInvalidNode) nd.parent = perm[nd.parent];
      if (!nd.is_leaf()) nd.make_inner(perm[nd.left()], perm[nd.right()]);
      shuffled.nodes[perm[i]] = nd;
    }
    shuffled.root = perm[bvh.root];
    if (trial % 2 == 1) shuffled.nodes.push_back(BvhNode{});  // unreachable
    const Bvh expected = depth_first_copy(shuffled);
    shuffled.renumber_depth_first();
    expect_same_depth_first_tree(shuffled, expected);
    ASSERT_TRUE(validate(shuffled, refs).ok());
  }
}

// for_each_children_first visits each reachable node once, after its children, on a tree
// numbered depth-first (from the array's end, no order allocated) and on any other (its
// post-order): the costs computed bottom-up over it depend on that.
TEST(Renumber, ChildrenFirstVisitsEveryReachableNodeAfterItsChildren) {
  PrimitiveRefs refs = testing::random_refs(200, 3);
  const Bvh built = build_sweep_sah(refs);
  ASSERT_TRUE(built.numbered_depth_first());
  Bvh swapped = built;  // the root's children swapped: numbers no longer depth-first
  {
    const uint32_t l = swapped.nodes[swapped.root].left(), r = swapped.nodes[swapped.root].right();
    swapped.nodes[swapped.root].make_inner(r, l);
  }
  Bvh extra = built;  // an unreachable node
  extra.nodes.push_back(BvhNode{});
  EXPECT_FALSE(swapped.numbered_depth_first());
  EXPECT_FALSE(extra.numbered_depth_first());
  EXPECT_FALSE(Bvh{}.numbered_depth_first());
  for (const Bvh* t : std::vector<const Bvh*>{&built, &swapped, &extra}) {
    std::vector<int> seen_at(t->nodes.size(), -1);
    int step = 0;
    for_each_children_first(*t, [&](uint32_t n) {
      ASSERT_LT(n, t->nodes.size());
      ASSERT_EQ(seen_at[n], -1) << "node " << n << " visited twice";
      const BvhNode& nd = t->nodes[n];
      if (!nd.is_leaf()) {
        ASSERT_NE(seen_at[nd.left()], -1) << "node " << n << " before its left child";
        ASSERT_NE(seen_at[nd.right()], -1) << "node " << n << " before its right child";
      }
      seen_at[n] = step++;
    });
    const std::vector<uint32_t> reachable = t->depth_first_order();
    EXPECT_EQ(static_cast<size_t>(step), reachable.size());
    for (uint32_t n : reachable) EXPECT_NE(seen_at[n], -1) << "node " << n << " not visited";
  }
}

// A tree already numbered depth-first is left as it is (renumbering returns early); one that
// differs from that anywhere, in a node's place, an unused node or slot, or the order of the
// leaves' slots, is still renumbered.
TEST(Renumber, OnlyATreeAlreadyInOrderIsLeftAsItIs) {
  PrimitiveRefs refs = testing::random_refs(300, 7);
  SweepSahConfig cfg;
  cfg.leaf.max_leaf_size = 4;
  const Bvh built = build_sweep_sah(refs, cfg);
  {
    Bvh same = built;
    same.renumber_depth_first();
    expect_same_depth_first_tree(same, depth_first_copy(built));
    expect_same_depth_first_tree(same, built);
  }
  // Each variant is a tree over the same references, but not in order.
  std::vector<std::pair<const char*, Bvh>> variants;
  {
    Bvh t = built;
    t.nodes.push_back(BvhNode{});  // an unreachable node at the end
    variants.emplace_back("unreachable node", t);
  }
  {
    Bvh t = built;
    t.ref_indices.push_back(t.ref_indices.front());  // a slot no leaf uses
    variants.emplace_back("unused slot", t);
  }
  {
    // The root's children swapped: every node keeps its number, which is no longer its place.
    Bvh t = built;
    const uint32_t l = t.nodes[t.root].left(), r = t.nodes[t.root].right();
    t.nodes[t.root].make_inner(r, l);
    variants.emplace_back("children swapped", t);
  }
  {
    // The first two leaves exchange their slots (their references move with them).
    Bvh t = built;
    std::vector<uint32_t> leaves;
    for (uint32_t n : t.depth_first_order())
      if (t.nodes[n].is_leaf()) leaves.push_back(n);
    ASSERT_GE(leaves.size(), 2u);
    BvhNode& a = t.nodes[leaves[0]];
    BvhNode& b = t.nodes[leaves[1]];
    std::vector<uint32_t> slots(t.ref_indices.begin() + a.first_ref(), t.ref_indices.begin() + b.first_ref() + b.ref_count());
    std::rotate(slots.begin(), slots.begin() + a.ref_count(), slots.end());
    std::copy(slots.begin(), slots.end(), t.ref_indices.begin() + a.first_ref());
    const uint32_t first = a.first_ref(), na = a.ref_count(), nb = b.ref_count();
    b.make_leaf(first, nb);
    a.make_leaf(first + nb, na);
    variants.emplace_back("leaf slots out of order", t);
  }
  for (auto& [name, t] : variants) {
    SCOPED_TRACE(name);
    const Bvh expected = depth_first_copy(t);
    t.renumber_depth_first();
    expect_same_depth_first_tree(t, expected);
    ASSERT_TRUE(validate(t, refs).ok());
  }
}

}  // namespace
}  // namespace bvhopt
