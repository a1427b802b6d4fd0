// Scene files read through assimp, and scene specs that may name a file (bvhopt::io).
#pragma once

#include <filesystem>
#include <string>

#include "bvhopt/mesh.h"
#include "bvhopt/scene.h"

namespace bvhopt {

// Reads any format assimp reads (OBJ, PLY, glTF/GLB, FBX, ...): polygons are triangulated,
// node transforms applied (instances flattened) and all meshes merged into one list, in
// the order assimp gives them. Throws Error for a missing file, an unknown or corrupt
// format, an empty scene, or bad numbers (see check_mesh).
Mesh load_mesh_file(const std::filesystem::path& path);

// A scene by name, as the command line takes it: the built-in scene when
// is_builtin_scene_spec(spec) (see load_builtin_scene), else a file. Throws Error for an
// empty name and whatever the two loaders throw.
Mesh load_scene(const std::string& spec);

}  // namespace bvhopt
