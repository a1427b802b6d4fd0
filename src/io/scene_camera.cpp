// Cameras stored in scene files, through assimp.
#include "io/scene_camera.h"

#include <cmath>
#include <numbers>

namespace bvhopt {
namespace {

Vec3 to_vec3(const aiVector3D& v) { return {float(v.x), float(v.y), float(v.z)}; }

// The node's transform to world space: its own, then each ancestor's.
aiMatrix4x4 world_transform(const aiNode* node) {
  aiMatrix4x4 world;
  for (const aiNode* n = node; n; n = n->mParent) world = n->mTransformation * world;
  return world;
}

}  // namespace

std::optional<Camera> scene_file_camera(const aiScene* scene, bool gltf) {
  for (unsigned i = 0; i < scene->mNumCameras; ++i) {
    const aiCamera* c = scene->mCameras[i];
    if (!c || c->mOrthographicWidth > 0.0f) continue;
    const aiNode* node = scene->mRootNode ? scene->mRootNode->FindNode(c->mName) : nullptr;
    const aiMatrix4x4 world = world_transform(node);
    const aiMatrix3x3 turn(world);
    Camera cam;
    cam.position = to_vec3(world * (gltf ? aiVector3D(0, 0, 0) : c->mPosition));
    const Vec3 look = to_vec3(turn * c->mLookAt);
    cam.up = to_vec3(turn * c->mUp);
    if (!is_finite(cam.position) || !is_finite(look) || !is_finite(cam.up) || !(length(look) > 0.0f)) continue;
    cam.target = cam.position + normalize(look);
    // assimp keeps the horizontal angle and the aspect ratio (width / height); the camera
    // here keeps the vertical one. Without an aspect ratio the angle is taken as vertical.
    const float horizontal = c->mHorizontalFOV;
    const float aspect = c->mAspect > 0.0f ? c->mAspect : 1.0f;
    const float vertical = gltf ? horizontal / aspect : 2.0f * std::atan(std::tan(0.5f * horizontal) / aspect);
    const float degrees = vertical * 180.0f / std::numbers::pi_v<float>;
    if (std::isfinite(degrees) && degrees > 0.0f && degrees < 180.0f) cam.fov_degrees = degrees;
    return cam;
  }
  return std::nullopt;
}

}  // namespace bvhopt
