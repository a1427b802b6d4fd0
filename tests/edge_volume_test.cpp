// Edge volume subdivision and the leaf dedup pass: invariants, an exact watertightness
// check on a closed mesh, determinism across thread counts, and traversal against brute
// force on a subdivided scene.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <map>
#include <tuple>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/edge_volume_subdivision.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/tracer.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "bvhopt/validate.h"
#include "test_support.h"

namespace bvhopt {
namespace {

// The surface of the cube [0, n]^3 as a closed mesh: each face an n x n grid of squares,
// two triangles each, every lattice point one shared vertex (so edges between faces are
// shared too). Faces lie in the axis planes: no edge box has volume.
Mesh lattice_cube(int n) {
  Mesh mesh;
  mesh.name = "cube";
  std::map<std::array<int, 3>, uint32_t> index;
  auto vertex = [&](std::array<int, 3> p) {
    auto it = index.find(p);
    if (it != index.end()) return it->second;
    const uint32_t v = static_cast<uint32_t>(mesh.vertex_count());
    mesh.add_vertex(Vec3(float(p[0]), float(p[1]), float(p[2])));
    index.emplace(p, v);
    return v;
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, w = (axis + 2) % 3;
    for (int side : {0, n}) {
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          auto at = [&](int a, int b) {
            std::array<int, 3> p{};
            p[axis] = side;
            p[u] = a;
            p[w] = b;
            return vertex(p);
          };
          const uint32_t a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
          // Alternate the diagonal so both diagonal directions occur.
          if ((i + j) % 2) {
            mesh.add_triangle(a, b, c);
            mesh.add_triangle(a, c, d);
          } else {
            mesh.add_triangle(a, b, d);
            mesh.add_triangle(b, c, d);
          }
        }
      }
    }
  }
  return mesh;
}

Mesh rotated_cube(int n) {
  Mesh mesh = lattice_cube(n);
  rotate_mesh(mesh, Vec3(30.0f, 30.0f, 0.0f));
  return mesh;
}

double area_d(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
  const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
  const double cx = uy * vz - uz * vy, cy = uz * vx - ux * vz, cz = ux * vy - uy * vx;
  return 0.5 * std::sqrt(cx * cx + cy * cy + cz * cz);
}

// Barycentric coordinates of p in triangle (a, b, c), in double.
std::array<double, 3> barycentric(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& p) {
  const double total = area_d(a, b, c);
  return {area_d(p, b, c) / total, area_d(a, p, c) / total, area_d(a, b, p) / total};
}

TEST(EdgeVolume, AxisAlignedTrianglesAreNeverSplit) {
  // A huge t makes eps tiny: only a zero volume can stay below it.
  const Mesh mesh = lattice_cube(6);
  EdgeVolumeConfig config;
  config.t = 60;
  config.max_reference_ratio = 0;
  const EdgeVolumeResult r = subdivide_edge_volume(mesh, config);
  EXPECT_EQ(r.refs.size(), mesh.triangle_count());
  EXPECT_EQ(r.stats.subdivided_triangles, 0u);
  EXPECT_EQ(r.stats.deepest, 0u);
  for (size_t i = 0; i < r.refs.size(); ++i) {
    ASSERT_EQ(r.refs.triangle_ids[i], i);
    EXPECT_EQ(r.refs.boxes[i], mesh.triangle(i).bounds());
  }
  // The same cube rotated off the axes must split, or the test above proves nothing.
  config.t = 14;
  EXPECT_GT(count_edge_volume(rotated_cube(6), config).subdivided_triangles, 0u);
}

