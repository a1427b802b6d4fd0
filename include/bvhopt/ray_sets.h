// Ray sets for measuring trees, generated deterministically from a seed. The ray file that
// saves them so any tracer traces the very same rays is in bvhopt/ray_file.h (bvhopt::io).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bvhopt/camera.h"
#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/tracer.h"

namespace bvhopt {

enum class RayKind : uint32_t {
  primary = 0,  // pinhole camera, one ray per pixel centre, row-major from the top left
  random = 1,   // Bittner: segments between two uniform points of the scene box
  ao = 2,       // ambient occlusion: cosine-distributed rays about the normal at primary hits
  path = 3,     // Kensler: two-bounce diffuse path tracing (primary, first and second bounce)
  shadow = 4,   // from primary hits to a point light, any-hit
};

// "primary", "random", "ao", "path", "shadow".
std::string_view ray_kind_name(RayKind kind);
std::optional<RayKind> parse_ray_kind(std::string_view name);
std::vector<RayKind> all_ray_kinds();

// The default view of a scene, in this order:
// 1. The camera stored in the scene file (Mesh::camera: glTF, FBX, ...), at this resolution.
// 2. Interior: probe rays from a centre along the six axis directions and the eight
//    diagonals; when at least 12 of the 14 hit geometry, most of those hits are on front
//    faces (the centre is enclosed by walls facing it, not inside a closed solid whose back
//    faces it sees) and the median probe gets far enough toward the box boundary (room to
//    look), the camera stands there looking along the longer horizontal axis of the box
//    (toward +). Tried at the centre of the bounding box (30% of the way), then at the
//    centre of the geometry's box (see geometry_bounds; half way), so that a room inside a
//    huge ground plane is still seen from inside.
// 3. Exterior: the camera looks at the centre of the geometry's box along a horizontal
//    axis, from outside, at the distance where the box's height and width fill the image
//    with a 5% margin at the box's centre; of the four horizontal sides, the one whose
//    probe image (64x48) has the most hits, the +short axis first and hits above 90%
//    counting as equal (so the wide side fills the image).
// Up is +y (the convention of the shared scenes' formats) unless `up_axis` says otherwise.
Camera default_camera(const Mesh& mesh, const Tracer& tracer, uint32_t width = 1024, uint32_t height = 768,
                      int up_axis = 1);

// Where the geometry is, robust to a few huge triangles (a ground plane far larger than
// the room on it): per axis, the 1st to 99th percentile of the triangle centroids, by count.
// The bounding box for meshes of fewer than 100 triangles.
Box geometry_bounds(const Mesh& mesh);

// One primary ray per pixel centre, row-major from the top-left pixel; directions unit length.
std::vector<Ray> camera_rays(const Camera& camera);

// The most rays one set may hold (4 GiB of rays), and the most pixels of a camera image.
inline constexpr uint64_t kMaxRayCount = uint64_t(1) << 27;

struct RaySetConfig {
  RayKind kind = RayKind::primary;
  uint64_t seed = 1;
  // Rays wanted. 0: the camera's width * height for primary rays, 1,000,000 otherwise.
  // primary: the resolution is set to about this many pixels at the camera's aspect ratio.
  // ao, shadow, path: the camera resolution grows until the hits give at least this many
  // rays, and the set is cut to exactly `count`, in pixel order. The image grows to at most
  // 64 pixels per ray wanted (at least 1024x1024, at most kMaxRayCount pixels); a camera
  // whose hits give fewer rays even then is an Error naming the set, the count reached and
  // why. At most kMaxRayCount (larger is an Error).
  uint64_t count = 0;
  std::optional<Camera> camera;   // default: default_camera(..., width, height)
  uint32_t width = 1024;
  uint32_t height = 768;
  int up_axis = 1;                // for the default camera and the default light
  uint32_t ao_rays_per_hit = 10;  // N in Bittner's paper
  float ao_length_fraction = 0.1f;  // AO ray length as a fraction of the scene box diagonal
  // Point light of the shadow rays (default_light when not given). A point that is not
  // finite is an Error; one inside a closed mesh lights only what is inside with it.
  std::optional<Vec3> light;
  // The query the set is traced with. Default: any hit for shadow rays, closest hit for the
  // others. Any hit for AO rays traces them as a renderer's occlusion queries do.
  std::optional<RayQuery> query;
};

struct RaySet {
  RayKind kind = RayKind::primary;
  RayQuery query = RayQuery::closest;  // shadow rays: any; all others: closest
  uint64_t seed = 0;
  uint32_t width = 0, height = 0;      // primary rays: the image they make; others 0
  std::vector<Ray> rays;
};

// The query a ray set is traced with unless RaySetConfig::query says otherwise: any hit for
// shadow rays, closest hit for the others.
RayQuery default_query(RayKind kind);

// The shadow rays' light when none is given: above the centre of the scene's box by 40 % of
// its extent along the up axis (inside the box, so that interiors are lit from within).
Vec3 default_light(const Mesh& mesh, int up_axis = 1);

// Deterministic in the mesh and config only (the same rays on any thread count). The
// tracer is used to find the hits that ao, shadow and path rays start from.
RaySet make_ray_set(const Mesh& mesh, const Tracer& tracer, const RaySetConfig& config);

}  // namespace bvhopt

// Callers written before the ray file moved to bvhopt::io get its functions from here too;
// new code includes bvhopt/ray_file.h itself.
#include "bvhopt/ray_file.h"
