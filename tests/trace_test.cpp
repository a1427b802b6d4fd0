// Traversal against brute force: every builder, leaf sizes 1 and 4, every ray set, both
// child orders; watertightness on closed meshes; degenerate and grazing rays.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <utility>

#include "bvhopt/any_tracer.h"
#include "bvhopt/build.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/tracer.h"
#include "bvhopt/testing/brute_force.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "test_support.h"

namespace bvhopt {
namespace {

constexpr ChildOrder kOrders[] = {ChildOrder::distance, ChildOrder::split_axis};

FlatBvh flat_tree(const Mesh& mesh, BuilderKind kind, uint32_t leaf_size) {
  const PrimitiveRefs refs = make_references(mesh);
  BuildOptions options;
  options.kind = kind;
  options.leaf.max_leaf_size = leaf_size;
  return flatten_for_tracing(build_bvh(refs, options), refs);
}

// A closed icosphere: every edge shared by exactly two triangles, vertices shared by five
// or six, all welded (the same index), so a gap could only come from the triangle test.
Mesh icosphere(int subdivisions, float radius, Vec3 centre) {
  const float p = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3> v = {{-1, p, 0}, {1, p, 0}, {-1, -p, 0}, {1, -p, 0}, {0, -1, p}, {0, 1, p},
                         {0, -1, -p}, {0, 1, -p}, {p, 0, -1}, {p, 0, 1}, {-p, 0, -1}, {-p, 0, 1}};
  std::vector<std::array<uint32_t, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                            {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                            {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                            {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]) * 0.5f);
      return mid[key] = uint32_t(v.size() - 1);
    };
    std::vector<std::array<uint32_t, 3>> g;
    for (auto& t : f) {
      uint32_t a = midpoint(t[0], t[1]), b = midpoint(t[1], t[2]), c = midpoint(t[2], t[0]);
      g.push_back({t[0], a, c});
      g.push_back({t[1], b, a});
      g.push_back({t[2], c, b});
      g.push_back({a, b, c});
    }
    f = std::move(g);
  }
  Mesh m;
  m.name = "icosphere";
  for (const Vec3& x : v) m.add_vertex(centre + normalize(x) * radius);
  for (auto& t : f) m.add_triangle(t[0], t[1], t[2]);
  return m;
}

// The surface of an n x n x n cube of unit cells with integer vertex coordinates, two
// triangles per face square: axis-aligned rays through grid lines hit edges and vertices
// exactly, where float arithmetic is exact.
Mesh grid_cube(int n) {
  Mesh m;
  m.name = "grid_cube";
  auto quad = [&](Vec3 o, Vec3 du, Vec3 dv, bool diag_flip) {
    const uint32_t b = uint32_t(m.vertex_count());
    m.add_vertex(o);
    m.add_vertex(o + du);
    m.add_vertex(o + du + dv);
    m.add_vertex(o + dv);
    if (diag_flip) {
      m.add_triangle(b, b + 1, b + 3);
      m.add_triangle(b + 1, b + 2, b + 3);
    } else {
      m.add_triangle(b, b + 1, b + 2);
      m.add_triangle(b, b + 2, b + 3);
    }
  };
  const float N = float(n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const float a = float(i), b = float(j);
      const bool flip = (i + j) % 2 == 1;
      quad({a, b, 0}, {1, 0, 0}, {0, 1, 0}, flip);
      quad({a, b, N}, {1, 0, 0}, {0, 1, 0}, !flip);
      quad({a, 0, b}, {1, 0, 0}, {0, 0, 1}, flip);
      quad({a, N, b}, {1, 0, 0}, {0, 0, 1}, !flip);
      quad({0, a, b}, {0, 1, 0}, {0, 0, 1}, flip);
      quad({N, a, b}, {0, 1, 0}, {0, 0, 1}, !flip);
    }
  return m;
}

void expect_matches_brute_force(const Tracer& tracer, const Mesh& mesh, const std::vector<Ray>& rays,
                                RayQuery query, const std::string& what) {
  for (ChildOrder order : kOrders) {
    const BruteForceCheck c = check_against_brute_force(tracer, mesh, rays, query, rays.size(), 1, order);
    EXPECT_EQ(c.checked, rays.size()) << what;
    EXPECT_EQ(c.mismatches, 0u) << what << " order " << int(order) << ": " << c.first_mismatch;
    // Any-hit must agree with closest hit on occlusion for every ray.
    uint64_t disagree = 0;
    for (const Ray& r : rays) {
      TraceCounters counters;
      disagree += tracer.any(r, counters, order) != tracer.closest(r, counters, order).hit();
    }
    EXPECT_EQ(disagree, 0u) << what << " any-hit vs closest";
  }
}

