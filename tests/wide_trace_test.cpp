// Wide traversal against brute force: every builder and optimizer, widths 4 and 8, both
// triangle tests, both child orders, every ISA the machine has, with and without edge volume
// subdivision; the kernels against each other hit for hit; awkward rays for the slab test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/testing/brute_force.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/wide_tracer.h"
#include "test_support.h"
#include "trace/wide_kernels.h"

namespace bvhopt {
namespace {

std::vector<Isa> machine_isas() {
  std::vector<Isa> out;
  for (Isa isa : {Isa::sse42, Isa::avx2, Isa::avx512})
    if (isa_supported(isa)) out.push_back(isa);
  return out;
}

Hit oracle(const Mesh& mesh, const Ray& ray, TriangleTest test) {
  return test == TriangleTest::watertight ? brute_force_closest(mesh, ray) : brute_force_closest_mt(mesh, ray);
}

struct Variant {
  uint32_t width;
  TriangleTest test;
  NearFirst order;
  Isa isa;
  std::string name() const {
    return "bvh" + std::to_string(width) + " " + std::string(triangle_test_name(test)) + " " +
           (order == NearFirst::octant_order ? "octant" : "sorted") + " " + std::string(isa_name(isa));
  }
};

std::vector<Variant> all_variants() {
  std::vector<Variant> out;
  for (uint32_t w : {4u, 8u})
    for (TriangleTest t : {TriangleTest::moller_trumbore, TriangleTest::watertight})
      for (NearFirst o : {NearFirst::octant_order, NearFirst::distance_sort})
        for (Isa isa : machine_isas()) out.push_back({w, t, o, isa});
  return out;
}

WideTracerOptions variant_options(const Variant& v) {
  WideTracerOptions o;
  o.layout.collapse.width = v.width;
  o.layout.test = v.test;
  o.isa = v.isa;
  o.near_first = v.order;
  return o;
}

WideTracer make_tracer(const FlatBvh& flat, const Mesh& mesh, const Variant& v,
                       CollapseMethod method = CollapseMethod::sah_optimal) {
  WideTracerOptions o = variant_options(v);
  o.layout.collapse.method = method;
  return WideTracer(flat, mesh, o);
}

// Brute-force hits of a ray set for both triangle tests, computed once per set.
struct Expected {
  RaySet set;
  std::vector<Hit> hits[2];  // by TriangleTest
};

std::vector<Expected> expected_hits(const Mesh& mesh, const std::vector<RaySet>& sets) {
  std::vector<Expected> out;
  for (const RaySet& set : sets) {
    Expected e{set, {}};
    for (TriangleTest t : {TriangleTest::moller_trumbore, TriangleTest::watertight})
      for (const Ray& r : set.rays) e.hits[int(t)].push_back(oracle(mesh, r, t));
    out.push_back(std::move(e));
  }
  return out;
}

// Exact: same triangle (ties in t already go to the lowest id on both sides), same t, u, v.
// Returns the number of mismatches and records the first.
size_t count_mismatches(const WideTracer& tracer, const std::vector<Ray>& rays, const std::vector<Hit>& want,
                        RayQuery query, std::string& first) {
  std::vector<Hit> hits(rays.size());
  std::vector<uint8_t> any(rays.size());
  TraceCounters counters;
  tracer.closest(rays.data(), rays.size(), hits.data(), counters);
  if (query == RayQuery::any) tracer.any(rays.data(), rays.size(), any.data(), counters);
  size_t bad = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit& got = hits[i];
    const bool same = got.triangle_id == want[i].triangle_id &&
                      (!want[i].hit() || (got.t == want[i].t && got.u == want[i].u && got.v == want[i].v));
    const bool any_ok = query != RayQuery::any || (any[i] != 0) == want[i].hit();
    if (same && any_ok) continue;
    if (bad++ == 0)
      first = "ray " + std::to_string(i) + ": got " + std::to_string(got.triangle_id) + " t " + std::to_string(got.t) +
              ", brute force " + std::to_string(want[i].triangle_id) + " t " + std::to_string(want[i].t) +
              (any_ok ? "" : " (any-hit disagrees)");
  }
  return bad;
}

size_t count_mismatches(const WideTracer& tracer, const Mesh& mesh, const std::vector<Ray>& rays, RayQuery query,
                        TriangleTest test, std::string& first) {
  std::vector<Hit> want;
  for (const Ray& r : rays) want.push_back(oracle(mesh, r, test));
  return count_mismatches(tracer, rays, want, query, first);
}

void expect_all_variants_match(const FlatBvh& flat, const Mesh& mesh, const std::vector<Expected>& expected,
                               const std::string& what) {
  for (const Variant& v : all_variants()) {
    const WideTracer tracer = make_tracer(flat, mesh, v);
    for (const Expected& e : expected) {
      std::string first;
      const size_t bad = count_mismatches(tracer, e.set.rays, e.hits[int(v.test)], e.set.query, first);
      EXPECT_EQ(bad, 0u) << what << " " << v.name() << " " << ray_kind_name(e.set.kind) << ": " << first;
    }
  }
}

std::vector<RaySet> ray_sets_for(const Mesh& mesh, const FlatBvh& flat, size_t count,
                                 std::vector<RayKind> kinds = {RayKind::primary, RayKind::random, RayKind::ao,
                                                               RayKind::shadow}) {
  const Tracer tracer(flat, mesh);
  std::vector<RaySet> sets;
  for (RayKind kind : kinds) {
    RaySetConfig cfg;
    cfg.kind = kind;
    cfg.seed = 5;
    cfg.count = count;
    cfg.width = 64;
    cfg.height = 48;
    sets.push_back(make_ray_set(mesh, tracer, cfg));
  }
  return sets;
}

FlatBvh built(const Mesh& mesh, const PrimitiveRefs& refs, BuilderKind kind, uint32_t leaf,
              const std::function<void(Bvh&)>& optimize = {}) {
  BuildOptions options;
  options.kind = kind;
  options.leaf.max_leaf_size = leaf;
  Bvh bvh = build_bvh(refs, options);
  if (optimize) optimize(bvh);
  return finalize(bvh, refs);
}

TEST(WideTrace, EveryBuilderMatchesBruteForce) {
  const Mesh mesh = testing::random_mesh(1200, 21, /*with_degenerate=*/true);
  const PrimitiveRefs refs = make_references(mesh);
  const std::vector<RaySet> sets = ray_sets_for(mesh, built(mesh, refs, BuilderKind::sweep_sah, 1), 1500);
  for (const RaySet& set : sets) ASSERT_GE(set.rays.size(), 1000u);
  const std::vector<Expected> expected = expected_hits(mesh, sets);
  for (BuilderKind kind : all_builders())
    for (uint32_t leaf : {1u, 8u})
      expect_all_variants_match(built(mesh, refs, kind, leaf), mesh, expected,
                                std::string(builder_name(kind)) + " leaf " + std::to_string(leaf));
}

TEST(WideTrace, EveryOptimizerMatchesBruteForce) {
  const Mesh mesh = testing::random_mesh(800, 22, true);
  const PrimitiveRefs refs = make_references(mesh);
  const std::vector<RaySet> sets = ray_sets_for(mesh, built(mesh, refs, BuilderKind::sweep_sah, 1), 1200);
  InsertionConfig insertion;
  insertion.limits.max_passes = 20;
  HillClimbConfig hill;
  hill.limits.max_passes = 20;
  AnnealConfig anneal_config;
  anneal_config.schedule_passes = 30;
  anneal_config.period = 10;
  CollapseConfig compact;
  compact.max_leaf_size = 8;
  const std::vector<std::pair<std::string, std::function<void(Bvh&)>>> optimizers = {
      {"insertion", [&](Bvh& b) { optimize_insertion(b, insertion); }},
      {"hill-climb", [&](Bvh& b) { hill_climb(b, hill); }},
      {"anneal", [&](Bvh& b) { anneal(b, anneal_config); }},
      {"insertion+collapse",
       [&](Bvh& b) {
         optimize_insertion(b, insertion);
         collapse_leaves(b, compact);
       }},
  };
  const std::vector<Expected> expected = expected_hits(mesh, sets);
  for (const auto& [name, optimize] : optimizers)
    expect_all_variants_match(built(mesh, refs, BuilderKind::sweep_sah, 1, optimize), mesh, expected, name);
}

TEST(WideTrace, EdgeVolumeSubdivisionGivesOneHitPerTriangle) {
  const Mesh mesh = testing::random_mesh(600, 23, true);
  EdgeVolumeConfig evh;
  evh.t = 16;
  const EdgeVolumeResult split = subdivide_edge_volume(mesh, evh);
  ASSERT_GT(split.stats.ratio, 1.5);  // several references per triangle, else the test says nothing
  const std::vector<RaySet> sets = ray_sets_for(mesh, built(mesh, split.refs, BuilderKind::sweep_sah, 1), 1200);
  const std::vector<Expected> expected = expected_hits(mesh, sets);
  for (uint32_t leaf : {1u, 4u}) {
    const FlatBvh flat = built(mesh, split.refs, BuilderKind::sweep_sah, leaf);
    expect_all_variants_match(flat, mesh, expected, "evh leaf " + std::to_string(leaf));
    // Each triangle is stored once per leaf: no leaf repeats an id across its blocks.
    const WideBvh wide(flat, mesh);
    EXPECT_LE(wide.stats().leaves, flat.triangle_ids.size());
  }
}

TEST(WideTrace, GreedyCollapseMatchesBruteForce) {
  const Mesh mesh = testing::random_mesh(700, 24, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::binned_sah, 4);
  const std::vector<RaySet> sets = ray_sets_for(mesh, flat, 1000);
  for (uint32_t w : {4u, 8u}) {
    const Variant v{w, TriangleTest::moller_trumbore, NearFirst::octant_order, default_isa()};
    const WideTracer tracer = make_tracer(flat, mesh, v, CollapseMethod::greedy);
    for (const RaySet& set : sets) {
      std::string first;
      EXPECT_EQ(count_mismatches(tracer, mesh, set.rays, set.query, v.test, first), 0u) << first;
    }
  }
}

TEST(WideTrace, EveryIsaAgreesHitForHitAndCountsTheSameWork) {
  const Mesh mesh = testing::random_mesh(3000, 25, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  const std::vector<RaySet> sets = ray_sets_for(mesh, flat, 4000);
  const std::vector<Isa> isas = machine_isas();
  ASSERT_FALSE(isas.empty());
  for (uint32_t w : {4u, 8u}) {
    for (TriangleTest test : {TriangleTest::moller_trumbore, TriangleTest::watertight}) {
      for (const RaySet& set : sets) {
        std::vector<Hit> reference;
        for (Isa isa : isas) {
          const WideTracer tracer = make_tracer(flat, mesh, {w, test, NearFirst::octant_order, isa});
          std::vector<Hit> hits(set.rays.size());
          TraceCounters c;
          tracer.closest(set.rays.data(), set.rays.size(), hits.data(), c);
          if (reference.empty()) {
            reference = hits;
            continue;
          }
          for (size_t i = 0; i < hits.size(); ++i) {
            ASSERT_EQ(hits[i].triangle_id, reference[i].triangle_id) << isa_name(isa) << " ray " << i;
            ASSERT_EQ(hits[i].t, reference[i].t) << isa_name(isa) << " ray " << i;
            ASSERT_EQ(hits[i].u, reference[i].u);
            ASSERT_EQ(hits[i].v, reference[i].v);
          }
        }
      }
    }
  }
}

// The kernel orders children with branches for coherent batches and (AVX-512) without for
// the others; the choice rests on rays_coherent. Camera rays must count as coherent and
// secondary rays, or camera rays in random order, must not.
TEST(WideTrace, CameraRaysAreCoherentAndSecondaryRaysAreNot) {
  const Mesh mesh = testing::random_mesh(2000, 31, false);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  const std::vector<RaySet> sets = ray_sets_for(mesh, flat, 3000, {RayKind::primary, RayKind::random, RayKind::ao});
  EXPECT_TRUE(wide_kernels::rays_coherent(sets[0].rays.data(), sets[0].rays.size()));
  EXPECT_FALSE(wide_kernels::rays_coherent(sets[1].rays.data(), sets[1].rays.size()));
  EXPECT_FALSE(wide_kernels::rays_coherent(sets[2].rays.data(), sets[2].rays.size()));
  std::vector<Ray> shuffled = sets[0].rays;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(3));
  EXPECT_FALSE(wide_kernels::rays_coherent(shuffled.data(), shuffled.size()));
  // A ray alone, or none, takes the branches (their history carries over between calls).
  EXPECT_TRUE(wide_kernels::rays_coherent(sets[1].rays.data(), 1));
  EXPECT_TRUE(wide_kernels::rays_coherent(nullptr, 0));
}

// Both ways of ordering push the same children in the same order, so the same rays traced
// as a coherent batch and as a shuffled one give the same hits and the same work, ray by ray.
TEST(WideTrace, CoherentAndIncoherentBatchesGiveTheSameHitsAndWork) {
  const Mesh mesh = testing::random_mesh(3000, 33, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  const RaySet camera = ray_sets_for(mesh, flat, 3072, {RayKind::primary})[0];
  std::vector<size_t> order(camera.rays.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), std::mt19937(4));
  std::vector<Ray> shuffled(order.size());
  for (size_t i = 0; i < order.size(); ++i) shuffled[i] = camera.rays[order[i]];
  ASSERT_TRUE(wide_kernels::rays_coherent(camera.rays.data(), camera.rays.size()));
  ASSERT_FALSE(wide_kernels::rays_coherent(shuffled.data(), shuffled.size()));
  for (Isa isa : machine_isas())
    for (uint32_t w : {4u, 8u}) {
      // Nearest first throughout: in slot order (ClosestHitOrder::adaptive) the shuffled
      // batch's runs of mostly missing rays would count other work.
      WideTracerOptions o = variant_options({w, TriangleTest::moller_trumbore, NearFirst::octant_order, isa});
      o.closest_hit_order = ClosestHitOrder::near_first;
      const WideTracer tracer(flat, mesh, o);
      std::vector<Hit> in_order(camera.rays.size()), mixed(camera.rays.size());
      TraceCounters a, b;
      tracer.closest(camera.rays.data(), camera.rays.size(), in_order.data(), a);
      tracer.closest(shuffled.data(), shuffled.size(), mixed.data(), b);
      EXPECT_EQ(a.steps, b.steps) << isa_name(isa) << " bvh" << w;
      EXPECT_EQ(a.triangle_tests, b.triangle_tests) << isa_name(isa) << " bvh" << w;
      size_t hits = 0;
      for (size_t i = 0; i < order.size(); ++i) {
        const Hit& x = in_order[order[i]];
        const Hit& y = mixed[i];
        ASSERT_EQ(x.triangle_id, y.triangle_id) << isa_name(isa) << " bvh" << w << " ray " << order[i];
        ASSERT_EQ(x.t, y.t);
        hits += x.triangle_id != kNoHit;
      }
      EXPECT_GT(hits, order.size() / 10) << "the camera must see the mesh for this test to mean anything";
      // Every ray alone gives the same too.
      for (size_t i = 0; i < 64; ++i) {
        TraceCounters c;
        const Hit h = tracer.closest(camera.rays[i * 37], c);
        ASSERT_EQ(h.triangle_id, in_order[i * 37].triangle_id);
        ASSERT_EQ(h.t, in_order[i * 37].t);
      }
    }
}

// The kernel traces rays side by side where neighbouring rays start far apart; the choice
// rests on rays_scattered. Random rays must count as scattered; camera, ambient occlusion
// and shadow rays (their origins a pixel's footprint apart, or the same) must not.
TEST(WideTrace, RandomRaysAreScatteredAndRaysFromTheCameraAreNot) {
  const Mesh mesh = testing::random_mesh(2000, 31, false);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  const float apart = wide_kernels::scatter_distance(flat.nodes[0].box);
  ASSERT_GT(apart, 0.0f);
  const std::vector<RaySet> sets =
      ray_sets_for(mesh, flat, 3000, {RayKind::primary, RayKind::random, RayKind::ao, RayKind::shadow});
  EXPECT_FALSE(wide_kernels::rays_scattered(sets[0].rays.data(), sets[0].rays.size(), apart));
  EXPECT_TRUE(wide_kernels::rays_scattered(sets[1].rays.data(), sets[1].rays.size(), apart));
  EXPECT_FALSE(wide_kernels::rays_scattered(sets[2].rays.data(), sets[2].rays.size(), apart));
  EXPECT_FALSE(wide_kernels::rays_scattered(sets[3].rays.data(), sets[3].rays.size(), apart));
  // The same ambient occlusion rays out of order start all over the mesh.
  std::vector<Ray> shuffled = sets[2].rays;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(3));
  EXPECT_TRUE(wide_kernels::rays_scattered(shuffled.data(), shuffled.size(), apart));
  // One ray, none, NaN origins, an empty scene: nothing to overlap, or nothing to judge by.
  EXPECT_FALSE(wide_kernels::rays_scattered(sets[1].rays.data(), 1, apart));
  EXPECT_FALSE(wide_kernels::rays_scattered(nullptr, 0, apart));
  std::vector<Ray> nan_rays = sets[1].rays;
  for (Ray& r : nan_rays) r.org.x = std::nanf("");
  EXPECT_FALSE(wide_kernels::rays_scattered(nan_rays.data(), nan_rays.size(), apart));
  EXPECT_EQ(wide_kernels::scatter_distance(Box::empty()), 0.0f);
}

