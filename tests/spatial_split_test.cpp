// The spatial-split builder (SBVH) and the triangle clipping it rests on: clipping against
// a double-precision oracle, degenerate triangles, coverage of every triangle by its
// references, the budget, determinism across thread counts, brute-force ray hits on the
// binary and wide layouts, and the optimizers and leaf collapse on its trees.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <random>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/collapse_leaves.h"
#include "bvhopt/cost.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/spatial_split_builder.h"
#include "bvhopt/sweep_sah_builder.h"
#include "bvhopt/testing/brute_force.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "bvhopt/tracer.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/triangle_clipping.h"
#include "bvhopt/triangle_cost.h"
#include "bvhopt/validate.h"
#include "bvhopt/wide_tracer.h"
#include "test_support.h"

namespace bvhopt {
namespace {

using D3 = std::array<double, 3>;

// ---- The oracle: the bounds of triangle ∩ box from the points where its extremes can lie
// (corners inside the box, edges crossing box faces, box edges crossing the triangle), in
// double, with no clipping at all. Returns false when nothing lies inside.
bool oracle_bounds(const Triangle& tri, const Box& box, D3& lo, D3& hi) {
  const D3 v[3] = {{tri.v0.x, tri.v0.y, tri.v0.z}, {tri.v1.x, tri.v1.y, tri.v1.z}, {tri.v2.x, tri.v2.y, tri.v2.z}};
  const D3 bmin = {box.min.x, box.min.y, box.min.z}, bmax = {box.max.x, box.max.y, box.max.z};
  double scale = 1.0;
  for (int k = 0; k < 3; ++k) scale = std::max({scale, std::abs(bmin[k]), std::abs(bmax[k])});
  const double eps = 1e-12 * scale;
  auto inside = [&](const D3& p) {
    for (int k = 0; k < 3; ++k)
      if (p[k] < bmin[k] - eps || p[k] > bmax[k] + eps) return false;
    return true;
  };
  bool any = false;
  auto add = [&](const D3& p) {
    if (!inside(p)) return;
    for (int k = 0; k < 3; ++k) {
      // A point just outside by rounding is pulled onto the box.
      const double c = std::clamp(p[k], bmin[k], bmax[k]);
      lo[k] = any ? std::min(lo[k], c) : c;
      hi[k] = any ? std::max(hi[k], c) : c;
    }
    any = true;
  };
  for (const D3& p : v) add(p);
  for (int e = 0; e < 3; ++e) {
    const D3& a = v[e];
    const D3& b = v[(e + 1) % 3];
    for (int k = 0; k < 3; ++k)
      for (double plane : {bmin[k], bmax[k]}) {
        if (a[k] == b[k]) continue;
        const double t = (plane - a[k]) / (b[k] - a[k]);
        if (t < 0.0 || t > 1.0) continue;
        D3 p;
        for (int j = 0; j < 3; ++j) p[j] = a[j] + t * (b[j] - a[j]);
        p[k] = plane;
        add(p);
      }
  }
  // Box edges against the triangle's plane, inside the triangle (barycentric in double).
  const D3 e1 = {v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]};
  const D3 e2 = {v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]};
  const D3 n = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  const double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  if (nn > 0.0) {
    for (int k = 0; k < 3; ++k) {
      if (n[k] == 0.0) continue;
      const int u = (k + 1) % 3, w = (k + 2) % 3;
      for (double pu : {bmin[u], bmax[u]})
        for (double pw : {bmin[w], bmax[w]}) {
          D3 p;
          p[u] = pu, p[w] = pw;
          p[k] = v[0][k] - (n[u] * (pu - v[0][u]) + n[w] * (pw - v[0][w])) / n[k];
          const D3 d = {p[0] - v[0][0], p[1] - v[0][1], p[2] - v[0][2]};
          // Barycentric coordinates from the cross products with the normal.
          auto cross_dot = [&](const D3& a, const D3& b) {
            const D3 c = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
            return (c[0] * n[0] + c[1] * n[1] + c[2] * n[2]) / nn;
          };
          const double beta = cross_dot(d, e2), gamma = cross_dot(e1, d);
          if (beta >= -1e-12 && gamma >= -1e-12 && beta + gamma <= 1.0 + 1e-12) add(p);
        }
    }
  }
  return any;
}

Vec3 random_point(std::mt19937_64& rng, float extent) {
  std::uniform_real_distribution<float> u(-extent, extent);
  return Vec3(u(rng), u(rng), u(rng));
}

// Relative tightness allowed: the box is rounded outward to float once.
constexpr double kSlack = 1e-5;

void expect_matches_oracle(const Triangle& tri, const Box& box, const Box& got, const std::string& what) {
  D3 lo, hi;
  const bool any = oracle_bounds(tri, box, lo, hi);
  double scale = 1.0;
  for (int k = 0; k < 3; ++k) scale = std::max({scale, std::abs(double(box.min[k])), std::abs(double(box.max[k]))});
  if (!any) {
    // Nothing inside by the oracle: the clip may keep a sliver only where the triangle
    // touches the box within rounding.
    if (!got.is_empty()) {
      Box grown(box.min - Vec3(float(kSlack * scale)), box.max + Vec3(float(kSlack * scale)));
      D3 l2, h2;
      EXPECT_TRUE(oracle_bounds(tri, grown, l2, h2)) << what << ": clipped box not empty, oracle finds nothing";
    }
    return;
  }
  ASSERT_FALSE(got.is_empty()) << what << ": clipped box empty, oracle finds a part inside";
  for (int k = 0; k < 3; ++k) {
    ASSERT_TRUE(std::isfinite(got.min[k]) && std::isfinite(got.max[k])) << what;
    // Contains the exact part (the oracle's double values, up to its own rounding)...
    EXPECT_LE(double(got.min[k]), lo[k] + 1e-12 * scale) << what << " axis " << k;
    EXPECT_GE(double(got.max[k]), hi[k] - 1e-12 * scale) << what << " axis " << k;
    // ...and no more than rounding beyond it.
    EXPECT_GE(double(got.min[k]), lo[k] - kSlack * scale) << what << " axis " << k;
    EXPECT_LE(double(got.max[k]), hi[k] + kSlack * scale) << what << " axis " << k;
  }
}