// Rays along the axes, with zero direction components, and grazing the scene box.
std::vector<Ray> awkward_rays(const Mesh& mesh, uint64_t seed, size_t count) {
  Box box;
  for (size_t v = 0; v < mesh.vertex_count(); ++v) box.extend(mesh.vertex(v));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Ray> rays;
  for (size_t i = 0; i < count; ++i) {
    Ray r;
    const Vec3 p = box.min + box.extent() * Vec3(u(rng), u(rng), u(rng));
    const int axis = int(i % 3);
    const float sign = (i / 3) % 2 ? -1.0f : 1.0f;
    switch ((i / 6) % 4) {
      case 0:  // exactly along an axis, +0 and -0 in the other components
        r.dir = Vec3(0.0f);
        r.dir[axis] = sign;
        r.dir[(axis + 1) % 3] = sign < 0 ? -0.0f : 0.0f;
        r.org = p - r.dir * (2.0f * length(box.extent()));
        break;
      case 1: {  // one zero component, starting inside the box
        r.org = p;
        r.dir = Vec3(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f);
        r.dir[axis] = 0.0f;
        if (r.dir == Vec3(0.0f)) r.dir[(axis + 1) % 3] = 1.0f;
        break;
      }
      case 2: {  // aimed at a vertex of a random triangle, from a random point
        const Triangle t = mesh.triangle(rng() % mesh.triangle_count());
        r.org = p;
        r.dir = t.v0 - p;
        if (r.dir == Vec3(0.0f)) r.dir = Vec3(1.0f, 0.0f, 0.0f);
        break;
      }
      default: {  // a segment ending on an edge midpoint, tmax 1, with tmin > 0
        const Triangle t = mesh.triangle(rng() % mesh.triangle_count());
        r.org = p;
        r.dir = (t.v1 + t.v2) * 0.5f - p;
        if (r.dir == Vec3(0.0f)) r.dir = Vec3(0.0f, 0.0f, 1.0f);
        r.tmin = 0.01f;
        r.tmax = 1.0f;
        break;
      }
    }
    rays.push_back(r);
  }
  return rays;
}

TEST(Trace, EveryBuilderLeafSizeAndRaySetMatchesBruteForce) {
  const Mesh mesh = testing::random_mesh(1500, 7, /*with_degenerate=*/true);
  for (BuilderKind kind : all_builders()) {
    for (uint32_t leaf : {1u, 4u}) {
      const Tracer tracer(flat_tree(mesh, kind, leaf), mesh);
      const std::string what = std::string(builder_name(kind)) + " leaf " + std::to_string(leaf);
      for (RayKind rk : all_ray_kinds()) {
        RaySetConfig cfg;
        cfg.kind = rk;
        cfg.seed = 11;
        cfg.count = 2000;
        const RaySet set = make_ray_set(mesh, tracer, cfg);
        ASSERT_GE(set.rays.size(), 1000u) << what << " " << ray_kind_name(rk);
        expect_matches_brute_force(tracer, mesh, set.rays, set.query, what + " " + std::string(ray_kind_name(rk)));
      }
      expect_matches_brute_force(tracer, mesh, awkward_rays(mesh, 3, 2400), RayQuery::closest, what + " awkward");
    }
  }
}

TEST(Trace, FinalizedTreesMatchBruteForce) {
  // The real pipeline: finalize's depth-first layout and recorded split axes, with and
  // without its child ordering.
  const Mesh mesh = testing::random_mesh(1500, 8, true);
  const PrimitiveRefs refs = make_references(mesh);
  for (BuilderKind kind : all_builders()) {
    for (uint32_t leaf : {1u, 4u}) {
      BuildOptions options;
      options.kind = kind;
      options.leaf.max_leaf_size = leaf;
      const Bvh bvh = build_bvh(refs, options);
      for (bool ordered : {true, false}) {
        FinalizeOptions fo;
        fo.order_children_by_split_axis = ordered;
        const Tracer tracer(finalize(bvh, refs, fo), mesh);
        RaySetConfig cfg;
        cfg.kind = RayKind::random;
        cfg.count = 1500;
        const RaySet set = make_ray_set(mesh, tracer, cfg);
        expect_matches_brute_force(tracer, mesh, set.rays, set.query,
                                   "finalize " + std::string(builder_name(kind)) + " leaf " + std::to_string(leaf));
        cfg.kind = RayKind::shadow;
        const RaySet shadow = make_ray_set(mesh, tracer, cfg);
        expect_matches_brute_force(tracer, mesh, shadow.rays, shadow.query, "finalize shadow");
      }
    }
  }
}