// Rays traced side by side visit the same nodes in the same order as alone: every lane count
// gives the same hits, bit for bit, and the same counted work, on every ISA, width, triangle
// test and child order, for closest and any hits, and for batches smaller than the lanes or
// not a multiple of them.
TEST(WideTrace, RaysTracedSideBySideGiveTheSameHitsAndWork) {
  const Mesh mesh = testing::random_mesh(3000, 35, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  const RaySet random = ray_sets_for(mesh, flat, 2000, {RayKind::random})[0];
  const std::vector<Ray>& rays = random.rays;
  ASSERT_TRUE(wide_kernels::rays_scattered(rays.data(), rays.size(), wide_kernels::scatter_distance(flat.nodes[0].box)))
      << "the rays must be traced side by side for this test to mean anything";
  // Batches of these sizes, one after another, cover the whole set (several too small for
  // the lanes, and odd; 20 leaves 4 rays after the 16 traced alone first).
  const std::vector<size_t> batch_sizes{1, 2, 3, 5, 7, 20, 64, 255, 645};
  for (const Variant& v : all_variants()) {
    std::vector<Hit> reference;
    std::vector<uint8_t> reference_any;
    TraceCounters reference_counters;
    for (uint32_t lanes : {1u, 2u, 3u, 4u, 5u, 8u, 16u}) {
      WideTracerOptions o = variant_options(v);
      o.lanes = lanes;
      const WideTracer tracer(flat, mesh, o);
      std::vector<Hit> hits(rays.size());
      std::vector<uint8_t> any(rays.size());
      TraceCounters counters;
      for (size_t begin = 0, k = 0; begin < rays.size(); ++k) {
        const size_t n = std::min(batch_sizes[k % batch_sizes.size()], rays.size() - begin);
        tracer.closest(rays.data() + begin, n, hits.data() + begin, counters);
        tracer.any(rays.data() + begin, n, any.data() + begin, counters);
        begin += n;
      }
      if (lanes == 1) {
        reference = hits;
        reference_any = any;
        reference_counters = counters;
        size_t hit = 0;
        for (const Hit& h : hits) hit += h.hit();
        ASSERT_GT(hit, rays.size() / 10) << v.name() << ": the rays must hit the mesh for this test to mean anything";
        ASSERT_LT(hit, rays.size());
        // Batches whose first rays take few steps are traced one ray at a time all the same.
        ASSERT_GT(counters.steps, 2 * 6 * rays.size()) << v.name() << ": too few steps per ray to go side by side";
        continue;
      }
      EXPECT_EQ(counters.steps, reference_counters.steps) << v.name() << " lanes " << lanes;
      EXPECT_EQ(counters.triangle_tests, reference_counters.triangle_tests) << v.name() << " lanes " << lanes;
      for (size_t i = 0; i < rays.size(); ++i) {
        ASSERT_EQ(hits[i].triangle_id, reference[i].triangle_id) << v.name() << " lanes " << lanes << " ray " << i;
        ASSERT_EQ(hits[i].t, reference[i].t) << v.name() << " lanes " << lanes << " ray " << i;
        ASSERT_EQ(hits[i].u, reference[i].u);
        ASSERT_EQ(hits[i].v, reference[i].v);
        ASSERT_EQ(any[i], reference_any[i]) << v.name() << " lanes " << lanes << " ray " << i;
        ASSERT_EQ(any[i] != 0, reference[i].hit()) << v.name() << " lanes " << lanes << " ray " << i;
      }
    }
  }
  WideTracerOptions too_many;
  too_many.lanes = kMaxTraceLanes + 1;
  EXPECT_THROW(WideTracer(flat, mesh, too_many), Error);
}

// Each ray through the per-ray entry points (closest(const Ray&), any(const Ray&): a kernel
// of its own, without a batch's set-up) against the same rays in batches: the same hits, the
// same answers to any-hit, the same counted work, for every width, triangle test, child order
// and ISA, on every ray set.
// Whether tracing these rays in one call takes a compacting kernel (incoherent batches, bvh8,
// the octant's order, AVX2 or AVX-512), where an any-hit ray from its far end goes first into
// the child it enters last; the per-ray kernel and the walk of coherent batches keep the
// octant's order, so their counted any-hit work may differ (their answers may not).
bool far_any_batch_compacts(const Variant& v, const std::vector<Ray>& rays, AnyHitOrder order) {
  return order == AnyHitOrder::far_first && v.width == 8 && v.order == NearFirst::octant_order &&
         v.isa != Isa::sse42 && rays.size() > 16 && !wide_kernels::rays_coherent(rays.data(), rays.size());
}

void expect_per_ray_calls_match_batches(const FlatBvh& flat, const Mesh& mesh, const std::vector<RaySet>& sets,
                                        const std::string& what) {
  for (const Variant& v : all_variants()) {
    // Closest-hit batches nearest first, as one ray a call is traced (ClosestHitOrder), and
    // any-hit batches from the far end (the adaptive orders have tests of their own below).
    WideTracerOptions nearest = variant_options(v);
    nearest.closest_hit_order = ClosestHitOrder::near_first;
    nearest.any_hit_order = AnyHitOrder::far_first;
    const WideTracer tracer(flat, mesh, nearest);
    for (const RaySet& set : sets) {
      const std::vector<Ray>& rays = set.rays;
      std::vector<Hit> batch_hits(rays.size());
      std::vector<uint8_t> batch_any(rays.size());
      TraceCounters batch_closest, batch_anyc;
      tracer.closest(rays.data(), rays.size(), batch_hits.data(), batch_closest);
      tracer.any(rays.data(), rays.size(), batch_any.data(), batch_anyc);
      TraceCounters one_closest, one_any;
      size_t hits = 0;
      for (size_t i = 0; i < rays.size(); ++i) {
        const Hit h = tracer.closest(rays[i], one_closest);
        const bool a = tracer.any(rays[i], one_any);
        hits += h.hit();
        ASSERT_EQ(h.triangle_id, batch_hits[i].triangle_id) << what << " " << v.name() << " ray " << i;
        ASSERT_EQ(h.t, batch_hits[i].t) << what << " " << v.name() << " ray " << i;
        ASSERT_EQ(h.u, batch_hits[i].u);
        ASSERT_EQ(h.v, batch_hits[i].v);
        ASSERT_EQ(a, batch_any[i] != 0) << what << " " << v.name() << " ray " << i;
      }
      ASSERT_GT(hits, 0u) << what << ": the rays must hit something for this test to mean anything";
      // A batch of many rays may order children another way (compaction on incoherent
      // batches, see CoherentAndIncoherentBatches...), which visits the same nodes in the same
      // order: the counted work is the same either way.
      EXPECT_EQ(one_closest.steps, batch_closest.steps) << what << " " << v.name() << " " << ray_kind_name(set.kind);
      EXPECT_EQ(one_closest.triangle_tests, batch_closest.triangle_tests) << what << " " << v.name();
      if (!far_any_batch_compacts(v, rays, AnyHitOrder::far_first)) {
        EXPECT_EQ(one_any.steps, batch_anyc.steps) << what << " " << v.name() << " " << ray_kind_name(set.kind);
        EXPECT_EQ(one_any.triangle_tests, batch_anyc.triangle_tests) << what << " " << v.name();
      } else {
        // The compacting kernels agree among themselves: one ray after another as side by side.
        WideTracerOptions o = nearest;
        o.lanes = 1;
        const WideTracer one_lane(flat, mesh, o);
        TraceCounters lane_work;
        std::vector<uint8_t> lane_any(rays.size());
        one_lane.any(rays.data(), rays.size(), lane_any.data(), lane_work);
        EXPECT_EQ(lane_any, batch_any) << what << " " << v.name();
        EXPECT_EQ(lane_work.steps, batch_anyc.steps) << what << " " << v.name() << " " << ray_kind_name(set.kind);
        EXPECT_EQ(lane_work.triangle_tests, batch_anyc.triangle_tests) << what << " " << v.name();
      }
    }
  }
}

TEST(WideTrace, PerRayCallsGiveTheSameHitsAndWorkAsBatches) {
  const Mesh mesh = testing::random_mesh(2000, 47, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  expect_per_ray_calls_match_batches(flat, mesh, ray_sets_for(mesh, flat, 1500), "sweep tree");
}

// Rays that mostly hit nothing, for the adaptive orders' tests: short rays inside the mesh's
// box, every sixteenth ray aimed from outside through a triangle's centroid; and a batch of
// aimed rays alone, which all hit.
struct MostlyMissingRays {
  std::vector<Ray> mostly_missing, hitting;
};

MostlyMissingRays mostly_missing_rays(const Mesh& mesh, uint32_t seed) {
  const Box box = mesh_bounds(mesh);
  const Vec3 extent = box.max - box.min;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const auto point_in_box = [&] {
    return Vec3{box.min.x + unit(rng) * extent.x, box.min.y + unit(rng) * extent.y, box.min.z + unit(rng) * extent.z};
  };
  const auto direction = [&] {
    for (;;) {
      const Vec3 d{2.0f * unit(rng) - 1.0f, 2.0f * unit(rng) - 1.0f, 2.0f * unit(rng) - 1.0f};
      const float len2 = d.x * d.x + d.y * d.y + d.z * d.z;
      if (len2 > 0.01f && len2 <= 1.0f) return d / std::sqrt(len2);
    }
  };
  const float diagonal = std::sqrt(extent.x * extent.x + extent.y * extent.y + extent.z * extent.z);
  // From outside the box through the centroid of a triangle of some area: it hits something.
  const auto aimed = [&] {
    for (;;) {
      const Triangle tri = mesh.triangle(size_t(unit(rng) * float(mesh.triangle_count() - 1)));
      const Vec3 e1 = tri.v1 - tri.v0, e2 = tri.v2 - tri.v0;
      const Vec3 n{e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
      if (n.x * n.x + n.y * n.y + n.z * n.z < 1e-8f * diagonal * diagonal * diagonal * diagonal) continue;
      const Vec3 centroid = (tri.v0 + tri.v1 + tri.v2) / 3.0f;
      const Vec3 d = direction();
      Ray r;
      r.org = centroid - d * (2.0f * diagonal);
      r.dir = d;
      return r;
    }
  };
  MostlyMissingRays out;
  for (size_t i = 0; i < 2048; ++i) {
    if (i % 16 == 0) {
      out.mostly_missing.push_back(aimed());
      continue;
    }
    Ray r;
    r.org = point_in_box();
    r.dir = direction();
    r.tmax = 0.002f * diagonal;
    out.mostly_missing.push_back(r);
  }
  for (size_t i = 0; i < 1024; ++i) out.hitting.push_back(aimed());
  return out;
}

double hit_share(const std::vector<Hit>& hits) {
  size_t hit = 0;
  for (const Hit& h : hits) hit += h.hit();
  return double(hit) / double(hits.size());
}

// A tracer with the adaptive orders (the default) and one with the usual ones (closest hit:
// nearest first; any hit: from the far end), one ray after the other: lanes would trace
// scattered rays side by side, in the usual order.
struct BothOrders {
  WideTracer adaptive, usual;
  BothOrders(const FlatBvh& flat, const Mesh& mesh, const Variant& v)
      : adaptive(flat, mesh, options(v, false)), usual(flat, mesh, options(v, true)) {}
  static WideTracerOptions options(const Variant& v, bool usual) {
    WideTracerOptions o = variant_options(v);
    o.lanes = 1;
    if (usual) {
      o.closest_hit_order = ClosestHitOrder::near_first;
      o.any_hit_order = AnyHitOrder::far_first;
    }
    return o;
  }
};

// Traces `rays` as `query` both ways, each with the answers of brute force; the work of each
// in `adaptive_work` and `usual_work`.
void trace_both_orders(const BothOrders& tracers, RayQuery query, const std::vector<Ray>& rays,
                       const std::vector<Hit>& want, TraceCounters& adaptive_work, TraceCounters& usual_work,
                       const std::string& what) {
  const WideTracer& adaptive = tracers.adaptive;
  const WideTracer& usual = tracers.usual;
  if (query == RayQuery::closest) {
    std::vector<Hit> a(rays.size()), u(rays.size());
    adaptive.closest(rays.data(), rays.size(), a.data(), adaptive_work);
    usual.closest(rays.data(), rays.size(), u.data(), usual_work);
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(a[i].triangle_id, want[i].triangle_id) << what << " ray " << i;
      ASSERT_EQ(u[i].triangle_id, want[i].triangle_id) << what << " ray " << i;
      if (want[i].hit()) {
        ASSERT_EQ(a[i].t, want[i].t) << what << " ray " << i;
        ASSERT_EQ(a[i].u, want[i].u);
        ASSERT_EQ(a[i].v, want[i].v);
      }
    }
  } else {
    std::vector<uint8_t> a(rays.size()), u(rays.size());
    adaptive.any(rays.data(), rays.size(), a.data(), adaptive_work);
    usual.any(rays.data(), rays.size(), u.data(), usual_work);
    for (size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(a[i] != 0, want[i].hit()) << what << " ray " << i;
      ASSERT_EQ(u[i] != 0, want[i].hit()) << what << " ray " << i;
    }
  }
}

// The rays of an incoherent batch enter children in slot order in the runs after a run where
// at most one ray in eight hit anything and the rays took 4 steps or more
// (ClosestHitOrder::adaptive and AnyHitOrder::adaptive). On a tree deep enough for that, a
// batch that mostly misses: the same answers as brute force and as the usual order
// (nearest first, or the far end first) on every variant, other counted work than the usual
// order (the slot order was taken: the aimed rays find their hit in another order), and the
// same counted work on every ISA (the choice rests on exact hits and counts, the slot order
// is the same on each). A batch of aimed rays alone, which all hit, counts the usual order's
// work exactly: it never leaves that order. Nor does the same mostly missing batch on a
// shallow tree, where its rays take fewer steps.
TEST(WideTrace, RaysThatMostlyMissEnterChildrenInSlotOrder) {
  // Deep enough for the mostly missing rays to take over 4 steps a ray in bvh4 and bvh8; the
  // small mesh's tree takes them fewer.
  const Mesh mesh = testing::random_mesh(12000, 71, true);
  const Mesh small = testing::random_mesh(200, 71, true);
  const FlatBvh deep = built(mesh, make_references(mesh), BuilderKind::sweep_sah, 4);
  const FlatBvh shallow = built(small, make_references(small), BuilderKind::sweep_sah, 4);
  const MostlyMissingRays rays = mostly_missing_rays(mesh, 9);
  const MostlyMissingRays small_rays = mostly_missing_rays(small, 9);
  for (const MostlyMissingRays* r : {&rays, &small_rays}) {
    ASSERT_FALSE(wide_kernels::rays_coherent(r->mostly_missing.data(), r->mostly_missing.size()));
    ASSERT_FALSE(wide_kernels::rays_coherent(r->hitting.data(), r->hitting.size()));
  }

  for (TriangleTest test : {TriangleTest::moller_trumbore, TriangleTest::watertight}) {
    std::vector<Hit> want_missing, want_hitting, want_small;
    for (const Ray& r : rays.mostly_missing) want_missing.push_back(oracle(mesh, r, test));
    for (const Ray& r : rays.hitting) want_hitting.push_back(oracle(mesh, r, test));
    for (const Ray& r : small_rays.mostly_missing) want_small.push_back(oracle(small, r, test));
    for (const std::vector<Hit>* want : {&want_missing, &want_small}) {
      ASSERT_GT(hit_share(*want), 0.04) << "the aimed rays must hit for this test to mean anything";
      ASSERT_LT(hit_share(*want), 0.1) << "the batch must mostly miss for this test to mean anything";
    }
    ASSERT_EQ(hit_share(want_hitting), 1.0);
    for (uint32_t w : {4u, 8u}) {
      for (RayQuery query : {RayQuery::closest, RayQuery::any}) {
        // The first ISA's work, and whether its any-hit rays from the far end go first into
        // the child entered last (far_any_batch_compacts): the ISAs that do agree among
        // themselves, as do those that walk the octant's order.
        std::optional<TraceCounters> first_isa[2];
        for (Isa isa : machine_isas()) {
          const Variant v{w, test, NearFirst::octant_order, isa};
          const BothOrders deep_tracers(deep, mesh, v), shallow_tracers(shallow, small, v);
          const std::string what = v.name() + (query == RayQuery::closest ? " closest" : " any");
          TraceCounters ca, cu;
          trace_both_orders(deep_tracers, query, rays.mostly_missing, want_missing, ca, cu, what + " deep");
          EXPECT_NE(ca.steps + ca.triangle_tests, cu.steps + cu.triangle_tests) << what << ": no slot order taken";
          const bool compacts = query == RayQuery::any && far_any_batch_compacts(v, rays.mostly_missing, AnyHitOrder::far_first);
          if (!first_isa[compacts]) {
            first_isa[compacts] = ca;
          } else {
            EXPECT_EQ(ca.steps, first_isa[compacts]->steps) << what;
            EXPECT_EQ(ca.triangle_tests, first_isa[compacts]->triangle_tests) << what;
          }
          TraceCounters ha, hu;
          trace_both_orders(deep_tracers, query, rays.hitting, want_hitting, ha, hu, what + " all hit");
          EXPECT_EQ(ha.steps, hu.steps) << what;
          EXPECT_EQ(ha.triangle_tests, hu.triangle_tests) << what;
          TraceCounters sa, su;
          trace_both_orders(shallow_tracers, query, small_rays.mostly_missing, want_small, sa, su, what + " shallow");
          EXPECT_EQ(sa.steps, su.steps) << what << " shallow";
          EXPECT_EQ(sa.triangle_tests, su.triangle_tests) << what << " shallow";
        }
      }
    }
  }
  EXPECT_EQ(parse_closest_hit_order("auto"), ClosestHitOrder::adaptive);
  EXPECT_EQ(parse_closest_hit_order("near"), ClosestHitOrder::near_first);
  EXPECT_FALSE(parse_closest_hit_order("far"));
  EXPECT_EQ(parse_any_hit_order("auto"), AnyHitOrder::adaptive);
  EXPECT_EQ(parse_any_hit_order("far"), AnyHitOrder::far_first);
  EXPECT_EQ(parse_any_hit_order("near"), AnyHitOrder::near_first);
  EXPECT_FALSE(parse_any_hit_order("middle"));
  EXPECT_EQ(WideTracerOptions{}.closest_hit_order, ClosestHitOrder::adaptive);
  EXPECT_EQ(WideTracerOptions{}.any_hit_order, AnyHitOrder::adaptive);
}

// Any-hit rays walk the octant order from the ray's far end by default (AnyHitOrder): from
// either end, every width, triangle test, child order and ISA answers as brute force does,
// ray by ray as in batches, with the same counted work both ways. And the option takes
// effect: from the far end a ray does the work the near-first walk does on the same segment
// traced the other way (its octant reversed), which differs from its own near-first work on
// shadow rays.
TEST(WideTrace, AnyHitRaysFromEitherEndGiveTheSameAnswers) {
  const Mesh mesh = testing::random_mesh(2000, 61, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 4);
  const std::vector<RaySet> sets = ray_sets_for(mesh, flat, 1500, {RayKind::ao, RayKind::shadow, RayKind::random});
  const std::vector<Expected> expected = expected_hits(mesh, sets);
  for (const Variant& v : all_variants()) {
    for (const Expected& e : expected) {
      const RaySet& set = e.set;
      const std::vector<Ray>& rays = set.rays;
      ASSERT_GE(rays.size(), 1000u);
      std::vector<Ray> reversed = rays;
      for (Ray& r : reversed) {
        ASSERT_TRUE(std::isfinite(r.tmax) && r.tmin == 0.0f);
        r.org = r.org + r.dir * r.tmax;
        r.dir = -r.dir;
      }
      TraceCounters work[2][2];  // [order][reversed]
      for (AnyHitOrder order : {AnyHitOrder::far_first, AnyHitOrder::near_first}) {
        WideTracerOptions o = variant_options(v);
        o.any_hit_order = order;
        const WideTracer tracer(flat, mesh, o);
        const std::string what = v.name() + " " + std::string(ray_kind_name(set.kind)) +
                                 (order == AnyHitOrder::far_first ? " far first" : " near first");
        for (int rev = 0; rev < 2; ++rev) {
          const std::vector<Ray>& in = rev ? reversed : rays;
          std::vector<uint8_t> batch(in.size());
          TraceCounters& batch_work = work[int(order)][rev];
          tracer.any(in.data(), in.size(), batch.data(), batch_work);
          TraceCounters one;
          size_t hit = 0;
          for (size_t i = 0; i < in.size(); ++i) {
            const bool a = tracer.any(in[i], one);
            ASSERT_EQ(a, batch[i] != 0) << what << " ray " << i;
            if (rev == 0) {
              ASSERT_EQ(a, e.hits[int(v.test)][i].hit()) << what << " ray " << i;
            }
            hit += a;
          }
          ASSERT_GT(hit, in.size() / 20) << what << ": too few rays hit for this test to mean anything";
          if (!far_any_batch_compacts(v, in, order)) {
            EXPECT_EQ(one.steps, batch_work.steps) << what;
            EXPECT_EQ(one.triangle_tests, batch_work.triangle_tests) << what;
          }
        }
      }
      if (v.order != NearFirst::octant_order) continue;  // distance_sort: nearest first either way
      // The mirror below holds for the octant's order alone.
      if (far_any_batch_compacts(v, rays, AnyHitOrder::far_first)) continue;
      const auto total = [](const TraceCounters& c) { return double(c.steps + c.triangle_tests); };
      const double far = total(work[int(AnyHitOrder::far_first)][0]);
      const double near = total(work[int(AnyHitOrder::near_first)][0]);
      const double near_reversed = total(work[int(AnyHitOrder::near_first)][1]);
      // The same boxes entered either way but for rounding at their faces: within 2 %.
      EXPECT_NEAR(far / near_reversed, 1.0, 0.02) << v.name() << " " << ray_kind_name(set.kind);
      // Shadow rays, most of them blocked, are where the two ends differ (AO and random rays
      // here are mostly unblocked, and a ray that hits nothing visits every box it enters).
      if (set.kind == RayKind::shadow) {
        EXPECT_NE(far, near) << v.name() << ": the order asked for is not the order walked";
      }
    }
  }
}

// An any-hit ray ends at the first leaf block that hits: eight triangles stacked along z in
// one leaf of two blocks, every one of them on the ray; closest-hit rays test both blocks.
TEST(WideTrace, AnyHitRaysStopAtTheFirstBlockThatHits) {
  Mesh mesh;
  for (uint32_t k = 0; k < 8; ++k) {
    const float z = float(k + 1);
    mesh.add_vertex({-10.0f, -10.0f, z});
    mesh.add_vertex({10.0f, -10.0f, z});
    mesh.add_vertex({0.0f, 10.0f, z});
    mesh.add_triangle(3 * k, 3 * k + 1, 3 * k + 2);
  }
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::object_median, 8);
  ASSERT_EQ(flat.nodes.size(), 1u);
  Ray ray;
  ray.org = Vec3(0.5f, 0.25f, 0.0f);
  ray.dir = Vec3(0.0f, 0.0f, 1.0f);
  ray.tmin = 0.0f;
  ray.tmax = 100.0f;
  const std::vector<Ray> rays(300, ray);  // a batch: the side-by-side and coherent kernels too
  for (const Variant& v : all_variants()) {
    const WideTracer tracer = make_tracer(flat, mesh, v);
    TraceCounters closest, any, batch;
    EXPECT_EQ(tracer.closest(ray, closest).triangle_id, 0u) << v.name();
    EXPECT_TRUE(tracer.any(ray, any)) << v.name();
    std::vector<uint8_t> hits(rays.size());
    tracer.any(rays.data(), rays.size(), hits.data(), batch);
    EXPECT_EQ(std::count(hits.begin(), hits.end(), 1), long(rays.size())) << v.name();
    EXPECT_EQ(closest.triangle_tests, 8u) << v.name();
    EXPECT_EQ(any.triangle_tests, 4u) << v.name();
    EXPECT_EQ(batch.triangle_tests, 4u * rays.size()) << v.name();
  }
}

// In an incoherent batch on bvh8 (the compacting kernels), an any-hit ray from its far end
// goes first into the child it enters last, by the entry distances rather than along its
// octant's diagonal. The rays run along x, spread by up to 6 degrees; each enters first the
// box of a triangle it misses (at x = 2.5, its centre far along the diagonal (1, 1, 1)),
// then the box of a wall it hits (at x = 10.5). Taking the wall first, a ray tests one block;
// walking the flipped octant's order (one ray a call, SSE4.2, bvh4), it tests the missed
// triangle's block first. Nearest first by distance (distance_sort) takes the near box first.
TEST(WideTrace, AnyHitRaysFromTheFarEndTakeTheChildEnteredLastFirst) {
  Mesh mesh;
  for (Vec3 p : {Vec3(10.5f, -5.0f, -5.0f), Vec3(10.5f, 15.0f, -5.0f), Vec3(10.5f, -5.0f, 15.0f)}) mesh.add_vertex(p);
  for (Vec3 p : {Vec3(2.5f, -1.0f, 40.0f), Vec3(2.5f, 40.0f, -1.0f), Vec3(2.5f, 40.0f, 40.0f)}) mesh.add_vertex(p);
  mesh.add_triangle(0, 1, 2);
  mesh.add_triangle(3, 4, 5);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 1);
  ASSERT_EQ(flat.nodes.size(), 3u);
  std::vector<Ray> rays;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 0.1f);
  for (int i = 0; i < 300; ++i) {
    Ray ray;
    ray.org = Vec3(0.0f, 0.0f, 0.0f);
    ray.dir = Vec3(1.0f, 0.01f + u(rng), 0.01f + u(rng));
    ray.tmin = 0.0f;
    ray.tmax = 100.0f;
    rays.push_back(ray);
  }
  ASSERT_FALSE(wide_kernels::rays_coherent(rays.data(), rays.size()));
  for (const Variant& v : all_variants()) {
    const WideTracer tracer = make_tracer(flat, mesh, v);
    TraceCounters one, batch;
    for (const Ray& ray : rays) EXPECT_TRUE(tracer.any(ray, one)) << v.name();
    std::vector<uint8_t> hits(rays.size());
    tracer.any(rays.data(), rays.size(), hits.data(), batch);
    EXPECT_EQ(std::count(hits.begin(), hits.end(), 1), long(rays.size())) << v.name();
    EXPECT_EQ(one.triangle_tests, 8u * rays.size()) << v.name();
    const uint32_t tests = far_any_batch_compacts(v, rays, AnyHitOrder::far_first) ? 4u : 8u;
    EXPECT_EQ(batch.triangle_tests, tests * rays.size()) << v.name();
  }
}