TEST(EdgeVolume, PiecesLieInsideAndCoverTheirTriangle) {
  const Mesh mesh = testing::random_mesh(400, 11, /*with_degenerate=*/true);
  EdgeVolumeConfig config;
  config.t = 20;
  const SubdividedTriangles pieces = subdivide_edge_volume_triangles(mesh, config);
  ASSERT_GT(pieces.stats.subdivided_triangles, 50u);
  ASSERT_FALSE(pieces.stats.depth_limit_hit);
  std::vector<double> covered(mesh.triangle_count(), 0.0);
  for (size_t i = 0; i < pieces.triangles.size(); ++i) {
    const uint32_t id = pieces.triangle_ids[i];
    ASSERT_LT(id, mesh.triangle_count());
    if (i > 0) {
      ASSERT_LE(pieces.triangle_ids[i - 1], id) << "pieces grouped by triangle, in order";
    }
    const Triangle orig = mesh.triangle(id);
    const Triangle& p = pieces.triangles[i];
    ASSERT_TRUE(orig.bounds().contains(p.bounds())) << "piece " << i;
    covered[id] += area_d(p.v0, p.v1, p.v2);
    if (orig.is_degenerate()) continue;
    for (const Vec3& v : {p.v0, p.v1, p.v2})
      for (double b : barycentric(orig.v0, orig.v1, orig.v2, v)) ASSERT_GE(b, -1e-5) << "piece " << i;
    // Inside means the three barycentrics sum to one (they would exceed it outside).
    for (const Vec3& v : {p.v0, p.v1, p.v2}) {
      const auto b = barycentric(orig.v0, orig.v1, orig.v2, v);
      ASSERT_NEAR(b[0] + b[1] + b[2], 1.0, 1e-4) << "piece " << i;
    }
  }
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    const Triangle orig = mesh.triangle(t);
    const double a = area_d(orig.v0, orig.v1, orig.v2);
    EXPECT_NEAR(covered[t], a, 1e-4 * a + 1e-9) << "triangle " << t;
  }
}

TEST(EdgeVolume, ReferencesAreThePiecesBoxes) {
  const Mesh mesh = testing::random_mesh(300, 5);
  EdgeVolumeConfig config;
  config.t = 18;
  const EdgeVolumeResult r = subdivide_edge_volume(mesh, config);
  const SubdividedTriangles p = subdivide_edge_volume_triangles(mesh, config);
  ASSERT_EQ(r.refs.size(), p.triangles.size());
  ASSERT_GT(r.refs.size(), mesh.triangle_count());
  for (size_t i = 0; i < r.refs.size(); ++i) {
    EXPECT_EQ(r.refs.boxes[i], p.triangles[i].bounds());
    EXPECT_EQ(r.refs.centroids[i], p.triangles[i].bounds().center());
    EXPECT_EQ(r.refs.triangle_ids[i], p.triangle_ids[i]);
  }
}

// Watertight: after subdivision of a closed mesh every piece edge (as an unordered pair of
// exact float points) is shared by exactly two pieces. A shared edge split at different
// points, or split from one side only, leaves a T-junction: a piece edge seen once.
TEST(EdgeVolume, SharedEdgesSplitAtIdenticalPoints) {
  const Mesh mesh = rotated_cube(5);
  EdgeVolumeConfig config;
  config.t = 16;
  config.max_reference_ratio = 0;
  const SubdividedTriangles pieces = subdivide_edge_volume_triangles(mesh, config);
  ASSERT_FALSE(pieces.stats.depth_limit_hit);
  ASSERT_FALSE(pieces.stats.budget_hit);
  ASSERT_GT(pieces.stats.ratio, 2.0) << "the test needs real subdivision";
  using Key = std::tuple<float, float, float, float, float, float>;
  std::map<Key, int> edges;
  auto key = [](Vec3 a, Vec3 b) {
    if (std::tie(b.x, b.y, b.z) < std::tie(a.x, a.y, a.z)) std::swap(a, b);
    return Key{a.x, a.y, a.z, b.x, b.y, b.z};
  };
  for (const Triangle& t : pieces.triangles) {
    ++edges[key(t.v0, t.v1)];
    ++edges[key(t.v1, t.v2)];
    ++edges[key(t.v2, t.v0)];
  }
  size_t bad = 0;
  for (const auto& [k, count] : edges) bad += count != 2;
  EXPECT_EQ(bad, 0u) << "of " << edges.size() << " piece edges";

  // Also the unsubdivided cube, so the check itself is known to pass on a closed mesh and
  // to fail on a T-junction.
  Mesh broken = rotated_cube(5);
  const Triangle t0 = broken.triangle(0);
  const Vec3 m = (t0.v0 + t0.v1) * 0.5f;
  const uint32_t mv = static_cast<uint32_t>(broken.vertex_count());
  broken.add_vertex(m);
  const uint32_t i0 = broken.indices[0], i1 = broken.indices[1], i2 = broken.indices[2];
  broken.indices[1] = mv;  // triangle 0 becomes (v0, m, v2) ...
  broken.add_triangle(mv, i1, i2);  // ... plus (m, v1, v2): edge v0-v1 split on one side only
  (void)i0;
  EdgeVolumeConfig none;
  none.t = -1;  // eps above the scene volume: no splits
  std::map<Key, int> e2;
  for (const Triangle& t : subdivide_edge_volume_triangles(broken, none).triangles) {
    ++e2[key(t.v0, t.v1)];
    ++e2[key(t.v1, t.v2)];
    ++e2[key(t.v2, t.v0)];
  }
  size_t bad2 = 0;
  for (const auto& [k, count] : e2) bad2 += count != 2;
  EXPECT_GT(bad2, 0u);
}