TEST(Trace, RandomRaysHitSomethingAndMissSomething) {
  // Guards the brute-force comparison above against a vacuous pass (everything missing).
  const Mesh mesh = testing::random_mesh(1500, 7, true);
  const Tracer tracer(flat_tree(mesh, BuilderKind::sweep_sah, 1), mesh);
  RaySetConfig cfg;
  cfg.kind = RayKind::random;
  cfg.count = 2000;
  const RaySet set = make_ray_set(mesh, tracer, cfg);
  const RayMeasurement m = measure_rays(tracer, set.rays, set.query, {.repeats = 1});
  EXPECT_GT(m.hit_rate, 0.05);
  EXPECT_LT(m.hit_rate, 0.999);
  EXPECT_GT(m.steps.mean, 1.0);
  EXPECT_GT(m.triangle_tests.mean, 0.5);
}

// trace_rays' calls of N rays (what `bvhopt trace --rays-per-call N` times) give the hits of
// one ray a call: every ray traced once, none twice, in every layout, closest and any hit,
// for call sizes that do and do not divide the blocks.
TEST(Trace, RaysPerCallGiveTheHitsOfOneRayACall) {
  const Mesh mesh = testing::random_mesh(1500, 11, true);
  const FlatBvh flat = flat_tree(mesh, BuilderKind::sweep_sah, 4);
  const Tracer binary(flat, mesh);
  for (TraceLayout layout : {TraceLayout::bvh2, TraceLayout::bvh4, TraceLayout::bvh8}) {
    const std::unique_ptr<WideTracer> wide = make_wide_tracer(flat, mesh, layout);
    const AnyTracer traced = wide ? AnyTracer(*wide) : AnyTracer(binary);
    for (RayKind kind : {RayKind::random, RayKind::shadow}) {
      RaySetConfig cfg;
      cfg.kind = kind;
      cfg.count = 3001;
      const RaySet set = make_ray_set(mesh, binary, cfg);
      std::vector<Hit> want;
      std::vector<TraceCounters> counters;
      trace_rays(traced, set.rays, set.query, want, &counters);  // one call a ray
      size_t hits = 0;
      for (const Hit& h : want) hits += h.hit();
      ASSERT_GT(hits, 0u);
      ASSERT_LT(hits, want.size());
      for (size_t per_call : {size_t(0), size_t(1), size_t(7), size_t(16), size_t(17), size_t(1000)}) {
        std::vector<Hit> got(set.rays.size(), Hit{1.0f, 0.5f, 0.5f, 123456});  // stale: must be overwritten
        trace_rays(traced, set.rays, set.query, got, nullptr, std::max<size_t>(256, per_call), per_call);
        for (size_t i = 0; i < want.size(); ++i) {
          ASSERT_EQ(got[i].hit(), want[i].hit()) << trace_layout_name(layout) << " " << per_call << " ray " << i;
          if (set.query == RayQuery::closest) {
            ASSERT_EQ(got[i].triangle_id, want[i].triangle_id) << trace_layout_name(layout) << " " << per_call;
            ASSERT_EQ(got[i].t, want[i].t);
          }
        }
      }
    }
  }
}

TEST(Trace, ClosedSphereIsWatertightAtEdgesAndVertices) {
  const Mesh mesh = icosphere(4, 3.7f, Vec3(0.3f, -1.1f, 2.9f));
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (uint32_t leaf : {1u, 4u}) {
    const Tracer tracer(flat_tree(mesh, BuilderKind::sweep_sah, leaf), mesh);
    uint64_t misses = 0, rays = 0, inside_misses = 0;
    std::vector<Ray> sample;
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
      const Triangle tri = mesh.triangle(t);
      // Targets exactly on the surface's edges and vertices, approached from outside and
      // from the centre (inside).
      for (const Vec3& target : {tri.v0, (tri.v0 + tri.v1) * 0.5f, (tri.v1 + tri.v2) * 0.5f}) {
        for (int from_inside = 0; from_inside < 2; ++from_inside) {
          Ray r;
          // From outside the ray comes from roughly above the target, so it enters the
          // sphere there rather than grazing past it; from inside every ray must hit.
          const Vec3 centre(0.3f, -1.1f, 2.9f);
          r.org = from_inside ? centre + Vec3(u(rng), u(rng), u(rng))
                              : centre + normalize(target - centre + Vec3(u(rng), u(rng), u(rng)) * 0.5f) * 20.0f;
          r.dir = target - r.org;
          TraceCounters c;
          inside_misses += from_inside && !brute_force_any(mesh, r);
          for (ChildOrder order : kOrders) {
            misses += tracer.closest(r, c, order).hit() ? 0 : 1;
            misses += tracer.any(r, c, order) ? 0 : 1;
            rays += 2;
          }
          if (sample.size() < 3000 && (t % 3 == 0)) sample.push_back(r);
        }
      }
    }
    EXPECT_EQ(misses, 0u) << "of " << rays << " rays through edges and vertices of a closed mesh";
    EXPECT_EQ(inside_misses, 0u) << "the triangle test itself leaks";
    expect_matches_brute_force(tracer, mesh, sample, RayQuery::closest, "icosphere");
  }
}