// A tree whose traversal may need more stack than the per-ray kernel's own (a caterpillar:
// each inner node a one-triangle leaf and the rest of the row) takes the batch path for
// single rays too, with the same results.
TEST(WideTrace, PerRayCallsOnATreeDeeperThanTheirStack) {
  const uint32_t n = 3000;
  Mesh mesh;
  for (uint32_t i = 0; i < n; ++i) {
    const float x = float(i);
    for (float v : {x, 0.0f, 0.0f, x + 0.5f, 0.0f, 0.0f, x, 1.0f, 0.5f}) mesh.positions.push_back(v);
    for (uint32_t k = 0; k < 3; ++k) mesh.indices.push_back(3 * i + k);
  }
  auto triangle_box = [&](uint32_t i) { return Box(Vec3(float(i), 0.0f, 0.0f), Vec3(float(i) + 0.5f, 1.0f, 0.5f)); };
  FlatBvh flat;
  // Depth-first: inner node k (triangles k..n-1) at 2k, its leaf (triangle k) at 2k + 1, the
  // inner node k + 1 at 2k + 2; the last inner node's right child is the last triangle's leaf.
  for (uint32_t k = 0; k + 1 < n; ++k) {
    FlatNode inner{};
    inner.box = Box(Vec3(float(k), 0.0f, 0.0f), Vec3(float(n - 1) + 0.5f, 1.0f, 0.5f));
    inner.index = 2 * k + 2;
    inner.axis = 0;
    flat.nodes.push_back(inner);
    FlatNode leaf{};
    leaf.box = triangle_box(k);
    leaf.index = k;
    leaf.count = 1;
    flat.nodes.push_back(leaf);
    flat.triangle_ids.push_back(k);
  }
  FlatNode last{};
  last.box = triangle_box(n - 1);
  last.index = n - 1;
  last.count = 1;
  flat.nodes.push_back(last);
  flat.triangle_ids.push_back(n - 1);
  for (uint32_t w : {4u, 8u}) {
    const WideTracer tracer = make_tracer(flat, mesh, {w, TriangleTest::moller_trumbore, NearFirst::octant_order,
                                                       machine_isas().back()});
    ASSERT_GT(tracer.layout().stack_entries(), wide_kernels::kOneRayStackEntries)
        << "bvh" << w << ": the tree must need more stack than the per-ray kernel has for this test to mean anything";
  }
  // Rays along the row, from both ends and through the middle, and across it.
  std::vector<Ray> rays;
  std::mt19937 rng(48);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int i = 0; i < 400; ++i) {
    Ray r;
    r.org = Vec3(i % 2 ? -10.0f : float(n) + 10.0f, u(rng) * 0.6f, 0.2f + 0.1f * u(rng));
    r.dir = Vec3(i % 2 ? 1.0f : -1.0f, 0.02f * (u(rng) - 0.5f), 0.01f * (u(rng) - 0.5f));
    rays.push_back(r);
    Ray across;
    across.org = Vec3(u(rng) * float(n), 0.3f * u(rng), -5.0f);
    across.dir = Vec3(0.0f, 0.0f, 1.0f);
    rays.push_back(across);
  }
  RaySet set;
  set.kind = RayKind::random;
  set.rays = rays;
  expect_per_ray_calls_match_batches(flat, mesh, {set}, "caterpillar");
  // And against brute force.
  for (const Variant& v : all_variants()) {
    const WideTracer tracer = make_tracer(flat, mesh, v);
    TraceCounters c;
    for (size_t i = 0; i < rays.size(); ++i) {
      const Hit want = oracle(mesh, rays[i], v.test), got = tracer.closest(rays[i], c);
      ASSERT_EQ(got.triangle_id, want.triangle_id) << v.name() << " ray " << i;
      ASSERT_EQ(got.t, want.t) << v.name() << " ray " << i;
    }
  }
}