TEST(EdgeVolume, CountPassEqualsFillPass) {
  for (uint64_t seed : {1u, 2u, 3u}) {
    const Mesh mesh = testing::random_mesh(500, seed, true);
    for (int t : {8, 14, 20}) {
      EdgeVolumeConfig config;
      config.t = t;
      const EdgeVolumeStats counted = count_edge_volume(mesh, config);
      const EdgeVolumeResult filled = subdivide_edge_volume(mesh, config);
      EXPECT_EQ(counted.references, filled.refs.size());
      EXPECT_EQ(filled.stats.references, filled.refs.size());
      EXPECT_EQ(counted.subdivided_triangles, filled.stats.subdivided_triangles);
      EXPECT_EQ(counted.deepest, filled.stats.deepest);
      // Per triangle: the fill pass wrote exactly as many pieces as it had room for, so
      // every triangle is present and pieces are contiguous.
      std::vector<uint32_t> per(mesh.triangle_count(), 0);
      for (uint32_t id : filled.refs.triangle_ids) ++per[id];
      for (uint32_t c : per) ASSERT_GE(c, 1u);
      EXPECT_DOUBLE_EQ(filled.stats.ratio, double(filled.refs.size()) / double(mesh.triangle_count()));
    }
  }
}

TEST(EdgeVolume, AreaReductionFactorsLieInQuarterToOne) {
  for (const Mesh& mesh : {testing::random_mesh(500, 9, true), rotated_cube(4)}) {
    EdgeVolumeConfig config;
    config.t = 18;
    const AreaReduction a = area_reduction_factors(mesh, config);
    ASSERT_GT(a.splits, 0u);
    // The float midpoint may round a hair below the exact one.
    EXPECT_GE(a.best, 0.25 * (1.0 - 1e-5));
    EXPECT_LE(a.worst, 1.0);
    EXPECT_LE(a.best, a.average);
    EXPECT_LE(a.average, a.worst);
    // Every split adds exactly one piece.
    EXPECT_EQ(a.splits, a.stats.references - a.stats.triangles);
  }
  // A needle along the box diagonal halves in every dimension: the factor is 0.25 exactly.
  Mesh needle;
  needle.add_vertex(Vec3(0, 0, 0));
  needle.add_vertex(Vec3(8, 8, 8));
  needle.add_vertex(Vec3(8, 8, 8.0f));
  needle.add_vertex(Vec3(0, 0, 0.001f));
  needle.add_triangle(0, 1, 3);
  EdgeVolumeConfig one;
  one.t = 2;
  const AreaReduction n = area_reduction_factors(needle, one);
  ASSERT_GT(n.splits, 0u);
  EXPECT_NEAR(n.best, 0.25, 1e-3);
}