TEST(Trace, AxisRaysThroughGridEdgesAndVerticesHitExactly) {
  const int n = 6;
  const Mesh mesh = grid_cube(n);
  for (uint32_t leaf : {1u, 4u}) {
    const Tracer tracer(flat_tree(mesh, BuilderKind::binned_sah, leaf), mesh);
    for (int axis = 0; axis < 3; ++axis)
      for (float sign : {-1.0f, 1.0f})
        // Half steps put the ray through cell centres, edge lines and vertices.
        for (int i = 0; i <= 2 * n; ++i)
          for (int j = 0; j <= 2 * n; ++j) {
            Ray r;
            r.org[axis] = sign > 0 ? -3.0f : float(n) + 3.0f;
            r.org[(axis + 1) % 3] = 0.5f * float(i);
            r.org[(axis + 2) % 3] = 0.5f * float(j);
            r.dir = Vec3(0.0f);
            r.dir[axis] = sign;
            for (ChildOrder order : kOrders) {
              TraceCounters c;
              const Hit h = tracer.closest(r, c, order);
              ASSERT_TRUE(h.hit()) << "axis " << axis << " sign " << sign << " at " << i << "," << j;
              EXPECT_EQ(h.t, 3.0f);
            }
          }
  }
}

TEST(Trace, ZeroAreaTrianglesAreNeverHit) {
  Mesh mesh;
  mesh.name = "degenerate";
  for (int i = 0; i < 50; ++i) {
    const float x = float(i);
    const uint32_t b = uint32_t(mesh.vertex_count());
    mesh.add_vertex({x, 0, 0});
    mesh.add_vertex({x, 1, 0});
    mesh.add_vertex(i % 2 ? Vec3(x, 1, 0) : Vec3(x, 2, 0));  // coincident or collinear
    mesh.add_triangle(b, b + 1, b + 2);
  }
  const Tracer tracer(flat_tree(mesh, BuilderKind::sweep_sah, 1), mesh);
  for (int i = 0; i < 50; ++i) {
    TraceCounters c;
    Ray r;
    r.org = Vec3(float(i), 0.5f, -1.0f);
    r.dir = Vec3(0, 0, 1);  // straight at the degenerate triangle's line
    EXPECT_FALSE(tracer.closest(r, c).hit());
    r.org = Vec3(float(i) - 1.0f, 0.5f, 0.0f);
    r.dir = Vec3(1, 0, 0);  // in the triangle's line, along it
    EXPECT_FALSE(tracer.any(r, c));
  }
}

TEST(Trace, GrazingRaysInATrianglesPlaneAgreeWithBruteForce) {
  Mesh mesh = testing::random_mesh(300, 9, false);
  std::vector<Ray> rays;
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    const Triangle tri = mesh.triangle(t);
    for (int k = 0; k < 4; ++k) {
      Ray r;
      const Vec3 e = k % 2 ? tri.v1 - tri.v0 : tri.v2 - tri.v1;
      r.org = tri.v0 - e * 2.0f;  // in the plane of the triangle, sliding along an edge
      r.dir = e + (tri.v2 - tri.v0) * (0.001f * u(rng));
      rays.push_back(r);
    }
  }
  const Tracer tracer(flat_tree(mesh, BuilderKind::object_median, 4), mesh);
  expect_matches_brute_force(tracer, mesh, rays, RayQuery::closest, "grazing");
}

