// Ray sets: deterministic in the seed on any thread count, sensible geometry per kind, and
// the ray file round trip with its error checks.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "bvhopt/build.h"
#include "bvhopt/error.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/ray_file.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/finalize.h"
#include "bvhopt/tracer.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

struct Scene {
  Mesh mesh;
  FlatBvh flat;
  Scene() : mesh(testing::random_mesh(3000, 21, true)) {
    const PrimitiveRefs refs = make_references(mesh);
    flat = flatten_for_tracing(build_bvh(refs), refs);
  }
};

bool same_rays(const std::vector<Ray>& a, const std::vector<Ray>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Ray)) == 0;
}

fs::path temp_path(const std::string& name) {
  return fs::temp_directory_path() / ("bvhopt_rays_" + std::to_string(::getpid()) + "_" + name);
}

TEST(RaySets, SameSeedSameRaysOnAnyThreadCount) {
  Scene s;
  const Tracer tracer(s.flat, s.mesh);
  for (RayKind kind : all_ray_kinds()) {
    RaySetConfig cfg;
    cfg.kind = kind;
    cfg.seed = 99;
    cfg.count = 5000;
    RaySet one, two, other;
    {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
      one = make_ray_set(s.mesh, tracer, cfg);
    }
    {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
      two = make_ray_set(s.mesh, tracer, cfg);
    }
    cfg.seed = 100;
    other = make_ray_set(s.mesh, tracer, cfg);
    EXPECT_TRUE(same_rays(one.rays, two.rays)) << ray_kind_name(kind);
    // Primary and shadow rays come from pixel centres only; the seed does not enter.
    if (kind != RayKind::primary && kind != RayKind::shadow) {
      EXPECT_FALSE(same_rays(one.rays, other.rays)) << ray_kind_name(kind);
    }
    EXPECT_EQ(one.rays.size(), kind == RayKind::primary ? one.rays.size() : 5000u) << ray_kind_name(kind);
    EXPECT_EQ(one.query, kind == RayKind::shadow ? RayQuery::any : RayQuery::closest);
  }
}

TEST(RaySets, KindsHaveTheirGeometry) {
  Scene s;
  const Tracer tracer(s.flat, s.mesh);
  Box box;
  for (size_t v = 0; v < s.mesh.vertex_count(); ++v) box.extend(s.mesh.vertex(v));
  const float diag = length(box.extent());

  RaySetConfig cfg;
  cfg.count = 4000;
  cfg.kind = RayKind::primary;
  const RaySet primary = make_ray_set(s.mesh, tracer, cfg);
  EXPECT_EQ(uint64_t(primary.width) * primary.height, primary.rays.size());
  EXPECT_NEAR(double(primary.rays.size()), 4000.0, 200.0);
  for (const Ray& r : primary.rays) EXPECT_NEAR(length(r.dir), 1.0f, 1e-5f);

  cfg.kind = RayKind::random;
  for (const Ray& r : make_ray_set(s.mesh, tracer, cfg).rays) {
    // Both ends inside the scene box (a tiny tolerance for rounding of org + dir).
    const Vec3 end = r.org + r.dir;
    const Vec3 tol(1e-3f);
    EXPECT_TRUE(Box(box.min - tol, box.max + tol).contains(r.org));
    EXPECT_TRUE(Box(box.min - tol, box.max + tol).contains(end));
    EXPECT_EQ(r.tmax, 1.0f);
  }

  cfg.kind = RayKind::ao;
  const RaySet ao = make_ray_set(s.mesh, tracer, cfg);
  ASSERT_EQ(ao.rays.size(), 4000u);
  for (size_t i = 0; i < ao.rays.size(); ++i) {
    const Ray& r = ao.rays[i];
    EXPECT_NEAR(length(r.dir), 1.0f, 1e-4f);
    EXPECT_NEAR(r.tmax, 0.1f * diag, 1e-3f * diag);
    // Ten rays per hit point, all from the same origin.
    if (i % 10 != 0) {
      EXPECT_EQ(r.org, ao.rays[i - i % 10].org);
    }
  }
  // Cosine distribution about the normal: the mean cosine to the mean direction of a
  // hemisphere sample is 2/3; check the rays of each hit point spread rather than repeat.
  EXPECT_NE(ao.rays[0].dir, ao.rays[1].dir);

  cfg.kind = RayKind::shadow;
  const RaySet shadow = make_ray_set(s.mesh, tracer, cfg);
  const Vec3 light = box.center() + Vec3(0.0f, 0.4f * box.extent().y, 0.0f);
  for (const Ray& r : shadow.rays) {
    const Vec3 end = r.org + r.dir;
    EXPECT_NEAR(length(end - light), 0.0f, 1e-3f * diag);
  }

  cfg.kind = RayKind::path;
  const RaySet path = make_ray_set(s.mesh, tracer, cfg);
  EXPECT_EQ(path.rays.size(), 4000u);
}