TEST(EdgeVolume, SameOutputOnOneAndTwoThreads) {
  Mesh mesh = testing::random_mesh(20000, 4, true);
  EdgeVolumeConfig config;
  config.t = 18;
  EdgeVolumeResult r1, r2;
  AreaReduction a1, a2;
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
    r1 = subdivide_edge_volume(mesh, config);
    a1 = area_reduction_factors(mesh, config);
  }
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 2);
    r2 = subdivide_edge_volume(mesh, config);
    a2 = area_reduction_factors(mesh, config);
  }
  ASSERT_GT(r1.refs.size(), mesh.triangle_count());
  EXPECT_EQ(r1.refs.boxes, r2.refs.boxes);
  EXPECT_EQ(r1.refs.centroids, r2.refs.centroids);
  EXPECT_EQ(r1.refs.triangle_ids, r2.refs.triangle_ids);
  EXPECT_EQ(a1.average, a2.average);
  EXPECT_EQ(a1.best, a2.best);
  EXPECT_EQ(a1.worst, a2.worst);
}

// The volume of the box of edge (a, b), in double as an independent oracle.
double edge_box_volume(const Vec3& a, const Vec3& b) {
  return std::abs(double(a.x) - b.x) * std::abs(double(a.y) - b.y) * std::abs(double(a.z) - b.z);
}

double largest_edge_box_volume(const Triangle& t) {
  return std::max({edge_box_volume(t.v0, t.v1), edge_box_volume(t.v1, t.v2), edge_box_volume(t.v2, t.v0)});
}

// The stopping rule of section 2.2: no piece leaves the subdivision with an edge box above
// eps_v = V / 2^t (no piece here hits the depth guard), and a piece is only split when it
// had one: every triangle split at least once had a fat edge.
TEST(EdgeVolume, EveryPieceEndsAtOrBelowTheThreshold) {
  const Mesh mesh = testing::random_mesh(500, 4, true);
  const Box bounds = describe(mesh).bounds;
  const Vec3 extent = bounds.extent();
  const double volume = double(extent.x) * extent.y * extent.z;
  for (int t : {10, 16, 22}) {
    EdgeVolumeConfig config;
    config.t = t;
    config.max_reference_ratio = 0;
    const SubdividedTriangles pieces = subdivide_edge_volume_triangles(mesh, config);
    ASSERT_EQ(pieces.stats.depth_limited, 0u);
    const double eps = volume / std::ldexp(1.0, t);
    ASSERT_NEAR(pieces.stats.threshold, eps, eps * 1e-6) << "t " << t;
    std::vector<size_t> count(mesh.triangle_count(), 0);
    for (size_t i = 0; i < pieces.triangles.size(); ++i) {
      EXPECT_LE(largest_edge_box_volume(pieces.triangles[i]), eps * (1 + 1e-6)) << "t " << t << ", piece " << i;
      ++count[pieces.triangle_ids[i]];
    }
    size_t split = 0;
    for (size_t tri = 0; tri < mesh.triangle_count(); ++tri) {
      const bool fat = largest_edge_box_volume(mesh.triangle(tri)) > eps * (1 + 1e-6);
      const bool thin = largest_edge_box_volume(mesh.triangle(tri)) < eps * (1 - 1e-6);
      if (thin) {
        EXPECT_EQ(count[tri], 1u) << "t " << t << ": triangle " << tri << " split without a fat edge";
      }
      if (fat) {
        EXPECT_GT(count[tri], 1u) << "t " << t << ": triangle " << tri << " kept a fat edge";
      }
      split += count[tri] > 1;
    }
    EXPECT_GT(split, 0u) << "t " << t << " split nothing: the test proves nothing";
  }
}

