// Meshes and the built-in scene: describe, check_mesh, rotate_mesh, make_builtin_scene and
// load_scene's spec parsing, on hand-made meshes whose answers are known.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdlib>
#include <string>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/mesh.h"
#include "bvhopt/scene.h"
#include "bvhopt/scene_file.h"
#include "test_support.h"

namespace bvhopt {
namespace {

// Runs `f`, expecting an Error whose message contains every one of `parts`.
template <class F>
void expect_error(F&& f, const std::vector<std::string>& parts) {
  try {
    f();
    ADD_FAILURE() << "no Error thrown (expected one mentioning '" << parts.front() << "')";
  } catch (const Error& e) {
    const std::string msg = e.what();
    for (const auto& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
  }
}

// Two unit right triangles, one with two coincident corners, one with collinear corners.
Mesh hand_mesh() {
  Mesh m;
  m.name = "hand.obj";
  m.add_vertex({0, 0, 0});   // 0
  m.add_vertex({2, 0, 0});   // 1
  m.add_vertex({0, 2, 0});   // 2
  m.add_vertex({0, 0, 3});   // 3
  m.add_vertex({1, 0, 0});   // 4: between 0 and 1
  m.add_vertex({0, 0, 0});   // 5: same point as 0
  m.add_triangle(0, 1, 2);   // area 2
  m.add_triangle(0, 2, 3);   // area 3
  m.add_triangle(0, 5, 1);   // coincident corners
  m.add_triangle(0, 4, 1);   // collinear
  return m;
}

TEST(Describe, CountsBoundsAndDegenerates) {
  MeshInfo info = describe(hand_mesh());
  EXPECT_EQ(info.triangles, 4u);
  EXPECT_EQ(info.vertices, 6u);
  EXPECT_EQ(info.degenerate_triangles, 2u);
  EXPECT_EQ(info.coincident_triangles, 1u);
  EXPECT_EQ(info.bounds.min, Vec3(0, 0, 0));
  EXPECT_EQ(info.bounds.max, Vec3(2, 2, 3));
}

TEST(Describe, EmptyMesh) {
  MeshInfo info = describe(Mesh{});
  EXPECT_EQ(info.triangles, 0u);
  EXPECT_TRUE(info.bounds.is_empty());
}

TEST(CheckMesh, AcceptsDegenerateTriangles) { EXPECT_NO_THROW(check_mesh(hand_mesh())); }

TEST(CheckMesh, NoTriangles) {
  Mesh m;
  m.name = "empty.obj";
  m.add_vertex({0, 0, 0});
  expect_error([&] { check_mesh(m); }, {"empty.obj", "no triangles"});
}

TEST(CheckMesh, IndexOutOfRange) {
  Mesh m = hand_mesh();
  m.indices[3 * 2 + 1] = 900;
  expect_error([&] { check_mesh(m); }, {"hand.obj: triangle 2: vertex index 900 out of range (6 vertices)"});
}

TEST(CheckMesh, NaNAndInfiniteCoordinates) {
  Mesh m = hand_mesh();
  m.positions[3 * 3 + 1] = std::nanf("");
  expect_error([&] { check_mesh(m); }, {"hand.obj: vertex 3: coordinate y is NaN"});
  m = hand_mesh();
  m.positions[3 * 4 + 2] = -INFINITY;
  expect_error([&] { check_mesh(m); }, {"hand.obj: vertex 4: coordinate z is infinite"});
}

TEST(CheckMesh, RaggedArrays) {
  Mesh m = hand_mesh();
  m.indices.pop_back();
  expect_error([&] { check_mesh(m); }, {"hand.obj", "not a multiple of three"});
  m = hand_mesh();
  m.positions.push_back(1.0f);
  expect_error([&] { check_mesh(m); }, {"hand.obj", "not a multiple of three"});
}

// A box of corners c +- (1, 2, 3) plus a vertex at its centre c.
Mesh cuboid(const Vec3& c) {
  Mesh m;
  m.name = "cuboid";
  for (int i = 0; i < 8; ++i) m.add_vertex(c + Vec3(i & 1 ? 1.f : -1.f, i & 2 ? 2.f : -2.f, i & 4 ? 3.f : -3.f));
  m.add_vertex(c);
  m.add_triangle(0, 1, 2);
  m.add_triangle(8, 7, 6);
  return m;
}

void expect_near(const Vec3& a, const Vec3& b, float tol) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

TEST(RotateMesh, QuarterTurnsMapAxesExactly) {
  const Vec3 c(10, -20, 5);
  Mesh m = cuboid(c);
  rotate_mesh(m, {0, 0, 90});
  // About z: (x, y, z) -> (-y, x, z). Corner 7 is c + (1, 2, 3).
  EXPECT_EQ(m.vertex(7), c + Vec3(-2, 1, 3));
  EXPECT_EQ(m.vertex(8), c);

  m = cuboid(c);
  rotate_mesh(m, {90, 0, 0});  // about x: (x, y, z) -> (x, -z, y)
  EXPECT_EQ(m.vertex(7), c + Vec3(1, -3, 2));

  m = cuboid(c);
  rotate_mesh(m, {0, 90, 0});  // about y: (x, y, z) -> (z, y, -x)
  EXPECT_EQ(m.vertex(7), c + Vec3(3, 2, -1));

  // x first, then z: (1, 2, 3) -> (1, -3, 2) -> (3, 1, 2).
  m = cuboid(c);
  rotate_mesh(m, {90, 0, 90});
  EXPECT_EQ(m.vertex(7), c + Vec3(3, 1, 2));

  m = cuboid(c);
  rotate_mesh(m, {360, -720, 0});
  EXPECT_EQ(m.positions, cuboid(c).positions);
}

TEST(RotateMesh, KeepsCentreAndEdgeLengths) {
  const Vec3 c(3, 4, -5);
  Mesh m = cuboid(c);
  rotate_mesh(m, {37, -81, 142});
  expect_near(m.vertex(8), c, 1e-5f);
  // The centre of the box is the centre of the rotation, so it stays for any mesh.
  Mesh r = testing::random_mesh(500, 11);
  Mesh original = r;
  rotate_mesh(r, {12.5f, 200, -33});
  ASSERT_EQ(r.triangle_count(), original.triangle_count());
  // Each rotated coordinate is rounded to float once, so an edge length may move by a few
  // ulps of the coordinates (not of the edge): the bound is relative to the largest one.
  float largest = 0;
  for (float x : r.positions) largest = std::max(largest, std::fabs(x));
  const double allowed = 8.0 * std::numeric_limits<float>::epsilon() * largest;
  double worst = 0;
  for (size_t t = 0; t < r.triangle_count(); ++t) {
    Triangle a = original.triangle(t), b = r.triangle(t);
    const float la[3] = {length(a.v1 - a.v0), length(a.v2 - a.v1), length(a.v0 - a.v2)};
    const float lb[3] = {length(b.v1 - b.v0), length(b.v2 - b.v1), length(b.v0 - b.v2)};
    for (int k = 0; k < 3; ++k) worst = std::max(worst, std::fabs(double(la[k]) - lb[k]) / allowed);
  }
  EXPECT_LT(worst, 1.0);
  // Rotating back (z, y, x in reverse, negated) restores the vertices.
  rotate_mesh(r, {0, 0, 33});
  rotate_mesh(r, {0, -200, 0});
  rotate_mesh(r, {-12.5f, 0, 0});
  // Each turn is about the current box centre, which moves, so compare shapes: every
  // vertex's offset from vertex 0.
  for (size_t v = 1; v < r.vertex_count(); v += 37)
    expect_near(r.vertex(v) - r.vertex(0), original.vertex(v) - original.vertex(0), 2e-3f);
}

TEST(BuiltinScene, DeterministicInSeed) {
  BuiltinSceneConfig a{.seed = 7, .target_triangles = 20'000};
  Mesh m1 = make_builtin_scene(a), m2 = make_builtin_scene(a);
  EXPECT_EQ(m1.positions, m2.positions);
  EXPECT_EQ(m1.indices, m2.indices);
  BuiltinSceneConfig b = a;
  b.seed = 8;
  Mesh m3 = make_builtin_scene(b);
  EXPECT_NE(m1.positions, m3.positions);
}

// The size lands on the target at every size the generator is meant for, the
// mesh is valid and free of degenerate triangles, and large and tiny triangles sit side by
// side: the largest is more than 1000 times the median.
class BuiltinSize : public ::testing::TestWithParam<uint64_t> {};

TEST_P(BuiltinSize, NearTargetValidAndMixed) {
  const uint64_t target = GetParam();
  Mesh m = make_builtin_scene({.seed = 3, .target_triangles = target});
  // Above the bare architecture (about 3.5k triangles) the count is met exactly.
  EXPECT_EQ(m.triangle_count(), target);
  ASSERT_NO_THROW(check_mesh(m));
  MeshInfo info = describe(m);
  EXPECT_EQ(info.degenerate_triangles, 0u);
  std::vector<float> areas(m.triangle_count());
  size_t thin_off_axis = 0;
  for (size_t t = 0; t < areas.size(); ++t) {
    Triangle tri = m.triangle(t);
    areas[t] = tri.area();
    // A long thin triangle whose longest edge follows no axis: a rotated slab's face.
    Vec3 e[3] = {tri.v1 - tri.v0, tri.v2 - tri.v1, tri.v0 - tri.v2};
    int longest = 0;
    for (int k = 1; k < 3; ++k)
      if (length(e[k]) > length(e[longest])) longest = k;
    Vec3 d = e[longest] / length(e[longest]);
    bool off_axis = std::fabs(d.x) < 0.95f && std::fabs(d.y) < 0.95f && std::fabs(d.z) < 0.95f;
    if (off_axis && length(e[longest]) > 2.5f && areas[t] < 0.25f * length(e[longest])) ++thin_off_axis;
  }
  std::nth_element(areas.begin(), areas.begin() + areas.size() / 2, areas.end());
  const float median = areas[areas.size() / 2];
  const float largest = *std::max_element(areas.begin(), areas.end());
  EXPECT_GT(largest / median, 1000.0f) << "largest " << largest << " median " << median;
  EXPECT_GT(thin_off_axis, 100u);  // 8 faces of each of the (20+) slabs
  // The hall stands on the floor (y = 0) and nothing pokes through it.
  EXPECT_GE(info.bounds.min.y, 0.0f);
}

INSTANTIATE_TEST_SUITE_P(Sizes, BuiltinSize, ::testing::Values(20'000, 60'000, 250'000));

TEST(BuiltinScene, ExactCountOverManySizesAndSeeds) {
  // Odd targets and several seeds: the furniture stops short and the fallen leaves fill
  // the gap, whatever mix of objects the seed drew.
  for (uint64_t target : {4'500, 7'777, 12'345, 33'333, 99'999, 123'457, 400'000, 1'000'003})
    for (uint64_t seed = 1; seed <= 3; ++seed)
      EXPECT_EQ(make_builtin_scene({.seed = seed, .target_triangles = target}).triangle_count(), target)
          << "target " << target << " seed " << seed;
}

TEST(BuiltinScene, NothingBelowTheFloorForAnySeed) {
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    MeshInfo info = describe(make_builtin_scene({.seed = seed, .target_triangles = 60'000}));
    EXPECT_GE(info.bounds.min.y, 0.0f) << "seed " << seed;
    EXPECT_LE(info.bounds.max.y, 22.5f) << "seed " << seed;  // the crown of the vault
  }
}

// The size the issue asks for. Not timed (bench/ measures speed); it shows that the count
// is met and the mesh is valid at 10M. Skipped under BVHOPT_SKIP_LARGE=1 (sanitizer runs).
TEST(BuiltinScene, ReachesTenMillion) {
  if (const char* env = std::getenv("BVHOPT_SKIP_LARGE"); env && std::string(env) == "1")
    GTEST_SKIP() << "BVHOPT_SKIP_LARGE=1";
  Mesh m = make_builtin_scene({.seed = 2, .target_triangles = 10'000'000});
  EXPECT_EQ(m.triangle_count(), 10'000'000u);
  // Sized exactly up front: no slack left from growing vectors.
  EXPECT_EQ(m.indices.capacity(), m.indices.size());
  EXPECT_EQ(m.positions.capacity(), m.positions.size());
  EXPECT_NO_THROW(check_mesh(m));
  EXPECT_EQ(describe(m).degenerate_triangles, 0u);
}

TEST(BuiltinScene, SmallTargetsStillGiveTheWholeHall) {
  // Below the bare architecture the target cannot be met; the hall is still complete.
  Mesh m = make_builtin_scene({.seed = 1, .target_triangles = 10});
  EXPECT_GT(m.triangle_count(), 1000u);
  EXPECT_NO_THROW(check_mesh(m));
}

TEST(LoadScene, BuiltinSpecs) {
  Mesh a = load_scene("builtin?triangles=20000");
  Mesh b = load_scene("builtin:atrium?triangles=20000&seed=1");
  Mesh c = load_scene("builtin:atrium?seed=2&triangles=20000");
  EXPECT_EQ(a.name, "builtin?triangles=20000");
  EXPECT_EQ(a.positions, b.positions);  // seed 1 is the default
  EXPECT_EQ(a.indices, b.indices);
  EXPECT_NE(a.positions, c.positions);
  EXPECT_EQ(c.triangle_count(), 20000u);
  Mesh d = load_scene("builtin");
  EXPECT_NEAR(double(d.triangle_count()), 250000.0, 5000.0);
  EXPECT_EQ(d.name, "builtin");
}

TEST(LoadScene, BadSpecs) {
  expect_error([] { load_scene("builtin:cathedral"); }, {"builtin:cathedral", "unknown built-in scene 'cathedral'"});
  expect_error([] { load_scene("builtin?tris=5"); }, {"builtin?tris=5", "unknown option 'tris'"});
  expect_error([] { load_scene("builtin?triangles="); }, {"builtin?triangles=", "'triangles'", "not a"});
  expect_error([] { load_scene("builtin?triangles=12x"); }, {"'12x' is not a non-negative integer"});
  expect_error([] { load_scene("builtin?triangles=-5"); }, {"'-5' is not a non-negative integer"});
  expect_error([] { load_scene("builtin?triangles=0"); }, {"out of range"});
  expect_error([] { load_scene("builtin?triangles=99999999999999999999999"); }, {"not a non-negative integer"});
  expect_error([] { load_scene("builtin?seed=1&seed=2"); }, {"'seed' given twice"});
  expect_error([] { load_scene("builtin?seed"); }, {"'seed' has no value"});
  expect_error([] { load_scene("builtin?"); }, {"nothing after '?'"});
  expect_error([] { load_scene(""); }, {"empty name"});
  // Not the generator: a file that happens to start with "builtin".
  expect_error([] { load_scene("builtin_hall.obj"); }, {"builtin_hall.obj", "no such file"});
}

}  // namespace
}  // namespace bvhopt