TEST(TriangleClipping, MatchesDoublePrecisionOracleOnRandomTriangles) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  size_t nonempty = 0, partial = 0;
  for (int i = 0; i < 20000; ++i) {
    const Triangle tri{random_point(rng, 2.0f), random_point(rng, 2.0f), random_point(rng, 2.0f)};
    Vec3 a = random_point(rng, 1.5f), b = random_point(rng, 1.5f);
    const Box box(min(a, b), max(a, b));
    const Box got = clip_triangle_to_box(tri, box);
    expect_matches_oracle(tri, box, got, "box " + std::to_string(i));
    nonempty += !got.is_empty();
    partial += !got.is_empty() && !(got == intersect(tri.bounds(), box));
    // A slab: the oracle sees it as a box reaching past the triangle on the other two axes.
    const int axis = i % 3;
    const float lo = std::min(a[axis], b[axis]), hi = std::max(a[axis], b[axis]);
    Box slab(tri.bounds().min - Vec3(1.0f), tri.bounds().max + Vec3(1.0f));
    slab.min[axis] = lo;
    slab.max[axis] = hi;
    expect_matches_oracle(tri, slab, clip_triangle_to_slab(tri, axis, lo, hi), "slab " + std::to_string(i));
    if (HasFailure()) break;
  }
  // The test says something: most clips are neither empty nor the plain box intersection.
  EXPECT_GT(nonempty, 5000u);
  EXPECT_GT(partial, 2000u);
}

TEST(TriangleClipping, SplitPiecesAreBelowAndAboveThePlaneAndCoverTheTriangle) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 2000; ++i) {
    const Triangle tri{random_point(rng, 1.0f), random_point(rng, 1.0f), random_point(rng, 1.0f)};
    const int axis = i % 3;
    const float pos = std::uniform_real_distribution<float>(-0.5f, 0.5f)(rng);
    ClipPolygon below, above;
    split_polygon(ClipPolygon(tri), axis, pos, below, above);
    const Box lb = below.bounds(), ab = above.bounds();
    if (!lb.is_empty()) { EXPECT_LE(lb.max[axis], pos); }
    if (!ab.is_empty()) { EXPECT_GE(ab.min[axis], pos); }
    Box u = lb;
    u.extend(ab);
    EXPECT_TRUE(u.contains(tri.bounds())) << i;  // the two pieces together are the whole triangle
    EXPECT_TRUE(tri.bounds().contains(lb) && tri.bounds().contains(ab)) << i;
  }
}

// Slicing by several planes at once: each piece as the double oracle bounds the triangle
// within its slab, the pieces together the whole triangle, and one plane exactly as
// split_polygon cuts it. Planes repeat and pass through corners, where a corner belongs to
// every piece whose slab holds it.
TEST(TriangleClipping, SlicesMatchTheOracleSlabBySlab) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(-1.5f, 1.5f);
  size_t cut = 0;
  for (int i = 0; i < 5000; ++i) {
    const Triangle tri{random_point(rng, 1.0f), random_point(rng, 1.0f), random_point(rng, 1.0f)};
    const int axis = i % 3;
    const int count = 1 + i % 9;
    std::vector<float> planes(count);
    for (float& p : planes) p = u(rng);
    if (i % 4 == 0) planes[0] = tri.v1[axis];         // through a corner
    if (i % 5 == 0 && count > 1) planes[1] = planes[0];  // a repeated plane
    std::sort(planes.begin(), planes.end());
    std::vector<Box> pieces(count + 1);
    slice_triangle(tri, axis, planes.data(), count, pieces.data());
    const Box around(tri.bounds().min - Vec3(1.0f), tri.bounds().max + Vec3(1.0f));
    Box all;
    for (int k = 0; k <= count; ++k) {
      Box slab = around;
      if (k > 0) slab.min[axis] = planes[k - 1];
      if (k < count) slab.max[axis] = planes[k];
      if (slab.is_empty()) continue;  // a plane outside the box around the triangle
      expect_matches_oracle(tri, slab, pieces[k], "slice " + std::to_string(i) + " piece " + std::to_string(k));
      all.extend(pieces[k]);
      cut += k > 0 && k < count && !pieces[k].is_empty();
    }
    EXPECT_TRUE(all.contains(tri.bounds())) << i;
    if (count == 1) {
      ClipPolygon below, above;
      split_polygon(ClipPolygon(tri), axis, planes[0], below, above);
      EXPECT_EQ(pieces[0], below.bounds()) << i;
      EXPECT_EQ(pieces[1], above.bounds()) << i;
    }
    if (HasFailure()) break;
  }
  EXPECT_GT(cut, 2000u);  // most slices have pieces between two planes
}