// One split (max_depth 1) of a triangle whose three edges have boxes of volume 8 (AB),
// 6 (AC) and 3 (BC): the new vertex is the midpoint of AB, the largest, in both pieces.
TEST(EdgeVolume, TheSplitEdgeIsTheOneWithTheLargestBox) {
  Mesh mesh;
  mesh.name = "three edges";
  const Vec3 a(0, 0, 0), b(4, 2, 1), c(1, 3, 2);
  for (const Vec3& v : {a, b, c}) mesh.add_vertex(v);
  mesh.add_triangle(0, 1, 2);
  for (const auto& [order, label] : {std::pair{std::array<uint32_t, 3>{0, 1, 2}, "abc"},
                                     std::pair{std::array<uint32_t, 3>{2, 0, 1}, "cab"},
                                     std::pair{std::array<uint32_t, 3>{1, 2, 0}, "bca"}}) {
    mesh.indices.assign(order.begin(), order.end());
    EdgeVolumeConfig config;
    config.t = 30;
    config.max_depth = 1;
    config.max_reference_ratio = 0;
    const SubdividedTriangles pieces = subdivide_edge_volume_triangles(mesh, config);
    ASSERT_EQ(pieces.triangles.size(), 2u) << label;
    const Vec3 mid_ab(2, 1, 0.5f);
    for (const Triangle& t : pieces.triangles) {
      const bool has_mid = t.v0 == mid_ab || t.v1 == mid_ab || t.v2 == mid_ab;
      EXPECT_TRUE(has_mid) << label << ": a piece without the midpoint of the largest edge box";
      const bool has_c = t.v0 == c || t.v1 == c || t.v2 == c;
      EXPECT_TRUE(has_c) << label << ": the corner opposite the split edge is in both pieces";
    }
  }
}

// More threads than cores (an arena of 8): the same references as on one thread.
TEST(EdgeVolume, SameOutputInAnArenaOfEight) {
  const Mesh mesh = testing::random_mesh(20000, 4, true);
  EdgeVolumeConfig config;
  config.t = 18;
  EdgeVolumeResult one, eight;
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
    one = subdivide_edge_volume(mesh, config);
  }
  tbb::task_arena arena(8);
  arena.execute([&] { eight = subdivide_edge_volume(mesh, config); });
  EXPECT_EQ(one.refs.boxes, eight.refs.boxes);
  EXPECT_EQ(one.refs.triangle_ids, eight.refs.triangle_ids);
}

TEST(EdgeVolume, DepthGuardIsRespected) {
  // One thin diagonal triangle in a scene of unit volume: t = 40 wants dozens of splits.
  Mesh mesh;
  mesh.add_vertex(Vec3(0, 0, 0));
  mesh.add_vertex(Vec3(1, 1, 1));
  mesh.add_vertex(Vec3(0.001f, 0, 0));
  mesh.add_triangle(0, 1, 2);
  EdgeVolumeConfig config;
  config.t = 40;
  config.max_depth = 5;
  config.max_reference_ratio = 0;
  const EdgeVolumeResult r = subdivide_edge_volume(mesh, config);
  EXPECT_TRUE(r.stats.depth_limit_hit);
  EXPECT_GT(r.stats.depth_limited, 0u);
  EXPECT_EQ(r.stats.deepest, 5u);
  EXPECT_LE(r.refs.size(), 32u);
  EXPECT_FALSE(r.stats.budget_hit);
  config.max_depth = 0;
  EXPECT_EQ(subdivide_edge_volume(mesh, config).refs.size(), 1u);
}

TEST(EdgeVolume, ReferenceBudgetLowersT) {
  const Mesh mesh = rotated_cube(6);
  EdgeVolumeConfig config;
  config.t = 22;
  config.max_reference_ratio = 0;
  const size_t unlimited = count_edge_volume(mesh, config).references;
  ASSERT_GT(unlimited, 3 * mesh.triangle_count());
  config.max_reference_ratio = 1.5;
  const EdgeVolumeResult r = subdivide_edge_volume(mesh, config);
  EXPECT_TRUE(r.stats.budget_hit);
  EXPECT_LT(r.stats.effective_t, 22);
  EXPECT_LE(double(r.refs.size()), 1.5 * double(mesh.triangle_count()));
  // One step higher would have broken the budget (the largest t that fits is chosen).
  EdgeVolumeConfig next = config;
  next.t = r.stats.effective_t + 1;
  next.max_reference_ratio = 0;
  EXPECT_GT(double(count_edge_volume(mesh, next).references), 1.5 * double(mesh.triangle_count()));
}

