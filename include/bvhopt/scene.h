// Scenes: the procedural built-in scene (bvhopt::core). Files are read through assimp by
// bvhopt/scene_file.h (bvhopt::io).
#pragma once

#include <cstdint>
#include <string>

#include "bvhopt/mesh.h"

namespace bvhopt {

// The built-in scene: an architectural interior (walls, floors, vaults, stairs, columns,
// chairs, tables, plants, long thin slabs rotated off the axes). Deterministic in `seed`;
// the triangle count comes close to `target_triangles` (within a few percent).
struct BuiltinSceneConfig {
  uint64_t seed = 1;
  uint64_t target_triangles = 250'000;
};
Mesh make_builtin_scene(const BuiltinSceneConfig& config = {});

// The fewest triangles the built-in scene has with this seed: its architecture alone (walls,
// vaults, stairs, slabs), with no furniture. A smaller target cannot be met.
uint64_t min_builtin_scene_triangles(uint64_t seed);

// Whether `spec` names the built-in scene: "builtin" followed by nothing, ':' or '?'
// (anything else, say a file called builtin.obj, is a path).
bool is_builtin_scene_spec(const std::string& spec);

// Above this the 32-bit vertex indices of a Mesh run out (about four vertices a triangle
// is the worst the generator uses) and memory is far beyond this tool's machines.
inline constexpr uint64_t kMaxBuiltinTriangles = 500'000'000;

// The config a built-in scene spec names (see load_builtin_scene), without generating it.
// Throws Error as load_builtin_scene does.
BuiltinSceneConfig parse_builtin_scene_spec(const std::string& spec);

// The built-in scene by name, as the command line takes it:
//   "builtin" or "builtin:atrium"              default size
//   "builtin:atrium?triangles=1000000&seed=7"  with options
// Throws Error for an unknown scene or option, or a bad number.
Mesh load_builtin_scene(const std::string& spec);

}  // namespace bvhopt

// Callers written before file loading moved to bvhopt::io get load_scene and load_mesh_file
// from here too; new code includes bvhopt/scene_file.h itself.
#include "bvhopt/scene_file.h"