// Zero area (coincident and collinear corners), triangles in an axis plane, needles: no
// NaN, the pieces inside the triangle's box, and the oracle's bounds where it has them.
TEST(TriangleClipping, DegenerateTrianglesClipWithoutNaN) {
  const Vec3 p(0.3f, -0.2f, 0.7f), q(1.3f, 0.8f, -0.4f);
  const std::vector<Triangle> cases = {
      {p, p, p},                                                   // a point
      {p, p, q},                                                   // two corners coincide
      {p, q, p * 0.5f + q * 0.5f},                                 // collinear
      {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)},               // in the plane z = 0
      {Vec3(0.5f, 0, 0), Vec3(0.5f, 1, 0), Vec3(0.5f, 0, 1)},      // in the plane x = 0.5
      {Vec3(0, 0, 0), Vec3(1, 1, 1), Vec3(1, 1, 1.0000001f)},      // needle along a diagonal
      {Vec3(0, 0, 0), Vec3(1e-7f, 0, 0), Vec3(0, 1e-7f, 1)},       // needle along z
      {Vec3(-1, 0.5f, 0.5f), Vec3(2, 0.5f, 0.5f), Vec3(2, 0.5f, 0.5f)},  // segment along an axis
  };
  const std::vector<Box> boxes = {Box(Vec3(0, 0, 0), Vec3(1, 1, 1)), Box(Vec3(0.5f, 0, 0), Vec3(0.5f, 1, 1)),
                                  Box(Vec3(0.25f, 0.25f, 0.25f), Vec3(0.75f, 0.75f, 0.75f)),
                                  Box(Vec3(-2), Vec3(0.5f))};
  for (size_t c = 0; c < cases.size(); ++c)
    for (size_t b = 0; b < boxes.size(); ++b) {
      const Box got = clip_triangle_to_box(cases[c], boxes[b]);
      const std::string what = "case " + std::to_string(c) + " box " + std::to_string(b);
      if (!got.is_empty()) {
        EXPECT_TRUE(is_finite(got.min) && is_finite(got.max)) << what;
        EXPECT_TRUE(intersect(cases[c].bounds(), boxes[b]).contains(got)) << what;
      }
      expect_matches_oracle(cases[c], boxes[b], got, what);
      for (int axis = 0; axis < 3; ++axis) {
        const Box s = clip_triangle_to_slab(cases[c], axis, boxes[b].min[axis], boxes[b].max[axis]);
        if (!s.is_empty()) { EXPECT_TRUE(is_finite(s.min) && is_finite(s.max)) << what << " slab " << axis; }
      }
    }
}

// ---- The builder.

// Long thin triangles crossing each other at many angles through the space of a random soup
// (with degenerate triangles) as many: overlap that spatial splits are made for.
Mesh crossing_mesh(uint32_t sticks, uint64_t seed) {
  Mesh mesh = testing::random_mesh(sticks, seed, /*with_degenerate=*/true);
  Box space;
  for (size_t v = 0; v < mesh.vertex_count(); ++v) space.extend(mesh.vertex(v));
  const Vec3 size = space.extent();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (uint32_t i = 0; i < sticks; ++i) {
    const uint32_t base = static_cast<uint32_t>(mesh.vertex_count());
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const Vec3 side = Vec3(u(rng), u(rng), 1.0f) * size * 0.001f;
    mesh.add_vertex(space.min + a * size);
    mesh.add_vertex(space.min + b * size);
    mesh.add_vertex(space.min + a * size + side);
    mesh.add_triangle(base, base + 1, base + 2);
  }
  return mesh;
}

SpatialSplitResult build_sbvh(const Mesh& mesh, double budget = 1.3, uint32_t leaf = 1,
                              const PrimitiveRefs* refs = nullptr, uint32_t exact_sweep_below = 0) {
  SpatialSplitConfig config;
  config.exact_sweep_below = exact_sweep_below;
  config.budget = budget;
  config.leaf.max_leaf_size = leaf;
  config.parallel_threshold = 64;  // many tasks even on a small scene
  config.parallel_binning_threshold = 1024;
  config.spatial_from = 0;  // spatial splits down to the smallest nodes, where the tests' scenes have most
  return build_spatial_split(mesh, refs ? *refs : make_references(mesh), config);
}

std::string tree_signature_of(const SpatialSplitResult& r) { return testing::tree_signature(r.bvh, r.refs); }

// Every point of every triangle (its corners, edge points and random interior points) lies
// in a box of one of its references; each reference box lies in the triangle's box.
void expect_covered(const Mesh& mesh, const PrimitiveRefs& refs) {
  std::vector<std::vector<uint32_t>> of(mesh.triangle_count());
  for (size_t r = 0; r < refs.size(); ++r) of[refs.triangle_ids[r]].push_back(static_cast<uint32_t>(r));
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  size_t uncovered = 0;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    ASSERT_FALSE(of[t].empty()) << "triangle " << t << " has no reference";
    const Triangle tri = mesh.triangle(t);
    for (uint32_t r : of[t]) EXPECT_TRUE(tri.bounds().contains(refs.boxes[r])) << "reference " << r;
    std::vector<Vec3> points = {tri.v0, tri.v1, tri.v2, (tri.v0 + tri.v1) * 0.5f, (tri.v1 + tri.v2) * 0.5f,
                                (tri.v2 + tri.v0) * 0.5f};
    for (int k = 0; k < 24; ++k) {
      float a = u(rng), b = u(rng);
      if (a + b > 1.0f) a = 1.0f - a, b = 1.0f - b;
      points.push_back(tri.v0 + (tri.v1 - tri.v0) * a + (tri.v2 - tri.v0) * b);
    }
    for (const Vec3& p : points) {
      // A point computed in float may sit an ulp off the exact triangle: allow for that.
      const float e = 1e-6f * std::max(1.0f, std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}));
      bool in = false;
      for (uint32_t r : of[t]) {
        const Box& b = refs.boxes[r];
        in |= Box(b.min - Vec3(e), b.max + Vec3(e)).contains(p);
      }
      uncovered += !in;
    }
  }
  EXPECT_EQ(uncovered, 0u);
}

TEST(SpatialSplit, ValidTreeCoveringEveryTriangle) {
  const Mesh mesh = crossing_mesh(1500, 5);
  for (uint32_t leaf : {1u, 4u}) {
    const SpatialSplitResult r = build_sbvh(mesh, 1.3, leaf);
    EXPECT_GT(r.stats.spatial_splits, 10u) << "no spatial split: the test says nothing";
    EXPECT_GT(r.refs.size(), mesh.triangle_count());
    const ValidationReport v = validate(r.bvh, r.refs);
    EXPECT_TRUE(v.ok()) << v.summary();
    expect_covered(mesh, r.refs);
    // The result's references are the leaves' slots in depth-first order.
    for (size_t i = 0; i < r.bvh.ref_indices.size(); ++i) ASSERT_EQ(r.bvh.ref_indices[i], i);
    // No leaf holds a triangle twice.
    EXPECT_TRUE(validate_deduplicated(r.bvh, r.refs).ok());
  }
}

