// The default camera sees the scene: a camera stored in a glTF file is used as it is; a room
// on a ground plane far larger than itself is seen from inside; every shared interior
// scene gets at least half its primary rays on geometry and every scanned model fills a
// fair part of the frame (the shared scenes' tests skip without the folder).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bvhopt/build.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/references.h"
#include "bvhopt/scene_file.h"
#include "bvhopt/testing/flatten_for_tracing.h"
#include "test_support.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

std::string base64(const std::vector<uint8_t>& bytes) {
  static constexpr char digits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const uint32_t n = uint32_t(bytes[i]) << 16 | (i + 1 < bytes.size() ? uint32_t(bytes[i + 1]) << 8 : 0) |
                       (i + 2 < bytes.size() ? uint32_t(bytes[i + 2]) : 0);
    out += digits[(n >> 18) & 63];
    out += digits[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? digits[(n >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? digits[n & 63] : '=';
  }
  return out;
}

// A glTF file with a 10x10 wall in the plane x = -10 and a perspective camera (yfov 0.8
// rad) on a node at (3, 1, 0) turned 90 degrees about +y, so that it looks along -x at the
// wall (glTF cameras look along their node's -z).
fs::path write_gltf_with_camera(const fs::path& dir) {
  const float wall[6][3] = {{-10, -5, -5}, {-10, -5, 5}, {-10, 5, 5}, {-10, -5, -5}, {-10, 5, 5}, {-10, 5, -5}};
  std::vector<uint8_t> bytes(sizeof wall);
  std::memcpy(bytes.data(), wall, sizeof wall);
  const std::string gltf = R"({
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0, 1]}],
  "nodes": [
    {"mesh": 0},
    {"camera": 0, "translation": [3, 1, 0], "rotation": [0, 0.70710678, 0, 0.70710678]}
  ],
  "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.01, "zfar": 100}}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
  "buffers": [{"byteLength": 72, "uri": "data:application/octet-stream;base64,)" +
                           base64(bytes) + R"("}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 72}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 6, "type": "VEC3",
                 "min": [-10, -5, -5], "max": [-10, 5, 5]}]
})";
  const fs::path path = dir / "camera.gltf";
  std::ofstream(path) << gltf;
  return path;
}

double hit_fraction(const Mesh& mesh, const Tracer& tracer, uint64_t count = 20000) {
  RaySetConfig config;
  config.count = count;
  const RaySet set = make_ray_set(mesh, tracer, config);
  size_t hits = 0;
  TraceCounters counters;
  for (const Ray& r : set.rays) hits += tracer.closest(r, counters).hit();
  return double(hits) / double(set.rays.size());
}

struct Traced {
  Mesh mesh;
  PrimitiveRefs refs;
  Tracer tracer;
  explicit Traced(Mesh m)
      : mesh(std::move(m)), refs(make_references(mesh)), tracer(flatten_for_tracing(build_bvh(refs), refs), mesh) {}
};

