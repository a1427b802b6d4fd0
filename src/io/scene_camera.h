// The camera a scene file stores (glTF, FBX, Collada, ...), for Mesh::camera.
#pragma once

#include <assimp/scene.h>

#include <optional>

#include "bvhopt/camera.h"

namespace bvhopt {

// The first perspective camera of the scene as assimp reads it, before post-processing,
// placed in world space by the transforms of its node and the node's ancestors (the same
// transforms aiProcess_PreTransformVertices applies to the meshes). Cameras with a zero or
// non-finite direction, and orthographic ones, are skipped. `gltf`: the file is glTF, whose
// reader (assimp 5.2) copies the node's translation into the camera's position, which the
// node transform then moves again, and keeps yfov * aspect as the horizontal angle; a glTF
// camera stands at its node's origin, and the vertical angle is read back exactly.
std::optional<Camera> scene_file_camera(const aiScene* scene, bool gltf);

}  // namespace bvhopt