// The optional exact sweep of small nodes' object splits: a valid, covering tree, the same
// on 1 and 2 threads, and (alone, budget 1) the sweep builder's cost where every node sweeps.
TEST(SpatialSplit, ExactSweepPathIsValidAndDeterministic) {
  const Mesh mesh = crossing_mesh(1500, 41);
  SpatialSplitResult one, two;
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
    one = build_sbvh(mesh, 1.3, 1, nullptr, 64);
  }
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 2);
    two = build_sbvh(mesh, 1.3, 1, nullptr, 64);
  }
  EXPECT_TRUE(validate(one.bvh, one.refs).ok());
  expect_covered(mesh, one.refs);
  EXPECT_EQ(tree_signature_of(one), tree_signature_of(two));
  const PrimitiveRefs refs = make_references(mesh);
  const SpatialSplitResult all_sweep = build_sbvh(mesh, 1.0, 1, nullptr, 1 << 16);
  EXPECT_NEAR(sah_cost(all_sweep.bvh), sah_cost(build_sweep_sah(refs)), 1e-9 * sah_cost(all_sweep.bvh));
}

// Nodes below spatial_from take object splits only: none at all when no node is that large.
TEST(SpatialSplit, SpatialSplitsOnlyFromTheGivenNodeSize) {
  const Mesh mesh = crossing_mesh(3000, 17);
  SpatialSplitConfig config;
  config.spatial_from = 0;
  const SpatialSplitResult everywhere = build_spatial_split(mesh, make_references(mesh), config);
  config.spatial_from = static_cast<uint32_t>(mesh.triangle_count()) + 1;
  const SpatialSplitResult nowhere = build_spatial_split(mesh, make_references(mesh), config);
  EXPECT_GT(everywhere.stats.spatial_splits, 0u);
  EXPECT_EQ(nowhere.stats.spatial_splits, 0u);
  EXPECT_EQ(nowhere.refs.size(), mesh.triangle_count());
}

// The number of nodes over more than `above` distinct triangles whose two children share a
// triangle. A node's distinct triangles are at most the references it held when it was
// split (descendants' splits add references, not triangles), so with spatial splits only in
// nodes of at most `above` references, such a node and all above it took object splits.
size_t nodes_whose_children_share_a_triangle(const SpatialSplitResult& r, uint32_t above) {
  std::vector<std::vector<uint32_t>> tris(r.bvh.nodes.size());
  size_t shared = 0;
  for (uint32_t n : r.bvh.post_order()) {
    const BvhNode& node = r.bvh.nodes[n];
    std::vector<uint32_t>& t = tris[n];
    if (node.is_leaf()) {
      for (uint32_t k = 0; k < node.ref_count(); ++k)
        t.push_back(r.refs.triangle_ids[r.bvh.ref_indices[node.first_ref() + k]]);
      std::sort(t.begin(), t.end());
      t.erase(std::unique(t.begin(), t.end()), t.end());
      continue;
    }
    const std::vector<uint32_t>& a = tris[node.child(0)];
    const std::vector<uint32_t>& b = tris[node.child(1)];
    std::vector<uint32_t> common;
    std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(common));
    std::set_union(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(t));
    if (t.size() > above && !common.empty()) ++shared;
  }
  return shared;
}

TEST(SpatialSplit, SpatialSplitsOnlyUpToTheGivenNodeSize) {
  const Mesh mesh = crossing_mesh(3000, 17);
  SpatialSplitConfig config;
  config.spatial_from = 0;
  const SpatialSplitResult everywhere = build_spatial_split(mesh, make_references(mesh), config);
  EXPECT_GT(nodes_whose_children_share_a_triangle(everywhere, 64), 0u);  // the check can fail
  config.spatial_max = 64;
  const SpatialSplitResult small = build_spatial_split(mesh, make_references(mesh), config);
  ASSERT_TRUE(validate(small.bvh, small.refs).ok());
  expect_covered(mesh, small.refs);
  EXPECT_GT(small.stats.spatial_splits, 0u);  // still below the limit
  EXPECT_EQ(nodes_whose_children_share_a_triangle(small, 64), 0u);
}