TEST(EdgeVolume, BadInputIsAnError) {
  Mesh mesh = testing::random_mesh(10, 1);
  EdgeVolumeConfig bad_depth;
  bad_depth.max_depth = 31;
  EXPECT_THROW(subdivide_edge_volume(mesh, bad_depth), Error);
  EdgeVolumeConfig bad_ratio;
  bad_ratio.max_reference_ratio = 0.5;
  EXPECT_THROW(count_edge_volume(mesh, bad_ratio), Error);
  mesh.indices[7] = 999;
  try {
    subdivide_edge_volume(mesh);
    FAIL() << "no error for an index out of range";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("triangle 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("random(1)"), std::string::npos) << e.what();
  }
}

// A tree over subdivided references with leaves of up to 8.
Bvh build_over(const PrimitiveRefs& refs, uint32_t leaf = 8) {
  BuildOptions options;
  options.leaf.max_leaf_size = leaf;
  return build_bvh(refs, options);
}

// Independent of validate_deduplicated: no leaf holds two references to one triangle.
size_t leaves_with_repeats(const Bvh& bvh, const PrimitiveRefs& refs) {
  size_t bad = 0;
  for (uint32_t n : bvh.depth_first_order()) {
    const BvhNode& node = bvh[n];
    if (!node.is_leaf()) continue;
    std::vector<uint32_t> ids;
    for (uint32_t k = 0; k < node.ref_count(); ++k) ids.push_back(refs.triangle_ids[bvh.ref_indices[node.first_ref() + k]]);
    std::sort(ids.begin(), ids.end());
    bad += std::adjacent_find(ids.begin(), ids.end()) != ids.end();
  }
  return bad;
}

TEST(LeafDedup, NoLeafHoldsATriangleTwice) {
  Mesh mesh = rotated_cube(6);
  EdgeVolumeConfig config;
  config.t = 20;
  const EdgeVolumeResult r = subdivide_edge_volume(mesh, config);
  Bvh bvh = build_over(r.refs);
  ASSERT_TRUE(validate(bvh, r.refs).ok());
  const size_t before = leaves_with_repeats(bvh, r.refs);
  ASSERT_GT(before, 0u) << "the test needs leaves with repeated triangles";
  EXPECT_FALSE(validate_deduplicated(bvh, r.refs).ok()) << "the check must see the repeats";

  std::vector<Box> leaf_boxes;
  for (uint32_t n : bvh.depth_first_order())
    if (bvh[n].is_leaf()) leaf_boxes.push_back(bvh[n].box);
  const double cost_before = sah_cost(bvh);

  const LeafDedupStats s = dedup_leaf_references(bvh, r.refs);
  EXPECT_EQ(leaves_with_repeats(bvh, r.refs), 0u);
  EXPECT_EQ(s.leaves_changed, before);
  EXPECT_LT(s.slots_after, s.slots_before);
  EXPECT_EQ(s.slots_after, bvh.ref_indices.size());
  const ValidationReport v = validate_deduplicated(bvh, r.refs);
  EXPECT_TRUE(v.ok()) << v.summary();
  // Leaf boxes are untouched (the union of everything the leaf held), in the same order.
  std::vector<Box> after;
  for (uint32_t n : bvh.depth_first_order())
    if (bvh[n].is_leaf()) after.push_back(bvh[n].box);
  EXPECT_EQ(after, leaf_boxes);
  EXPECT_LT(sah_cost(bvh), cost_before);
  // Every triangle still appears somewhere.
  std::vector<uint8_t> seen(mesh.triangle_count(), 0);
  for (uint32_t ref : bvh.ref_indices) seen[r.refs.triangle_ids[ref]] = 1;
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), long(mesh.triangle_count()));

  // Dropping a whole leaf's content is caught as a missing triangle.
  Bvh broken = bvh;
  for (uint32_t n : broken.depth_first_order()) {
    BvhNode& node = broken[n];
    if (node.is_leaf() && node.ref_count() == 1) {
      const uint32_t id = r.refs.triangle_ids[broken.ref_indices[node.first_ref()]];
      // Point the slot at a piece of another triangle that no leaf uses.
      for (size_t ref = 0; ref < r.refs.size(); ++ref) {
        if (r.refs.triangle_ids[ref] != id &&
            std::find(broken.ref_indices.begin(), broken.ref_indices.end(), ref) == broken.ref_indices.end()) {
          broken.ref_indices[node.first_ref()] = static_cast<uint32_t>(ref);
          break;
        }
      }
      break;
    }
  }
  EXPECT_FALSE(validate_deduplicated(broken, r.refs).ok());
}