TEST(RaySets, InteriorCameraStandsInsideLookingAlongTheLongerAxis) {
  // A closed box room 20 x 4 x 8: the default camera must stand inside, looking along x.
  Mesh room;
  room.name = "room";
  const Vec3 lo(0, 0, 0), hi(20, 4, 8);
  for (int i = 0; i < 8; ++i) room.add_vertex({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  const uint32_t faces[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
  for (auto& f : faces) {
    room.add_triangle(f[0], f[1], f[2]);
    room.add_triangle(f[0], f[2], f[3]);
  }
  const PrimitiveRefs refs = make_references(room);
  const Tracer tracer(flatten_for_tracing(build_bvh(refs), refs), room);
  const Camera cam = default_camera(room, tracer);
  EXPECT_TRUE(Box(lo, hi).contains(cam.position));
  const Vec3 d = normalize(cam.target - cam.position);
  EXPECT_NEAR(std::fabs(d.x), 1.0f, 1e-6f);
  // Every primary ray from inside a closed room hits a wall.
  RaySetConfig cfg;
  cfg.count = 2000;
  const RaySet set = make_ray_set(room, tracer, cfg);
  for (const Ray& r : set.rays) {
    TraceCounters c;
    EXPECT_TRUE(tracer.any(r, c));
  }

  // An object seen from outside: the camera is outside its box.
  Scene s;
  const Tracer t2(s.flat, s.mesh);
  Box box;
  for (size_t v = 0; v < s.mesh.vertex_count(); ++v) box.extend(s.mesh.vertex(v));
  EXPECT_FALSE(box.contains(default_camera(s.mesh, t2).position));
}

// The built-in scene is an interior whose surfaces face inwards, so the default camera
// stands inside the hall, where its users' scenes put it, rather than framing it from outside.
TEST(RaySets, DefaultCameraStandsInsideTheBuiltinHall) {
  for (uint64_t seed : {1, 2}) {
    Mesh mesh = load_scene("builtin:atrium?triangles=60000&seed=" + std::to_string(seed));
    PrimitiveRefs refs = make_references(mesh);
    Bvh bvh = build_bvh(refs);
    Tracer tracer(finalize(bvh, refs), mesh);
    Camera cam = default_camera(mesh, tracer);
    Box bounds = describe(mesh).bounds;
    EXPECT_TRUE(bounds.contains(cam.position)) << "seed " << seed;
    EXPECT_LT(length(cam.position - bounds.center()), 1e-3f * length(bounds.extent())) << "seed " << seed;
    RaySetConfig config;
    config.kind = RayKind::primary;
    config.count = 20000;
    RaySet set = make_ray_set(mesh, tracer, config);
    size_t hits = 0;
    TraceCounters counters;
    for (const Ray& r : set.rays) hits += tracer.closest(r, counters).hit();
    EXPECT_EQ(hits, set.rays.size()) << "an enclosed hall: every primary ray hits something";
  }
}

TEST(RaySets, FileRoundTripIsExact) {
  Scene s;
  const Tracer tracer(s.flat, s.mesh);
  for (RayKind kind : all_ray_kinds()) {
    RaySetConfig cfg;
    cfg.kind = kind;
    cfg.count = 3000;
    cfg.seed = 4;
    const RaySet set = make_ray_set(s.mesh, tracer, cfg);
    const fs::path p = temp_path("roundtrip.rays");
    write_ray_file(p, set);
    const RaySet back = read_ray_file(p);
    EXPECT_EQ(back.kind, set.kind);
    EXPECT_EQ(back.query, set.query);
    EXPECT_EQ(back.seed, set.seed);
    EXPECT_EQ(back.width, set.width);
    EXPECT_EQ(back.height, set.height);
    EXPECT_TRUE(same_rays(back.rays, set.rays));
    EXPECT_EQ(fs::file_size(p), 64 + 32 * set.rays.size());
    fs::remove(p);
  }
}

std::string ray_read_error(const fs::path& p) {
  try {
    read_ray_file(p);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(RaySets, BadFilesAreRejectedWithClearMessages) {
  Scene s;
  const Tracer tracer(s.flat, s.mesh);
  RaySetConfig cfg;
  cfg.kind = RayKind::random;
  cfg.count = 100;
  const RaySet set = make_ray_set(s.mesh, tracer, cfg);
  const fs::path p = temp_path("bad.rays");
  write_ray_file(p, set);
  std::vector<char> good(fs::file_size(p));
  std::ifstream(p, std::ios::binary).read(good.data(), std::streamsize(good.size()));
  auto write_bytes = [&](const std::vector<char>& bytes) {
    std::ofstream(p, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
  };
  auto patched = [&](size_t offset, const void* data, size_t n) {
    std::vector<char> b = good;
    std::memcpy(b.data() + offset, data, n);
    return b;
  };

  EXPECT_NE(ray_read_error(temp_path("missing.rays")).find("cannot open"), std::string::npos);
  write_bytes(std::vector<char>(good.begin(), good.begin() + 20));
  EXPECT_NE(ray_read_error(p).find("too short"), std::string::npos);
  write_bytes(patched(0, "NOTRAYS!", 8));
  EXPECT_NE(ray_read_error(p).find("magic"), std::string::npos);
  const uint32_t v2 = 2;
  write_bytes(patched(8, &v2, 4));
  EXPECT_NE(ray_read_error(p).find("version 2"), std::string::npos);
  const uint32_t kind9 = 9;
  write_bytes(patched(12, &kind9, 4));
  EXPECT_NE(ray_read_error(p).find("unknown ray kind"), std::string::npos);
  write_bytes(std::vector<char>(good.begin(), good.end() - 5));
  EXPECT_NE(ray_read_error(p).find("truncated"), std::string::npos);
  std::vector<char> flipped = good;
  flipped[64 + 32 * 50 + 3] ^= 0x10;
  write_bytes(flipped);
  EXPECT_NE(ray_read_error(p).find("checksum"), std::string::npos);
  // A well-formed file (right checksum) holding an untraceable ray.
  RaySet bad = set;
  bad.rays[7].dir = Vec3(0.0f);
  write_ray_file(p, bad);
  EXPECT_NE(ray_read_error(p).find("ray 7"), std::string::npos);
  bad = set;
  bad.rays[8].org.x = std::nanf("");
  write_ray_file(p, bad);
  EXPECT_NE(ray_read_error(p).find("ray 8"), std::string::npos);
  // The good file still reads.
  write_bytes(good);
  EXPECT_EQ(ray_read_error(p), "");
  fs::remove(p);
  // Writing into a missing folder fails with the file named, leaving nothing behind.
  const fs::path nowhere = temp_path("no_such_dir") / "x.rays";
  EXPECT_THROW(write_ray_file(nowhere, set), Error);
}

}  // namespace
}  // namespace bvhopt

namespace bvhopt {
namespace {

// A scene whose bounds are one point has no segment between two distinct points of its box:
// random rays must say so, not draw pairs forever.
TEST(RaySets, RandomRaysOnAPointSizedSceneAreAnErrorNotAHang) {
  Mesh mesh;
  mesh.name = "point.obj";
  for (int i = 0; i < 3; ++i) mesh.add_vertex({5, 5, 5});
  mesh.add_triangle(0, 1, 2);
  const PrimitiveRefs refs = make_references(mesh);
  const FlatBvh flat = flatten_for_tracing(build_bvh(refs), refs);
  const Tracer tracer(flat, mesh);
  RaySetConfig cfg;
  cfg.kind = RayKind::random;
  cfg.count = 1;
  try {
    make_ray_set(mesh, tracer, cfg);
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("single point"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace bvhopt