// Nodes of two references take their own path (no bins cleared or swept). On pairs of every
// kind (apart, overlapping, identical, flat, sharing a centre, far from the origin): a valid
// tree of both triangles, and when split, two leaves of one with the left one's centre below
// the right one's on some axis (the binned split sends the lower centre left) or, for one
// centre, the same.
TEST(SpatialSplit, PairsOfReferencesSplitWithTheLowerCentreLeft) {
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int split = 0;
  for (int trial = 0; trial < 400; ++trial) {
    Mesh mesh;
    const float scale = trial % 4 == 3 ? 1e6f : 1.0f;
    const Vec3 offset = trial % 5 == 4 ? Vec3(1e5f, -3e4f, 7e3f) : Vec3(0.0f);
    Vec3 p[6];
    for (Vec3& v : p) v = offset + Vec3(u(rng), u(rng), u(rng)) * scale;
    if (trial % 7 == 1) p[3] = p[0], p[4] = p[1], p[5] = p[2];               // the same triangle twice
    if (trial % 7 == 2) p[3] = p[0] * 2.0f - p[1], p[4] = p[0] * 2.0f - p[2], p[5] = p[0];  // a shared corner
    if (trial % 7 == 3)
      for (Vec3& v : p) v.z = offset.z;  // flat on z
    if (trial % 7 == 4) p[3] = p[1], p[4] = p[0], p[5] = p[2];  // the same corners in another order
    for (const Vec3& v : p) mesh.add_vertex(v);
    mesh.add_triangle(0, 1, 2);
    mesh.add_triangle(3, 4, 5);
    const SpatialSplitResult r = build_spatial_split(mesh, make_references(mesh));
    ASSERT_TRUE(validate(r.bvh, r.refs).ok()) << "trial " << trial;
    ASSERT_EQ(r.refs.size(), 2u) << "trial " << trial;
    const BvhNode& root = r.bvh.nodes[r.bvh.root];
    if (root.is_leaf()) continue;
    ++split;
    const BvhNode& left = r.bvh.nodes[root.left()];
    const BvhNode& right = r.bvh.nodes[root.right()];
    ASSERT_TRUE(left.is_leaf() && right.is_leaf()) << "trial " << trial;
    ASSERT_EQ(left.ref_count() + right.ref_count(), 2u) << "trial " << trial;
    const Vec3 cl = r.refs.boxes[r.bvh.ref_indices[left.first_ref()]].center();
    const Vec3 cr = r.refs.boxes[r.bvh.ref_indices[right.first_ref()]].center();
    const bool same_centre = cl.x == cr.x && cl.y == cr.y && cl.z == cr.z;  // halved in slot order
    EXPECT_TRUE(same_centre || cl.x < cr.x || cl.y < cr.y || cl.z < cr.z) << "trial " << trial;
  }
  EXPECT_GT(split, 200);
}

// node_alpha only ever removes spatial splits: at 0 the root's test alone decides, and a
// node's object split can never overlap by more than the node's whole area, so at 1 a node
// tries a spatial split only when no object split exists (none in this scene).
TEST(SpatialSplit, NodeAlphaTriesSpatialSplitsOnlyWhereChildrenOverlapEnough) {
  const Mesh mesh = crossing_mesh(3000, 17);
  const PrimitiveRefs refs = make_references(mesh);
  SpatialSplitConfig config;
  config.spatial_from = 0;
  config.node_alpha = 0.0;
  const SpatialSplitResult all = build_spatial_split(mesh, refs, config);
  config.node_alpha = 0.1;
  const SpatialSplitResult some = build_spatial_split(mesh, refs, config);
  config.node_alpha = 1.0;
  const SpatialSplitResult none = build_spatial_split(mesh, refs, config);
  EXPECT_GT(all.stats.spatial_splits, 0u);
  EXPECT_GT(some.stats.spatial_splits, 0u);
  EXPECT_LE(some.stats.spatial_splits, all.stats.spatial_splits);
  EXPECT_EQ(none.stats.spatial_splits, 0u);
  EXPECT_EQ(none.refs.size(), mesh.triangle_count());
  for (const SpatialSplitResult* r : {&all, &some, &none}) EXPECT_TRUE(validate(r->bvh, r->refs).ok());
  config.node_alpha = -0.5;
  EXPECT_THROW(build_spatial_split(mesh, refs, config), Error);
  config.node_alpha = std::nan("");
  EXPECT_THROW(build_spatial_split(mesh, refs, config), Error);
}

// With fixed ranges (every node its own task), with subtrees of one task passing their room
// on, and with the whole tree built by one task.
TEST(SpatialSplit, BudgetIsNeverExceeded) {
  const Mesh mesh = crossing_mesh(800, 9);
  const size_t n = mesh.triangle_count();
  for (uint32_t threshold : {2u, 64u, 1u << 30})
    for (double budget : {1.0, 1.01, 1.1, 1.3, 2.0, 4.0}) {
      SpatialSplitConfig config;
      config.budget = budget;
      config.spatial_from = 0;
      config.parallel_threshold = threshold;
      const SpatialSplitResult r = build_spatial_split(mesh, make_references(mesh), config);
      const size_t limit = static_cast<size_t>(std::floor(budget * double(n)));
      EXPECT_LE(r.refs.size(), limit) << budget << " " << threshold;
      EXPECT_EQ(r.stats.budget, limit) << budget;
      EXPECT_TRUE(validate(r.bvh, r.refs).ok()) << budget << " " << threshold;
      if (budget == 1.0) { EXPECT_EQ(r.refs.size(), n); }
      if (budget >= 1.3) { EXPECT_GT(r.stats.spatial_splits, 0u); }
    }
}

// A grid of small disjoint triangles, which gain nothing from spatial splits, beside long
// sticks crossing each other, which gain from every reference they are given.
Mesh grid_beside_sticks(uint32_t side, uint32_t sticks, uint64_t seed, bool sticks_left = false) {
  Mesh mesh;
  const Vec3 grid_at(sticks_left ? 2.0f * float(side) : 0.0f, 0.0f, 0.0f);
  const Vec3 at(sticks_left ? 0.0f : 2.0f * float(side), 0.0f, 0.0f);
  for (uint32_t i = 0; i < side; ++i)
    for (uint32_t j = 0; j < side; ++j) {
      const uint32_t base = static_cast<uint32_t>(mesh.vertex_count());
      const Vec3 p = grid_at + Vec3(float(i), float(j), 0.0f);
      mesh.add_vertex(p);
      mesh.add_vertex(p + Vec3(0.5f, 0.0f, 0.0f));
      mesh.add_vertex(p + Vec3(0.0f, 0.5f, 0.0f));
      mesh.add_triangle(base, base + 1, base + 2);
    }
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, float(side));
  for (uint32_t k = 0; k < sticks; ++k) {
    const uint32_t base = static_cast<uint32_t>(mesh.vertex_count());
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    mesh.add_vertex(at + a);
    mesh.add_vertex(at + b);
    mesh.add_vertex(at + a + Vec3(0.0f, 0.0f, 0.01f));
    mesh.add_triangle(base, base + 1, base + 2);
  }
  return mesh;
}