TEST(WideTrace, HitsSomethingAndMissesSomething) {
  // Guards the comparisons above against a vacuous pass.
  const Mesh mesh = testing::random_mesh(1200, 21, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 1);
  const std::vector<RaySet> sets = ray_sets_for(mesh, flat, 1500);
  const WideTracer tracer(flat, mesh);
  for (const RaySet& set : sets) {
    size_t hit = 0;
    TraceCounters c;
    for (const Ray& r : set.rays) hit += tracer.closest(r, c).hit() ? 1 : 0;
    EXPECT_GT(hit, set.rays.size() / 50) << ray_kind_name(set.kind);
    if (set.kind == RayKind::random) {
      EXPECT_LT(hit, set.rays.size());
    }
    EXPECT_GT(c.steps, set.rays.size());
  }
}

// Slab test cases: boxes as single triangles' bounds, rays along the axes (with +0 and -0 in
// the other components), through box edges and corners, and with one or two zero components.
std::vector<Ray> slab_rays(const Mesh& mesh, uint64_t seed, size_t count, float distance = 3.0f) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Box box;
  for (size_t v = 0; v < mesh.vertex_count(); ++v) box.extend(mesh.vertex(v));
  const float far = distance * length(box.extent());
  std::vector<Ray> rays;
  for (size_t i = 0; i < count; ++i) {
    const Triangle t = mesh.triangle(rng() % mesh.triangle_count());
    const Box b = t.bounds();
    const int axis = int(rng() % 3), other = (axis + 1 + int(rng() % 2)) % 3;
    const float sign = rng() % 2 ? -1.0f : 1.0f;
    Ray r;
    Vec3 target;
    switch (i % 4) {
      case 0:  // a vertex (a corner of the triangle's box on two axes)
        target = (rng() % 2) ? t.v1 : t.v2;
        break;
      case 1:  // a point on an edge of the triangle's box
        target = b.min;
        target[other] = b.max[other];
        target[axis] = b.min[axis] + u(rng) * b.extent()[axis];
        break;
      case 2:  // a point inside the triangle
        target = t.v0 + (t.v1 - t.v0) * 0.3f + (t.v2 - t.v0) * 0.3f;
        break;
      default:  // the box corner itself
        target = rng() % 2 ? b.min : b.max;
        break;
    }
    r.dir = Vec3(sign < 0 ? -0.0f : 0.0f);
    r.dir[axis] = sign;
    if (i % 8 >= 4) {  // one zero component only
      r.dir[other] = u(rng) - 0.5f;
    }
    r.org = target - r.dir * far;
    if (i % 16 >= 12) r.org = target;  // origin on the slab itself
    rays.push_back(r);
  }
  return rays;
}