TEST(LeafDedup, UnsubdividedTreeIsUnchanged) {
  const Mesh mesh = testing::random_mesh(2000, 3);
  const PrimitiveRefs refs = make_references(mesh);
  Bvh bvh = build_over(refs);
  Bvh copy = bvh;
  copy.renumber_depth_first();
  const LeafDedupStats s = dedup_leaf_references(bvh, refs);
  EXPECT_EQ(s.leaves_changed, 0u);
  EXPECT_EQ(bvh.ref_indices, copy.ref_indices);
  EXPECT_TRUE(validate(bvh, refs).ok());
  EXPECT_TRUE(validate_deduplicated(bvh, refs).ok());
}

void expect_traversal_matches_brute_force(const Mesh& mesh, int t, uint32_t leaf, uint64_t rays) {
  EdgeVolumeConfig config;
  config.t = t;
  const EdgeVolumeResult r = subdivide_edge_volume(mesh, config);
  ASSERT_GT(r.stats.subdivided_triangles, 0u);
  Bvh bvh = build_over(r.refs, leaf);
  dedup_leaf_references(bvh, r.refs);
  ASSERT_TRUE(validate_deduplicated(bvh, r.refs).ok());
  for (bool through_finalize : {true, false}) {
    const Tracer tracer(through_finalize ? finalize(bvh, r.refs) : flatten_for_tracing(bvh, r.refs), mesh);
    for (RayKind kind : {RayKind::primary, RayKind::random}) {
      RaySetConfig rc;
      rc.kind = kind;
      rc.count = rays;
      rc.seed = 7;
      const RaySet set = make_ray_set(mesh, tracer, rc);
      for (RayQuery q : {RayQuery::closest, RayQuery::any}) {
        const BruteForceCheck c = check_against_brute_force(tracer, mesh, set.rays, q, rays, 3);
        EXPECT_EQ(c.mismatches, 0u) << c.first_mismatch;
        EXPECT_GT(c.checked, 0u);
      }
    }
  }
}

TEST(EdgeVolumeTraversal, MatchesBruteForceOnSubdividedScene) {
  Mesh mesh = rotated_cube(6);
  const Mesh soup = testing::random_mesh(300, 8, true);
  // Put the soup inside the cube's space so rays meet both.
  const uint32_t base = static_cast<uint32_t>(mesh.vertex_count());
  for (size_t v = 0; v < soup.vertex_count(); ++v) mesh.add_vertex(soup.vertex(v) * 0.05f + Vec3(0.5f, 0.5f, 0.5f));
  for (uint32_t i : soup.indices) mesh.indices.push_back(base + i);
  for (uint32_t leaf : {1u, 4u}) expect_traversal_matches_brute_force(mesh, 18, leaf, 1500);
}

TEST(EdgeVolumeTraversal, MatchesBruteForceOnRotatedSharedScene) {
  const std::filesystem::path file = testing::scenes_dir() / "staircase.obj";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << file << " not found";
  Mesh mesh = load_mesh_file(file);
  rotate_mesh(mesh, Vec3(30.0f, 30.0f, 0.0f));
  expect_traversal_matches_brute_force(mesh, 14, 4, 300);
}

}  // namespace
}  // namespace bvhopt