// A subtree built by one task (fewer than parallel_threshold references) passes the room
// its left part leaves unused on to the right part: the tree built whole by one task uses
// more of the budget than the one of fixed ranges (every node its own task), never more
// than the budget, and both are valid.
TEST(SpatialSplit, OneTaskSubtreesPassUnusedRoomOn) {
  const Mesh mesh = grid_beside_sticks(40, 800, 5);
  const size_t limit = static_cast<size_t>(std::floor(1.3 * double(mesh.triangle_count())));
  SpatialSplitConfig config;
  config.spatial_from = 0;
  config.parallel_threshold = 2;
  const SpatialSplitResult fixed = build_spatial_split(mesh, make_references(mesh), config);
  config.parallel_threshold = 1u << 30;
  const SpatialSplitResult packed = build_spatial_split(mesh, make_references(mesh), config);
  for (const SpatialSplitResult* r : {&fixed, &packed}) {
    EXPECT_LE(r->refs.size(), limit);
    const ValidationReport v = validate(r->bvh, r->refs);
    EXPECT_TRUE(v.ok()) << v.summary();
    expect_covered(mesh, r->refs);
  }
  EXPECT_GT(packed.refs.size(), fixed.refs.size() + limit / 100);
  EXPECT_LT(sah_cost(packed.bvh), sah_cost(fixed.bvh));
}

// The spare room goes to the children by count times surface area: the sticks, a third of
// the triangles in a box of three times the grid's area, built first, get 60 % of it, where
// a share by counts would leave them a third (and the grid after them could not use it).
TEST(SpatialSplit, SpareRoomFollowsTheChildrenCountTimesArea) {
  const uint32_t side = 40, sticks = 800;
  const Mesh mesh = grid_beside_sticks(side, sticks, 5, /*sticks_left=*/true);
  const size_t n = mesh.triangle_count();
  SpatialSplitConfig config;
  config.spatial_from = 0;
  config.parallel_threshold = 1u << 30;
  const SpatialSplitResult r = build_spatial_split(mesh, make_references(mesh), config);
  ASSERT_TRUE(validate(r.bvh, r.refs).ok());
  const size_t spare = static_cast<size_t>(std::floor(1.3 * double(n))) - n;
  size_t stick_refs = 0;
  for (uint32_t tri : r.refs.triangle_ids) stick_refs += tri >= side * side;
  EXPECT_GT(stick_refs, sticks + spare / 3 + spare / 20);
  EXPECT_LE(stick_refs, sticks + spare * 62 / 100);
}

void expect_same(const SpatialSplitResult& a, const SpatialSplitResult& b, const std::string& what) {
  EXPECT_EQ(a.refs.boxes, b.refs.boxes) << what;
  EXPECT_EQ(a.refs.triangle_ids, b.refs.triangle_ids) << what;
  ASSERT_EQ(a.bvh.nodes.size(), b.bvh.nodes.size()) << what;
  for (size_t i = 0; i < a.bvh.nodes.size(); ++i) {
    const BvhNode &x = a.bvh.nodes[i], &y = b.bvh.nodes[i];
    ASSERT_TRUE(x.box == y.box && x.left_or_first == y.left_or_first && x.right_or_count == y.right_or_count &&
                x.parent == y.parent)
        << what << " node " << i;
  }
}

TEST(SpatialSplit, SameTreeOnOneAndTwoThreadsAndAnArenaOfEight) {
  const Mesh mesh = crossing_mesh(6000, 13);
  SpatialSplitResult one, two, eight;
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
    one = build_sbvh(mesh);
  }
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 2);
    two = build_sbvh(mesh);
  }
  tbb::task_arena arena(8);
  arena.execute([&] { eight = build_sbvh(mesh); });
  ASSERT_GT(one.stats.spatial_splits, 0u);
  expect_same(one, two, "1 vs 2 threads");
  expect_same(one, eight, "1 thread vs arena of 8");
  // The counts, summed over the threads that made the splits: one split per inner node, and
  // the same counts whatever the threads.
  size_t inner = 0;
  for (const BvhNode& n : one.bvh.nodes) inner += n.is_leaf() ? 0 : 1;
  EXPECT_EQ(one.stats.spatial_splits + one.stats.object_splits, inner);
  for (const SpatialSplitResult* other : {&two, &eight}) {
    EXPECT_EQ(other->stats.spatial_splits, one.stats.spatial_splits);
    EXPECT_EQ(other->stats.object_splits, one.stats.object_splits);
    EXPECT_EQ(other->stats.split_references, one.stats.split_references);
    EXPECT_EQ(other->stats.unsplit_references, one.stats.unsplit_references);
  }
  EXPECT_GT(one.stats.split_references, 0u);
}

TEST(SpatialSplit, SplitsLowerTheCostOfCrossingTriangles) {
  const Mesh mesh = crossing_mesh(3000, 17);
  const SpatialSplitResult split = build_sbvh(mesh, 1.3), unsplit = build_sbvh(mesh, 1.0);
  EXPECT_LT(sah_cost(split.bvh), 0.9 * sah_cost(unsplit.bvh));
}

TEST(SpatialSplit, EdgeVolumePiecesAsInput) {
  const Mesh mesh = crossing_mesh(1000, 19);
  EdgeVolumeConfig evh;
  evh.t = 12;
  const EdgeVolumeResult pieces = subdivide_edge_volume(mesh, evh);
  ASSERT_GT(pieces.refs.size(), mesh.triangle_count());
  const SpatialSplitResult r = build_sbvh(mesh, 1.3, 1, &pieces.refs);
  EXPECT_LE(r.refs.size(), std::max(pieces.refs.size(), size_t(1.3 * mesh.triangle_count())));
  EXPECT_TRUE(validate(r.bvh, r.refs).ok());
  expect_covered(mesh, r.refs);
}