TEST(DefaultCamera, UsesTheCameraOfAGltfFile) {
  const fs::path dir = fs::temp_directory_path() / ("bvhopt_camera_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  Mesh mesh = load_mesh_file(write_gltf_with_camera(dir));
  fs::remove_all(dir);
  ASSERT_TRUE(mesh.camera.has_value());
  EXPECT_NEAR(mesh.camera->position.x, 3.0f, 1e-4f);
  EXPECT_NEAR(mesh.camera->position.y, 1.0f, 1e-4f);
  EXPECT_NEAR(mesh.camera->position.z, 0.0f, 1e-4f);
  const Vec3 look = normalize(mesh.camera->target - mesh.camera->position);
  EXPECT_NEAR(look.x, -1.0f, 1e-4f);
  EXPECT_NEAR(mesh.camera->up.y, 1.0f, 1e-4f);
  EXPECT_NEAR(mesh.camera->fov_degrees, 0.8 * 180.0 / 3.14159265358979, 0.05);

  const Traced t(mesh);
  const Camera cam = default_camera(t.mesh, t.tracer, 320, 200);
  EXPECT_EQ(cam.position, mesh.camera->position);
  EXPECT_EQ(cam.target, mesh.camera->target);
  EXPECT_EQ(cam.width, 320u);
  EXPECT_EQ(cam.height, 200u);
  // The wall fills the middle of its view.
  TraceCounters counters;
  Ray centre;
  centre.org = cam.position;
  centre.dir = normalize(cam.target - cam.position);
  EXPECT_TRUE(t.tracer.closest(centre, counters).hit());

  // Turning the scene turns its camera with it.
  Mesh turned = mesh;
  rotate_mesh(turned, Vec3(0.0f, 90.0f, 0.0f));
  const Vec3 turned_look = normalize(turned.camera->target - turned.camera->position);
  EXPECT_NEAR(turned_look.z, 1.0f, 1e-4f);  // -x turned 90 degrees about +y is +z
  const Traced tt(turned);
  Ray r;
  r.org = turned.camera->position;
  r.dir = turned_look;
  EXPECT_TRUE(tt.tracer.closest(r, counters).hit());
}

// A closed room (10 x 3 x 6, walls subdivided into many triangles) on a ground plane 1000
// units wide: the bounding box is the plane's, but the camera belongs in the room.
TEST(DefaultCamera, SeesARoomOnAHugeGroundPlane) {
  Mesh mesh;
  mesh.name = "room on a plane";
  const Vec3 lo(0.0f, 0.0f, 0.0f), hi(10.0f, 3.0f, 6.0f);
  const int n = 6;  // quads per wall edge
  const Vec3 centre = (lo + hi) * 0.5f;
  auto quad = [&](Vec3 o, Vec3 u, Vec3 v) {
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const Vec3 p = o + u * (float(i) / n) + v * (float(j) / n);
        const Vec3 du = u * (1.0f / n), dv = v * (1.0f / n);
        const uint32_t b = uint32_t(mesh.vertex_count());
        mesh.add_vertex(p);
        mesh.add_vertex(p + du);
        mesh.add_vertex(p + du + dv);
        mesh.add_vertex(p + dv);
        // Facing into the room, as the walls of architectural models do.
        const bool inward = dot(cross(du, dv), centre - p) > 0.0f;
        mesh.add_triangle(b, inward ? b + 1 : b + 3, b + 2);
        mesh.add_triangle(b, b + 2, inward ? b + 3 : b + 1);
      }
  };
  const Vec3 ex(hi.x, 0, 0), ey(0, hi.y, 0), ez(0, 0, hi.z);
  quad(lo, ex, ez);       // floor
  quad(ey, ez, ex);       // ceiling
  quad(lo, ey, ex);       // z = 0
  quad(ez, ex, ey);       // z = 6
  quad(lo, ez, ey);       // x = 0
  quad(ex, ey, ez);       // x = 10
  const uint32_t b = uint32_t(mesh.vertex_count());
  for (Vec3 p : {Vec3(-500, -0.1f, -500), Vec3(500, -0.1f, -500), Vec3(500, -0.1f, 500), Vec3(-500, -0.1f, 500)})
    mesh.add_vertex(p);
  mesh.add_triangle(b, b + 2, b + 1);
  mesh.add_triangle(b, b + 3, b + 2);

  const Box geometry = geometry_bounds(mesh);
  EXPECT_LE(geometry.extent().x, 10.5f);
  EXPECT_LE(geometry.extent().z, 6.5f);
  const Traced t(mesh);
  const Camera cam = default_camera(t.mesh, t.tracer);
  EXPECT_TRUE(Box(lo, hi).contains(cam.position));
  EXPECT_GE(hit_fraction(t.mesh, t.tracer), 0.99);
}

// Kind of each shared scene by MANIFEST.tsv: architectural scenes are interiors.
TEST(DefaultCamera, SharedScenesAreSeen) {
  if (!fs::is_directory(testing::scenes_dir())) GTEST_SKIP() << "no shared scenes at " << testing::scenes_dir();
  const auto rows = testing::read_manifest(testing::scenes_dir() / "MANIFEST.tsv");
  int checked = 0;
  for (const testing::ManifestRow& row : rows) {
    if (testing::skip_large_scenes() && row.triangles > 100'000) continue;
    const double wanted = row.kind == "architectural" ? 0.5 : row.kind == "scanned" ? 0.2 : 0.0;
    if (wanted == 0.0) continue;
    const Traced t(load_scene((testing::scenes_dir() / row.file).string()));
    const double hits = hit_fraction(t.mesh, t.tracer);
    EXPECT_GE(hits, wanted) << row.file << " (" << row.kind << ")";
    ++checked;
  }
  EXPECT_GE(checked, testing::skip_large_scenes() ? 1 : 8);
}

}  // namespace
}  // namespace bvhopt
