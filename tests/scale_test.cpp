// Results do not depend on the scene's scale or position (issue 14, item 3): the same trees
// and costs for a scene scaled by 2^-60, 1 and 2^60, boxes of a far-away scene padded by a
// few ulps of their own coordinates, the same ray hits at every scale (checked against an
// oracle that shares no code with the tracers), and costs that are never NaN.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/testing/brute_force.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/binary_layout.h"
#include "bvhopt/wide_tracer.h"
#include "test_support.h"

namespace bvhopt {
namespace {

Mesh transformed(Mesh mesh, float scale, float offset = 0.0f) {
  for (float& p : mesh.positions) p = p * scale + offset;
  return mesh;
}

struct Outcome {
  std::string tree;
  double cost = 0.0;
};

// Every builder, then every optimizer on the sweep tree, then the collapse.
std::vector<Outcome> pipeline(const Mesh& mesh) {
  const PrimitiveRefs refs = make_references(mesh);
  std::vector<Outcome> out;
  for (BuilderKind kind : all_builders()) {
    BuildOptions o;
    o.kind = kind;
    Bvh bvh = build_bvh(refs, o);
    out.push_back({testing::tree_signature(bvh, refs), sah_cost(bvh)});
  }
  const Bvh start = build_bvh(refs, {});
  {
    Bvh bvh = start;
    InsertionConfig c;
    c.limits.max_passes = 12;
    const OptimizeReport r = optimize_insertion(bvh, c);
    out.push_back({testing::tree_signature(bvh, refs), r.final_cost});
  }
  {
    Bvh bvh = start;
    HillClimbConfig c;
    c.limits.max_passes = 6;
    const OptimizeReport r = hill_climb(bvh, c);
    out.push_back({testing::tree_signature(bvh, refs), r.final_cost});
  }
  {
    Bvh bvh = start;
    AnnealConfig c;
    c.limits.max_passes = 8;
    c.schedule_passes = 6;
    const OptimizeReport r = anneal(bvh, c);
    out.push_back({testing::tree_signature(bvh, refs), r.final_cost});
  }
  {
    Bvh bvh = start;
    const double ocost = optimal_collapse_cost(bvh);
    CollapseConfig c;
    const CollapseResult r = collapse_leaves(bvh, c);
    out.push_back({testing::tree_signature(bvh, refs), r.cost_after});
    out.push_back({"ocost", ocost});
  }
  return out;
}

// Scaling by a power of two is exact in every coordinate and, with areas in double, in every
// area (by 4^k) and every cost ratio: the trees and costs must be bit for bit the same.
TEST(Scale, SameTreesAndCostsAtTwoToTheMinus60OneAndTwoToThe60) {
  const Mesh mesh = testing::random_mesh(700, 21, true);
  const std::vector<Outcome> unit = pipeline(mesh);
  for (float scale : {0x1p-60f, 0x1p60f}) {
    const std::vector<Outcome> scaled = pipeline(transformed(mesh, scale));
    ASSERT_EQ(scaled.size(), unit.size());
    for (size_t i = 0; i < unit.size(); ++i) {
      EXPECT_TRUE(std::isfinite(scaled[i].cost)) << "step " << i << " scale " << scale;
      EXPECT_EQ(scaled[i].cost, unit[i].cost) << "step " << i << " scale " << scale;
      EXPECT_EQ(scaled[i].tree, unit[i].tree) << "step " << i << " scale " << scale;
    }
  }
}

// How far `padded` lies outside `exact`, in ulps of `exact`.
double ulps_out(float exact, float padded) {
  const double ulp = std::nextafter(std::fabs(exact), std::numeric_limits<float>::infinity()) - std::fabs(exact);
  return std::fabs(double(padded) - double(exact)) / ulp;
}

// A scene 1e6 or 1e7 from the origin (georeferenced): the traced boxes grow by a few ulps
// of their own coordinates, not by a fraction of the distance to the origin, and traversal
// still finds every hit of the brute force with the same triangle test.
TEST(Scale, FarFromTheOriginBoxesGrowByAFewUlps) {
  const Mesh base = testing::random_mesh(600, 5, true);
  for (float offset : {1e6f, 1e7f}) {
    const Mesh mesh = transformed(base, 1.0f, offset);
    const PrimitiveRefs refs = make_references(mesh);
    const FlatBvh flat = flatten_for_tracing(build_bvh(refs, {}), refs);
    const BinaryLayout layout = make_binary_layout(flat, mesh);
    // Each inner flat node's children, in the layout's order (a node's left child follows it).
    double worst = 0.0;
    size_t pair = 0;
    for (size_t i = 0; i < flat.nodes.size(); ++i) {
      if (flat.nodes[i].is_leaf()) continue;
      const BinaryNode& b = layout.nodes[pair++];
      const FlatNode* kids[2] = {&flat.nodes[i + 1], &flat.nodes[flat.nodes[i].index]};
      for (int s = 0; s < 2; ++s) {
        // The slot holds one of the two children; take the nearer.
        double best = std::numeric_limits<double>::infinity();
        for (const FlatNode* k : kids) {
          const Box& e = k->box;
          const double d = std::max({ulps_out(e.min.x, b.x[s]), ulps_out(e.max.x, b.x[s + 2]), ulps_out(e.min.y, b.y[s]),
                                     ulps_out(e.max.y, b.y[s + 2]), ulps_out(e.min.z, b.z[s]), ulps_out(e.max.z, b.z[s + 2])});
          best = std::min(best, d);
        }
        worst = std::max(worst, best);
      }
    }
    EXPECT_GE(pair, 100u);
    EXPECT_LE(worst, 8.0) << "offset " << offset;

    const Tracer tracer(flat, mesh);
    RaySetConfig cfg;
    cfg.kind = RayKind::random;
    cfg.count = 3000;
    const RaySet set = make_ray_set(mesh, tracer, cfg);
    size_t hits = 0, mismatches = 0;
    for (const Ray& r : set.rays) {
      TraceCounters counters;
      const Hit h = tracer.closest(r, counters);
      const Hit want = brute_force_closest(mesh, r);
      hits += want.hit();
      mismatches += h.triangle_id != want.triangle_id;
    }
    EXPECT_GT(hits, 300u) << "offset " << offset;
    EXPECT_EQ(mismatches, 0u) << "offset " << offset;
  }
}

struct RayOutcome {
  std::vector<uint32_t> binary, wide_mt, wide_watertight;
  size_t hits = 0;
  size_t oracle_disagreements = 0;  // rays where a tracer and the double oracle differ
};

// Primary or random rays from the scene's own default camera or box, through the binary
// tracer and both wide triangle tests, each ray also through the double-precision oracle.
RayOutcome trace_at(const Mesh& mesh, RayKind kind) {
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = flatten_for_tracing(build_bvh(refs, {}), refs);
  const Tracer tracer(flat, mesh);
  WideTracerOptions wt;
  wt.layout.test = TriangleTest::watertight;
  const WideTracer wide_mt(flat, mesh), wide_wt(flat, mesh, wt);
  RaySetConfig cfg;
  cfg.kind = kind;
  cfg.count = 2500;
  const RaySet set = make_ray_set(mesh, tracer, cfg);
  RayOutcome out;
  for (const Ray& r : set.rays) {
    TraceCounters counters;
    const uint32_t b = tracer.closest(r, counters).triangle_id;
    const uint32_t m = wide_mt.closest(r, counters).triangle_id;
    const uint32_t w = wide_wt.closest(r, counters).triangle_id;
    out.binary.push_back(b);
    out.wide_mt.push_back(m);
    out.wide_watertight.push_back(w);
    const Hit oracle = brute_force_closest_double(mesh, r);
    out.hits += oracle.hit();
    // Hit or miss must agree; two triangles at the same distance (a shared edge) may differ.
    for (uint32_t id : {b, m, w}) out.oracle_disagreements += (id != Hit{}.triangle_id) != oracle.hit();
  }
  return out;
}

// The same hits at every power-of-two scale (exact), and always the oracle's. The range is
// 2^+-50 here: the float triangle tests square edge lengths, which stays a normal float for
// this scene's smallest triangles down to 2^-50 (areas are double everywhere else).
TEST(Scale, SameRayHitsAtEveryScale) {
  const Mesh unit = transformed(testing::random_mesh(1500, 3), 0x1p-7f);  // about 0.8 across
  for (RayKind kind : {RayKind::primary, RayKind::random}) {
    const RayOutcome ref = trace_at(unit, kind);
    EXPECT_GT(ref.hits, ref.binary.size() / 10) << ray_kind_name(kind);
    EXPECT_LE(ref.oracle_disagreements, ref.binary.size() / 500) << ray_kind_name(kind);
    for (float scale : {0x1p-50f, 0x1p50f}) {
      const RayOutcome s = trace_at(transformed(unit, scale), kind);
      const std::string what = std::string(ray_kind_name(kind)) + " scale " + std::to_string(scale);
      EXPECT_EQ(s.hits, ref.hits) << what;
      EXPECT_EQ(s.binary, ref.binary) << what;
      EXPECT_EQ(s.wide_mt, ref.wide_mt) << what;
      EXPECT_EQ(s.wide_watertight, ref.wide_watertight) << what;
      EXPECT_LE(s.oracle_disagreements, s.binary.size() / 500) << what;
    }
  }
}

// A scene whose coordinates reach 1e15 (not a power-of-two scale): primary rays hit as
// often as at scale 1 and as the oracle says (they used to hit nothing above about 1e13,
// where the triangle tests' distance numerator, a cube of the scale, overflowed).
TEST(Scale, PrimaryRaysHitAt1e13) {
  const Mesh unit = testing::random_mesh(1500, 4);
  const RayOutcome ref = trace_at(unit, RayKind::primary);
  const RayOutcome big = trace_at(transformed(unit, 1e13f), RayKind::primary);
  const double rate = double(ref.hits) / ref.binary.size(), big_rate = double(big.hits) / big.binary.size();
  EXPECT_GT(rate, 0.05);
  EXPECT_NEAR(big_rate, rate, 0.01);
  EXPECT_LE(big.oracle_disagreements, big.binary.size() / 500);
}

// ---- Non-finite costs ------------------------------------------------------------------------

TEST(Scale, NonFiniteCostIsAnErrorNeverAResult) {
  const PrimitiveRefs refs = testing::random_refs(300, 2);
  const Bvh bvh = build_bvh(refs, {});
  CostModel nan_model;
  nan_model.traversal = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(sah_cost(bvh, nan_model), Error);
  EXPECT_THROW(optimal_collapse_cost(bvh, nan_model), Error);
  {
    Bvh t = bvh;
    InsertionConfig c;
    c.cost = nan_model;
    c.limits.max_passes = 3;
    EXPECT_THROW(optimize_insertion(t, c), Error);
  }
  {
    Bvh t = bvh;
    HillClimbConfig c;
    c.cost = nan_model;
    c.limits.max_passes = 3;
    EXPECT_THROW(hill_climb(t, c), Error);
  }
  {
    Bvh t = bvh;
    CollapseConfig c;
    c.cost = nan_model;
    EXPECT_THROW(collapse_leaves(t, c), Error);
  }
  // A box reaching infinity has an infinite area: the cost is not a number either.
  Bvh inf_box = bvh;
  inf_box[inf_box.root].box.max.x = std::numeric_limits<float>::infinity();
  EXPECT_THROW(sah_cost(inf_box), Error);
  try {
    sah_cost(bvh, nan_model);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("NaN"), std::string::npos) << e.what();
  }
}

// ---- Zero-area roots ---------------------------------------------------------------------------

// Nine coincident points: the limit of the formula as every box grows alike is
// c_T * inner + c_I * references = 3 * 8 + 2 * 9 = 42 for nine leaves, and 2 * 9 = 18 once
// collapsed into one leaf. Every optimizer reports that same number, never NaN.
TEST(Scale, CoincidentPointsCostTheFormulasLimit) {
  const Vec3 p(5, 5, 5);
  const PrimitiveRefs refs = make_references(std::vector<Box>(9, Box(p, p)));
  const Bvh bvh = build_bvh(refs, {});
  ASSERT_EQ(bvh.leaf_count(), 9u);
  EXPECT_EQ(sah_cost(bvh), 42.0);
  // The limit it is: cubes of any side d around the point give exactly 42.
  for (float d : {1e-3f, 1.0f}) {
    Bvh grown = bvh;
    for (BvhNode& n : grown.nodes) n.box = Box(p - Vec3(d), p + Vec3(d));
    EXPECT_DOUBLE_EQ(sah_cost(grown), 42.0);
  }
  EXPECT_EQ(optimal_collapse_cost(bvh), 18.0);
  {
    Bvh t = bvh;
    InsertionConfig c;
    c.limits.max_passes = 5;
    const OptimizeReport r = optimize_insertion(t, c);
    EXPECT_EQ(r.initial_cost, 42.0);
    EXPECT_EQ(r.final_cost, 42.0);
  }
  for (bool annealing : {false, true}) {
    Bvh t = bvh;
    OptimizeReport r;
    if (annealing) {
      AnnealConfig c;
      c.limits.max_passes = 5;
      r = anneal(t, c);
    } else {
      HillClimbConfig c;
      c.limits.max_passes = 5;
      r = hill_climb(t, c);
    }
    EXPECT_EQ(r.initial_cost, 42.0);
    EXPECT_EQ(r.final_cost, 42.0);
  }
  Bvh t = bvh;
  const CollapseResult c = collapse_leaves(t);
  EXPECT_EQ(c.cost_before, 42.0);
  EXPECT_EQ(c.cost_after, 18.0);
}

// References on one axis-parallel segment: each box weighs its length relative to the
// root's, the limit of the areas' ratio as the boxes grow by d -> 0 on every side.
TEST(Scale, SegmentCostIsTheLimitOfThickenedBoxes) {
  const PrimitiveRefs refs = make_references(std::vector<Box>{Box({0, 0, 0}, {1, 0, 0}), Box({2, 0, 0}, {4, 0, 0})});
  const Bvh bvh = build_bvh(refs, {});
  ASSERT_EQ(bvh.leaf_count(), 2u);
  // c_T * 1 + c_I * (1/4 + 2/4)
  EXPECT_DOUBLE_EQ(sah_cost(bvh), 3.0 + 2.0 * 0.75);
  Bvh grown = bvh;
  const float d = 1e-4f;
  for (BvhNode& n : grown.nodes) n.box = Box(n.box.min - Vec3(d), n.box.max + Vec3(d));
  EXPECT_NEAR(sah_cost(grown), sah_cost(bvh), 1e-3);
}

// ---- Limits ------------------------------------------------------------------------------------

// A Bvh holds at most 2^30 references: its nodes (2n - 1, numbered from 0) then stay below
// bit 31, the leaf flag, where one more reference would make an inner node read as a leaf.
TEST(Limits, ReferenceCountIsCheckedWhereNodeIndicesStillFit) {
  EXPECT_NO_THROW(check_reference_count(kMaxReferences, "test"));
  EXPECT_THROW(check_reference_count(kMaxReferences + 1, "test"), Error);
  EXPECT_THROW(check_reference_count(size_t(0x7fffffff), "test"), Error);
  try {
    check_reference_count(kMaxReferences + 1, "median builder");
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("median builder"), std::string::npos) << e.what();
  }
  BvhNode n;
  n.make_inner(0, static_cast<uint32_t>(2 * kMaxReferences - 2));  // the last node of the largest tree
  EXPECT_FALSE(n.is_leaf());
  n.make_inner(0, static_cast<uint32_t>(2 * (kMaxReferences + 1) - 2));
  EXPECT_TRUE(n.is_leaf()) << "the limit is tight: one more reference and an inner node reads as a leaf";
}

// One leaf-size limit for traced trees, the same in finalize and flatten_for_tracing.
TEST(Limits, TracedLeafSizeIsOneLimitInBothFlatteners) {
  for (uint32_t count : {kMaxTracedLeafSize, kMaxTracedLeafSize + 1}) {
    const PrimitiveRefs refs = make_references(std::vector<Box>(count, Box({0, 0, 0}, {1, 1, 1})));
    Bvh bvh;
    bvh.nodes.resize(1);
    bvh.nodes[0].set_box(Box({0, 0, 0}, {1, 1, 1}));
    bvh.nodes[0].make_leaf(0, count);
    bvh.root = 0;
    for (uint32_t i = 0; i < count; ++i) bvh.ref_indices.push_back(i);
    if (count <= kMaxTracedLeafSize) {
      EXPECT_EQ(finalize(bvh, refs).nodes.at(0).count, count);
      EXPECT_EQ(flatten_for_tracing(bvh, refs).nodes.at(0).count, count);
    } else {
      EXPECT_THROW(finalize(bvh, refs), Error);
      EXPECT_THROW(flatten_for_tracing(bvh, refs), Error);
    }
  }
}

}  // namespace
}  // namespace bvhopt