TEST(SpatialSplit, BadInputIsAnError) {
  const Mesh mesh = crossing_mesh(50, 1);
  SpatialSplitConfig c;
  c.budget = 0.5;
  EXPECT_THROW(build_spatial_split(mesh, make_references(mesh), c), Error);
  c = {};
  c.budget = std::nan("");
  EXPECT_THROW(build_spatial_split(mesh, make_references(mesh), c), Error);
  c = {};
  c.spatial_bins = 1;
  EXPECT_THROW(build_spatial_split(mesh, make_references(mesh), c), Error);
  c = {};
  c.alpha = -1.0;
  EXPECT_THROW(build_spatial_split(mesh, make_references(mesh), c), Error);
  PrimitiveRefs wrong = make_references(mesh);
  wrong.triangle_ids[3] = 1000000;
  EXPECT_THROW(build_spatial_split(mesh, wrong, {}), Error);
  BuildOptions o;
  o.kind = BuilderKind::spatial_split;
  EXPECT_THROW(build_bvh(make_references(mesh), o), Error);
  EXPECT_EQ(build_tree(mesh, make_references(mesh), o).refs.size() >= mesh.triangle_count(), true);
  EXPECT_EQ(parse_builder("sbvh"), BuilderKind::spatial_split);
}

// ---- Ray hits against brute force, binary and wide layouts.

void expect_binary_matches(const Mesh& mesh, const Bvh& bvh, const PrimitiveRefs& refs, const std::string& what,
                           uint64_t rays = 1500) {
  for (bool through_finalize : {true, false}) {
    const Tracer tracer(through_finalize ? finalize(bvh, refs) : flatten_for_tracing(bvh, refs), mesh);
    for (RayKind kind : {RayKind::primary, RayKind::random}) {
      RaySetConfig rc;
      rc.kind = kind;
      rc.count = rays;
      rc.seed = 7;
      const RaySet set = make_ray_set(mesh, tracer, rc);
      for (RayQuery q : {RayQuery::closest, RayQuery::any}) {
        const BruteForceCheck c = check_against_brute_force(tracer, mesh, set.rays, q, rays, 3);
        EXPECT_EQ(c.mismatches, 0u) << what << ": " << c.first_mismatch;
        EXPECT_GT(c.checked, 0u);
      }
    }
  }
}

void expect_wide_matches(const Mesh& mesh, const Bvh& bvh, const PrimitiveRefs& refs, const std::string& what,
                         uint64_t rays = 1500) {
  const FlatBvh flat = finalize(bvh, refs);
  RaySetConfig rc;
  rc.kind = RayKind::random;
  rc.count = rays;
  rc.seed = 11;
  const RaySet set = make_ray_set(mesh, Tracer(flat, mesh), rc);
  for (uint32_t width : {4u, 8u}) {
    WideTracerOptions o;
    o.layout.collapse.width = width;
    o.layout.test = TriangleTest::watertight;
    const WideTracer tracer(flat, mesh, o);
    std::vector<Hit> hits(set.rays.size());
    TraceCounters counters;
    tracer.closest(set.rays.data(), set.rays.size(), hits.data(), counters);
    size_t bad = 0, hit = 0;
    for (size_t i = 0; i < set.rays.size(); ++i) {
      const Hit want = brute_force_closest(mesh, set.rays[i]);
      hit += want.hit();
      bad += hits[i].triangle_id != want.triangle_id || (want.hit() && hits[i].t != want.t);
    }
    EXPECT_EQ(bad, 0u) << what << " bvh" << width;
    EXPECT_GT(hit, rays / 20);
  }
}

TEST(SpatialSplit, RayHitsMatchBruteForce) {
  const Mesh mesh = crossing_mesh(1200, 23);
  for (uint32_t leaf : {1u, 4u}) {
    const SpatialSplitResult r = build_sbvh(mesh, 1.5, leaf);
    ASSERT_GT(r.stats.spatial_splits, 0u);
    expect_binary_matches(mesh, r.bvh, r.refs, "leaf " + std::to_string(leaf));
    expect_wide_matches(mesh, r.bvh, r.refs, "leaf " + std::to_string(leaf));
  }
}

TEST(SpatialSplit, RayHitsMatchBruteForceOnRotatedSharedScene) {
  const std::filesystem::path file = testing::scenes_dir() / "staircase.obj";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << file << " not found";
  Mesh mesh = load_mesh_file(file);
  rotate_mesh(mesh, Vec3(30.0f, 30.0f, 0.0f));
  const SpatialSplitResult r = build_sbvh(mesh);
  EXPECT_TRUE(validate(r.bvh, r.refs).ok());
  expect_binary_matches(mesh, r.bvh, r.refs, "staircase", 300);
  expect_wide_matches(mesh, r.bvh, r.refs, "staircase", 300);
}

// ---- Optimizers and collapse on SBVH trees.

TEST(SpatialSplit, InsertionAndRotationsKeepATrackedCostEqualToTheRecomputedOne) {
  const Mesh mesh = crossing_mesh(2000, 29);
  SpatialSplitResult r = build_sbvh(mesh);
  ASSERT_GT(r.refs.size(), mesh.triangle_count());
  const double built = sah_cost(r.bvh);
  InsertionConfig ic;
  ic.limits.max_passes = 30;
  const OptimizeReport ins = optimize_insertion(r.bvh, ic);
  EXPECT_TRUE(validate(r.bvh, r.refs).ok());
  EXPECT_NEAR(ins.final_cost, sah_cost(r.bvh), 1e-9 * ins.final_cost);
  EXPECT_LT(ins.final_cost, built);
  // Leaves of one reference: counting triangles or references is the same here.
  EXPECT_EQ(sah_cost(r.bvh, r.refs), sah_cost(r.bvh));
  HillClimbConfig hc;
  const OptimizeReport rot = hill_climb(r.bvh, hc);
  EXPECT_TRUE(validate(r.bvh, r.refs).ok());
  EXPECT_NEAR(rot.final_cost, sah_cost(r.bvh), 1e-9 * rot.final_cost);
  expect_binary_matches(mesh, r.bvh, r.refs, "optimized");
}