TEST(WideTrace, AxisRaysThroughBoxEdgesAndZeroComponentsMatchBruteForce) {
  for (uint64_t seed : {31u, 32u}) {
    const Mesh mesh = testing::random_mesh(900, seed, true);
    const PrimitiveRefs refs = make_references(mesh);
    const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 2);
    RaySet set;
    set.kind = RayKind::random;
    set.rays = slab_rays(mesh, seed, 4000);
    const std::vector<Expected> expected = expected_hits(mesh, {set});
    size_t hits = 0;
    for (const Hit& h : expected[0].hits[0]) hits += h.hit() ? 1 : 0;
    EXPECT_GT(hits, set.rays.size() / 4);
    expect_all_variants_match(flat, mesh, expected, "slab rays");
  }
}

// From ten thousand scene sizes away an exit distance's rounding (a few ulps of a distance
// that large) outgrows the boxes' padding (a fixed fraction of the scene's size); the slab
// test's exit scaling has to cover it, or rays through box edges and corners miss the
// triangle that brute force hits (without it: 1 to 3 misses per kernel here). From 1e5
// scene sizes away a few such rays miss even with it, as they did before the scaling was
// folded into the far planes.
TEST(WideTrace, RaysFromFarAwayThroughBoxEdgesMatchBruteForce) {
  const Mesh mesh = testing::random_mesh(900, 33, true);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 2);
  RaySet set;
  set.kind = RayKind::random;
  set.rays = slab_rays(mesh, 33, 4000, 1e4f);
  const std::vector<Expected> expected = expected_hits(mesh, {set});
  size_t hits = 0;
  for (const Hit& h : expected[0].hits[0]) hits += h.hit() ? 1 : 0;
  EXPECT_GT(hits, set.rays.size() / 4);
  expect_all_variants_match(flat, mesh, expected, "rays from far away");
}

