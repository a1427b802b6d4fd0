// Scenes: files read through assimp, or the procedural built-in scene.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "bvhopt/mesh.h"

namespace bvhopt {

// Reads any format assimp reads (OBJ, PLY, glTF/GLB, FBX, ...): polygons are triangulated,
// node transforms applied (instances flattened) and all meshes merged into one list, in
// the order assimp gives them. Throws Error for a missing file, an unknown or corrupt
// format, an empty scene, or bad numbers (see check_mesh).
Mesh load_mesh_file(const std::filesystem::path& path);

// The built-in scene: an architectural interior (walls, floors, vaults, stairs, columns,
// chairs, tables, plants, long thin slabs rotated off the axes). Deterministic in `seed`;
// the triangle count comes close to `target_triangles` (within a few percent).
struct BuiltinSceneConfig {
  uint64_t seed = 1;
  uint64_t target_triangles = 250'000;
};
Mesh make_builtin_scene(const BuiltinSceneConfig& config = {});

// A scene by name, as the command line takes it:
//   "path/to/file.obj"                       a file
//   "builtin" or "builtin:atrium"            the built-in scene, default size
//   "builtin:atrium?triangles=1000000&seed=7"  with options
// Throws Error for anything else.
Mesh load_scene(const std::string& spec);

}  // namespace bvhopt