TEST(SpatialSplit, CollapseKeepsEachTriangleOnceAndCountsTriangles) {
  const Mesh mesh = crossing_mesh(2000, 31);
  SpatialSplitResult r = build_sbvh(mesh, 2.0);
  // Several references of one triangle under one node, so that collapsing merges some.
  const std::vector<uint64_t> tri = subtree_triangle_counts(r.bvh, r.refs);
  const double ocost_triangles = optimal_collapse_cost(r.bvh, r.refs);
  const double ocost_references = optimal_collapse_cost(r.bvh);
  EXPECT_LE(ocost_triangles, ocost_references);
  EXPECT_LT(tri[r.bvh.root], r.refs.size());
  EXPECT_EQ(tri[r.bvh.root], mesh.triangle_count());
  Bvh plain = r.bvh;
  const CollapseResult c = collapse_leaves(r.bvh, r.refs, CollapseConfig{});
  EXPECT_NEAR(c.cost_after, ocost_triangles, 1e-9 * ocost_triangles);
  EXPECT_NEAR(sah_cost(r.bvh, r.refs), c.cost_after, 1e-9 * c.cost_after);
  // After the dedup each leaf's references are its distinct triangles: both counts agree.
  EXPECT_NEAR(sah_cost(r.bvh), c.cost_after, 1e-9 * c.cost_after);
  EXPECT_GT(c.dropped_references, 0u) << "no leaf merged pieces: the test says nothing";
  const ValidationReport v = validate_deduplicated(r.bvh, r.refs);
  EXPECT_TRUE(v.ok()) << v.summary();
  expect_binary_matches(mesh, r.bvh, r.refs, "collapsed");
  expect_wide_matches(mesh, r.bvh, r.refs, "collapsed");
  // The plain collapse (counting references) keeps duplicates and costs at least as much.
  const CollapseResult p = collapse_leaves(plain, CollapseConfig{});
  EXPECT_GE(p.cost_after, c.cost_after);
}

// Subtree triangle counts against a brute-force count of each subtree's triangle set.
TEST(TriangleCost, SubtreeCountsMatchBruteForce) {
  const Mesh mesh = crossing_mesh(400, 37);
  const SpatialSplitResult r = build_sbvh(mesh, 3.0);
  Bvh bvh = r.bvh;
  CollapseConfig big;
  big.cost = CostModel{20.0, 1.0};  // traversal dear: big leaves, holding repeated triangles
  collapse_leaves(bvh, big);
  const std::vector<uint64_t> got = subtree_triangle_counts(bvh, r.refs);
  size_t repeated = 0;
  for (uint32_t n : bvh.depth_first_order()) {
    std::vector<uint32_t> ids, stack{n};
    while (!stack.empty()) {
      const BvhNode& nd = bvh[stack.back()];
      stack.pop_back();
      if (!nd.is_leaf()) {
        stack.push_back(nd.left());
        stack.push_back(nd.right());
        continue;
      }
      for (uint32_t k = 0; k < nd.ref_count(); ++k) ids.push_back(r.refs.triangle_ids[bvh.ref_indices[nd.first_ref() + k]]);
    }
    const size_t all = ids.size();
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    ASSERT_EQ(got[n], ids.size()) << "node " << n;
    repeated += bvh[n].is_leaf() && ids.size() < all;
  }
  EXPECT_GT(repeated, 0u) << "no leaf repeats a triangle: the test says nothing";
}

// The shortcut for unsplit references: it must see a triangle's second slot wherever it
// is, and where it sees none, the triangle-counting functions must give what the
// reference-counting ones give, bit for bit, and the same collapsed tree.
TEST(TriangleCost, OneSlotPerTriangleTakesTheReferenceCountingPathWithTheSameResult) {
  const Mesh mesh = crossing_mesh(400, 41);
  SweepSahConfig config;
  config.leaf.max_leaf_size = 1;
  const PrimitiveRefs refs = make_references(mesh);
  const Bvh unsplit = build_sweep_sah(refs, config);
  ASSERT_TRUE(one_slot_per_triangle(unsplit, refs));
  EXPECT_EQ(sah_cost(unsplit, refs), sah_cost(unsplit));
  EXPECT_EQ(optimal_collapse_cost(unsplit, refs), optimal_collapse_cost(unsplit));
  EXPECT_EQ(optimal_collapse_cost(unsplit, refs, {}, 4), optimal_collapse_cost(unsplit, {}, 4));
  Bvh a = unsplit, b = unsplit;
  const CollapseResult ca = collapse_leaves(a, refs, CollapseConfig{});
  const CollapseResult cb = collapse_leaves(b, CollapseConfig{});
  EXPECT_EQ(ca.cost_after, cb.cost_after);
  EXPECT_EQ(ca.dropped_references, 0u);
  EXPECT_EQ(a.ref_indices, b.ref_indices);
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  for (size_t n = 0; n < a.nodes.size(); ++n)
    EXPECT_EQ(a.nodes[n].right_or_count, b.nodes[n].right_or_count) << "node " << n;

  // Split references: two slots of one triangle, in leaves far apart or in one leaf.
  const SpatialSplitResult r = build_sbvh(mesh, 3.0);
  ASSERT_GT(r.refs.size(), mesh.triangle_count());
  EXPECT_FALSE(one_slot_per_triangle(r.bvh, r.refs));
  // One reference per triangle but a slot listed twice: also not one slot per triangle.
  Bvh twice = unsplit;
  twice.ref_indices.back() = twice.ref_indices.front();
  EXPECT_FALSE(one_slot_per_triangle(twice, refs));
}

}  // namespace
}  // namespace bvhopt