TEST(Trace, DeepTreeBeyondTheFixedStack) {
  // A caterpillar of 400 leaves: depth 399, deeper than the fixed stack, so the heap stack
  // must take over.
  const Mesh mesh = testing::random_mesh(400, 4, false);
  const PrimitiveRefs refs = make_references(mesh);
  Bvh bvh;
  const uint32_t n = 400;
  bvh.ref_indices.resize(n);
  for (uint32_t i = 0; i < n; ++i) bvh.ref_indices[i] = i;
  // Nodes: leaves 0..n-1, inner n..2n-2; inner n+k has leaf k and inner n+k+1 (last: leaf n-1).
  bvh.nodes.resize(2 * n - 1);
  for (uint32_t i = 0; i < n; ++i) {
    bvh.nodes[i].make_leaf(i, 1);
    bvh.nodes[i].set_box(refs.boxes[i]);
  }
  for (uint32_t k = n - 1; k-- > 0;) {
    const uint32_t self = n + k;
    const uint32_t right = k + 1 == n - 1 ? n - 1 : self + 1;
    bvh.nodes[self].make_inner(k, right);
    bvh.nodes[self].set_box(merge(bvh.nodes[k].box, bvh.nodes[right].box));
    bvh.nodes[k].parent = self;
    bvh.nodes[right].parent = self;
  }
  bvh.root = n;
  const Tracer tracer(flatten_for_tracing(bvh, refs), mesh);
  RaySetConfig cfg;
  cfg.kind = RayKind::random;
  cfg.count = 1000;
  expect_matches_brute_force(tracer, mesh, make_ray_set(mesh, tracer, cfg).rays, RayQuery::closest, "deep");
}

TEST(Trace, RejectsTreesThatDoNotFitTheMesh) {
  const Mesh mesh = testing::random_mesh(20, 1, false);
  FlatBvh flat = flat_tree(mesh, BuilderKind::sweep_sah, 1);
  FlatBvh bad_id = flat;
  bad_id.triangle_ids[3] = 20;
  EXPECT_THROW({ Tracer t(bad_id, mesh); }, Error);
  FlatBvh bad_child = flat;
  bad_child.nodes[0].index = 0;
  EXPECT_THROW({ Tracer t(bad_child, mesh); }, Error);
  EXPECT_THROW({ Tracer t(FlatBvh{}, mesh); }, Error);
}

TEST(Trace, LargeLeavesAndOneLeafTreesMatchBruteForce) {
  // Large leaves, and trees that are one leaf (a node with an empty slot).
  const Mesh mesh = testing::random_mesh(300, 3, /*with_degenerate=*/true);
  for (uint32_t leaf : {16u, 40u, 300u}) {
    const Tracer tracer(flat_tree(mesh, BuilderKind::sweep_sah, leaf), mesh);
    const std::string what = "sweep leaf " + std::to_string(leaf);
    for (RayKind rk : {RayKind::primary, RayKind::random, RayKind::shadow}) {
      RaySetConfig cfg;
      cfg.kind = rk;
      cfg.seed = 3;
      cfg.count = 1000;
      const RaySet set = make_ray_set(mesh, tracer, cfg);
      expect_matches_brute_force(tracer, mesh, set.rays, set.query, what + " " + std::string(ray_kind_name(rk)));
    }
  }
  // Trees that are one leaf, of 9 entries and of 300.
  for (uint32_t n : {9u, 300u}) {
    const Mesh small = testing::random_mesh(n, 4, false);
    FlatBvh flat;
    FlatNode leaf{};
    leaf.box = describe(small).bounds;
    leaf.index = 0;
    leaf.count = static_cast<uint16_t>(n);
    flat.nodes.push_back(leaf);
    for (uint32_t i = 0; i < n; ++i) flat.triangle_ids.push_back(i);
    const Tracer one_leaf(flat, small);
    EXPECT_EQ(one_leaf.node_count(), 1u);
    RaySetConfig cfg;
    cfg.kind = RayKind::random;
    cfg.count = 2000;
    const RaySet set = make_ray_set(small, one_leaf, cfg);
    expect_matches_brute_force(one_leaf, small, set.rays, set.query, "one leaf of " + std::to_string(n));
  }
}

TEST(Trace, SharedSceneSampleMatchesBruteForce) {
  // staircase.obj: real geometry with 2,429 zero-area triangles.
  const auto path = testing::scenes_dir() / "staircase.obj";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not found";
  const Mesh mesh = load_mesh_file(path);
  const Tracer tracer(flat_tree(mesh, BuilderKind::sweep_sah, 4), mesh);
  for (RayKind rk : {RayKind::primary, RayKind::random, RayKind::ao, RayKind::shadow}) {
    RaySetConfig cfg;
    cfg.kind = rk;
    cfg.count = 20000;
    const RaySet set = make_ray_set(mesh, tracer, cfg);
    for (ChildOrder order : kOrders) {
      const BruteForceCheck c = check_against_brute_force(tracer, mesh, set.rays, set.query, 300, 5, order);
      EXPECT_EQ(c.mismatches, 0u) << ray_kind_name(rk) << ": " << c.first_mismatch;
    }
  }
}

}  // namespace
}  // namespace bvhopt
