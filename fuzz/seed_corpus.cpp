// Writes the fuzzers' seed corpora: small valid files of every kind the readers take,
// made by the library's own writers, so the corpora follow the formats as they change.
// Usage: fuzz_seed_corpus DIR  (creates DIR/bvh_file, DIR/ray_file, DIR/scene_file,
// DIR/builtin_spec; the pipeline fuzzer starts from nothing).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "bvhopt/build.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/ray_file.h"
#include "bvhopt/references.h"

namespace fs = std::filesystem;

namespace {

void write_text(const fs::path& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

// Scene files get the fuzzer's leading format byte: 0 .obj, 1 .ply, 2 .gltf, 3 .glb.
void write_scene(const fs::path& dir, const std::string& name, char format, const std::string& text) {
  write_text(dir / name, std::string(1, format) + text);
}

const char* const kObj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nf 1 2 3\nf 2 3 4\n";
const char* const kPlyAscii =
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n1 0 0\n0 1 0\n1 1 1\n3 0 1 2\n3 1 2 3\n";
// One triangle, the buffer inline as base64 (three float positions, then three uint16 indices).
const char* const kGltf =
    R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
    R"("meshes":[{"primitives":[{"attributes":{"POSITION":1},"indices":0}]}],)"
    R"("buffers":[{"uri":"data:application/octet-stream;base64,AAABAAIAAAAAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAAAAAACAPwAAAAA=","byteLength":44}],)"
    R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":6,"target":34963},)"
    R"({"buffer":0,"byteOffset":8,"byteLength":36,"target":34962}],)"
    R"("accessors":[{"bufferView":0,"byteOffset":0,"componentType":5123,"count":3,"type":"SCALAR","max":[2],"min":[0]},)"
    R"({"bufferView":1,"byteOffset":0,"componentType":5126,"count":3,"type":"VEC3","max":[1,1,0],"min":[0,0,0]}]})";

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 2;
  }
  const fs::path root = argv[1];
  for (const char* sub : {"bvh_file", "ray_file", "scene_file", "builtin_spec", "pipeline"})
    fs::create_directories(root / sub);

  // A handful of triangles: small seeds keep the readers' executions fast.
  bvhopt::Mesh mesh;
  mesh.name = "seed";
  for (int i = 0; i < 8; ++i) {
    const float x = float(i % 3), y = float(i / 3), z = float(i % 2);
    mesh.add_vertex({x, y, z});
    mesh.add_vertex({x + 1, y, z});
    mesh.add_vertex({x, y + 1, z + 0.5f});
    mesh.add_triangle(3 * i, 3 * i + 1, 3 * i + 2);
  }
  const std::string spec = mesh.name;
  const bvhopt::PrimitiveRefs refs = bvhopt::make_references(mesh);
  for (uint32_t leaf : {1u, 4u}) {
    bvhopt::BuildOptions options;
    options.leaf.max_leaf_size = leaf;
    bvhopt::BvhFileInfo info;
    info.scene_name = spec;
    info.scene_triangles = mesh.triangle_count();
    info.method = "sweep";
    bvhopt::write_bvh_file(root / "bvh_file" / ("leaf" + std::to_string(leaf) + ".bvh"),
                           bvhopt::build_bvh(refs, options), refs, info);
  }

  bvhopt::RaySet rays;
  rays.kind = bvhopt::RayKind::primary;
  rays.width = 2;
  rays.height = 2;
  for (int i = 0; i < 4; ++i) rays.rays.push_back(bvhopt::Ray{{float(i), 0, -5}, 0.0f, {0, 0, 1}, 100.0f});
  bvhopt::write_ray_file(root / "ray_file" / "primary4.rays", rays);

  write_scene(root / "scene_file", "quad.obj", 0, kObj);
  write_scene(root / "scene_file", "quad.ply", 1, kPlyAscii);
  write_scene(root / "scene_file", "triangle.gltf", 2, kGltf);

  for (const char* s : {"builtin", "builtin:atrium", "builtin?triangles=100", "builtin:atrium?triangles=500&seed=7",
                        "builtin?seed=18446744073709551615&triangles=1"})
    write_text(root / "builtin_spec" / (std::to_string(std::hash<std::string>{}(s))), s);
  return 0;
}