TEST(WideTrace, SegmentsHonourTminAndTmaxIncludingTheEnds) {
  const Mesh mesh = testing::random_mesh(500, 41, false);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 1);
  std::vector<Ray> rays = ray_sets_for(mesh, flat, 1000)[1].rays;  // random segments
  // Cut each segment to end exactly at (or start exactly at) its brute-force hit.
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit h = brute_force_closest_mt(mesh, rays[i]);
    if (!h.hit()) continue;
    if (i % 2) rays[i].tmax = h.t; else rays[i].tmin = h.t;
  }
  for (const Variant& v : all_variants()) {
    const WideTracer tracer = make_tracer(flat, mesh, v);
    std::string first;
    EXPECT_EQ(count_mismatches(tracer, mesh, rays, RayQuery::any, v.test, first), 0u) << v.name() << ": " << first;
  }
}

TEST(WideTrace, MollerTrumboreAgreesWithTheWatertightTestAwayFromEdges) {
  // The default test is not watertight; on random rays it finds the same hits as the
  // watertight brute force except, rarely, on a shared edge.
  const Mesh mesh = testing::random_mesh(1500, 42, false);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::sweep_sah, 1);
  const RaySet set = ray_sets_for(mesh, flat, 3000)[1];
  const WideTracer tracer(flat, mesh);
  size_t differ = 0;
  TraceCounters c;
  for (const Ray& r : set.rays) {
    const Hit a = tracer.closest(r, c), b = brute_force_closest(mesh, r);
    if (a.triangle_id != b.triangle_id) {
      ++differ;
    } else if (a.hit()) {
      EXPECT_NEAR(a.t, b.t, 1e-4f * std::max(1.0f, b.t));
    }
  }
  EXPECT_LE(differ, set.rays.size() / 1000);
}

TEST(WideTrace, OneLeafTreeAndRejectedTrees) {
  Mesh mesh = testing::random_mesh(3, 43, false);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = built(mesh, refs, BuilderKind::object_median, 8);
  ASSERT_EQ(flat.nodes.size(), 1u);
  const std::vector<RaySet> sets = ray_sets_for(mesh, flat, 500, {RayKind::random});  // a camera may see nothing
  expect_all_variants_match(flat, mesh, expected_hits(mesh, sets), "one leaf");
  Mesh fewer = mesh;
  fewer.indices.resize(3);
  EXPECT_THROW(WideBvh(flat, fewer), Error);
  const Mesh big = testing::random_mesh(100, 44, false);
  EXPECT_THROW(WideBvh(built(big, make_references(big), BuilderKind::object_median, 100), big), Error);
}

}  // namespace
}  // namespace bvhopt
