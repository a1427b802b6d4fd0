// Ray set generation (the ray file is in src/io/ray_file.cpp).
#include "bvhopt/ray_sets.h"


#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "bvhopt/error.h"
#include "bvhopt/random_stream.h"

namespace bvhopt {
namespace {

// splitmix64: one independent stream per (seed, pixel), so generation in parallel blocks
// gives the same rays as a serial loop.
struct Rng : RandomStream {
  Rng(uint64_t seed, uint64_t stream) : RandomStream{seed * kGoldenGamma ^ (stream + 0x632BE59BD9B4E019ull)} {
    next();
    next();
  }
  float uniform() { return uniform_float(); }  // [0, 1)
};

// Unit geometric normal of the hit triangle, turned toward the side the ray came from.
// Returns false for triangles too thin to have a usable normal.
bool facing_normal(const Triangle& tri, const Vec3& dir, Vec3& n) {
  const Vec3 c = cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
  const float len = length(c);
  if (!(len > 0.0f) || !std::isfinite(len)) return false;
  n = c / len;
  if (dot(n, dir) > 0.0f) n = -n;
  return true;
}

Vec3 hit_point(const Triangle& tri, const Hit& h) {
  return tri.v0 * (1.0f - h.u - h.v) + tri.v1 * h.u + tri.v2 * h.v;
}

// Cosine-weighted direction about unit n.
Vec3 cosine_direction(const Vec3& n, Rng& rng) {
  const Vec3 helper = std::fabs(n.x) > 0.5f ? Vec3(0.0f, 1.0f, 0.0f) : Vec3(1.0f, 0.0f, 0.0f);
  const Vec3 t = normalize(cross(helper, n));
  const Vec3 b = cross(n, t);
  const float r1 = rng.uniform(), r2 = rng.uniform();
  const float phi = 2.0f * std::numbers::pi_v<float> * r1;
  const float r = std::sqrt(r2);
  const float z = std::sqrt(std::max(0.0f, 1.0f - r2));
  return normalize(t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + n * z);
}

// The camera at about `pixels` pixels, its aspect kept; never more than a ray set may hold
// (rounded to the nearest, 13379x10032 overshot that limit, and the secondary sets, growing
// their image to it, failed with the camera's error instead of their own).
Camera with_pixels(Camera cam, double pixels) {
  const double aspect = double(cam.width) / double(std::max<uint32_t>(cam.height, 1));
  const double h = std::max(1.0, std::round(std::sqrt(pixels / aspect)));
  double w = std::max(1.0, std::round(pixels / h));
  if (w * h > double(kMaxRayCount)) w = std::max(1.0, std::floor(double(kMaxRayCount) / h));
  cam.width = static_cast<uint32_t>(std::min(w, 1e5));
  cam.height = static_cast<uint32_t>(std::min(h, 1e5));
  return cam;
}

}  // namespace

std::string_view ray_kind_name(RayKind kind) {
  switch (kind) {
    case RayKind::primary: return "primary";
    case RayKind::random: return "random";
    case RayKind::ao: return "ao";
    case RayKind::path: return "path";
    case RayKind::shadow: return "shadow";
  }
  return "unknown";
}

std::optional<RayKind> parse_ray_kind(std::string_view name) {
  for (RayKind k : all_ray_kinds())
    if (ray_kind_name(k) == name) return k;
  return std::nullopt;
}

std::vector<RayKind> all_ray_kinds() {
  return {RayKind::primary, RayKind::random, RayKind::ao, RayKind::path, RayKind::shadow};
}

namespace {

// The pinhole camera's ray through pixel (x, y), one pixel at a time, so that a large image
// need not be held as rays.
class CameraBasis {
 public:
  explicit CameraBasis(const Camera& cam);
  Ray ray(uint64_t pixel) const {
    const uint32_t x = static_cast<uint32_t>(pixel % cam_.width), y = static_cast<uint32_t>(pixel / cam_.width);
    const float sx = (2.0f * (x + 0.5f) / cam_.width - 1.0f) * tan_half_ * aspect_;
    const float sy = (1.0f - 2.0f * (y + 0.5f) / cam_.height) * tan_half_;
    Ray r;
    r.org = cam_.position;
    r.dir = normalize(forward_ + right_ * sx + up_ * sy);
    return r;
  }
  uint64_t pixels() const { return uint64_t(cam_.width) * cam_.height; }

 private:
  Camera cam_;
  Vec3 forward_, right_, up_;
  float tan_half_ = 0.0f, aspect_ = 1.0f;
};

CameraBasis::CameraBasis(const Camera& cam) : cam_(cam) {
  const Vec3 forward_raw = cam.target - cam.position;
  if (!(length(forward_raw) > 0.0f) || !is_finite(forward_raw))
    throw Error("camera: position and target must differ and be finite");
  const Vec3 forward = normalize(forward_raw);
  Vec3 right = cross(forward, cam.up);
  if (!(length(right) > 1e-6f)) {
    // Looking straight along `up`: any perpendicular will do.
    right = cross(forward, std::fabs(forward.x) < 0.9f ? Vec3(1, 0, 0) : Vec3(0, 1, 0));
  }
  right_ = normalize(right);
  forward_ = forward;
  up_ = cross(right_, forward);
  if (cam.width == 0 || cam.height == 0) throw Error("camera: resolution must be at least 1x1");
  if (uint64_t(cam.width) * cam.height > kMaxRayCount)
    throw Error("camera: resolution " + std::to_string(cam.width) + "x" + std::to_string(cam.height) + " has more than " +
                std::to_string(kMaxRayCount) + " pixels (the most rays a set may hold)");
  if (!(cam.fov_degrees > 0.0f && cam.fov_degrees < 180.0f))
    throw Error("camera: field of view " + std::to_string(cam.fov_degrees) + " not in (0, 180) degrees");
  tan_half_ = std::tan(0.5f * cam.fov_degrees * std::numbers::pi_v<float> / 180.0f);
  aspect_ = float(cam.width) / float(cam.height);
}

}  // namespace

std::vector<Ray> camera_rays(const Camera& cam) {
  const CameraBasis basis(cam);
  std::vector<Ray> rays(basis.pixels());
  for (uint64_t p = 0; p < rays.size(); ++p) rays[p] = basis.ray(p);
  return rays;
}

namespace {

// Segments between two uniform points of the box.
// A box whose extent rounds away can give the same point twice; a pair is redrawn at most
// this many times, which only a box of (nearly) one point ever exhausts.
constexpr int kMaxRandomRayDraws = 64;

std::vector<Ray> random_rays(const Box& box, uint64_t count, uint64_t seed) {
  const std::string no_segment =
      "random rays: the scene's bounds are a single point, so no segment between two distinct points of its "
      "box exists (use a camera ray set)";
  if (box.extent() == Vec3(0.0f)) throw Error(no_segment);
  std::vector<Ray> rays;
  rays.resize(count);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      Rng rng(seed, i);
      Ray& ray = rays[i];
      for (int draw = 0;; ++draw) {
        if (draw == kMaxRandomRayDraws) throw Error(no_segment);
        const Vec3 a = box.min + box.extent() * Vec3(rng.uniform(), rng.uniform(), rng.uniform());
        const Vec3 b = box.min + box.extent() * Vec3(rng.uniform(), rng.uniform(), rng.uniform());
        if (a == b) continue;  // a zero direction cannot be traced
        ray.org = a;
        ray.dir = b - a;
        ray.tmin = 0.0f;
        ray.tmax = 1.0f;
        break;
      }
    }
  });
  return rays;
}

// Rays started at the primary hits of a camera: up to `per_pixel` per pixel, made by
// `emit(pixel, hit, tri, normal, rng, out)`, in pixel order, until `count` are made or the
// image ends. Pixels are traced a chunk at a time, so memory stays at `count` rays plus one
// chunk whatever the resolution; cutting at `count` gives the same rays as tracing all.
constexpr uint64_t kPixelChunk = uint64_t(1) << 16;

template <class Emit>
std::vector<Ray> from_primary_hits(const Mesh& mesh, const Tracer& tracer, const Camera& camera, uint64_t seed,
                                   uint32_t per_pixel, uint64_t count, Emit emit) {
  const CameraBasis basis(camera);
  const uint64_t pixels = basis.pixels();
  std::vector<Ray> out;
  std::vector<Ray> slots(kPixelChunk * per_pixel);
  std::vector<uint32_t> used(kPixelChunk);
  for (uint64_t begin = 0; begin < pixels && out.size() < count; begin += kPixelChunk) {
    const uint64_t n = std::min(kPixelChunk, pixels - begin);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        used[i] = 0;
        const Ray primary = basis.ray(begin + i);
        TraceCounters c;
        const Hit h = tracer.closest(primary, c);
        if (!h.hit()) continue;
        const Triangle tri = mesh.triangle(h.triangle_id);
        Vec3 normal;
        if (!facing_normal(tri, primary.dir, normal)) continue;
        Rng rng(seed, begin + i);
        used[i] = emit(primary, h, tri, normal, rng, &slots[i * per_pixel]);
      }
    });
    for (size_t i = 0; i < n; ++i) out.insert(out.end(), slots.begin() + i * per_pixel, slots.begin() + i * per_pixel + used[i]);
  }
  return out;
}

// The largest image the secondary sets grow to: `kPixelsPerRay` pixels per ray wanted
// (a view whose hits give fewer rays than that is all but empty; shadow rays start only at
// lit hits, about 1 % of the pixels of staircase.obj from its default camera), at least a
// 1024x1024 image, at most kMaxRayCount pixels. It bounds the time and, with the chunks
// above, keeps memory to the rays wanted whatever the camera sees.
constexpr double kPixelsPerRay = 1024.0;
double max_secondary_pixels(uint64_t count, uint32_t per_pixel) {
  return std::min(double(kMaxRayCount), std::max(1024.0 * 1024.0, kPixelsPerRay * double(count) / per_pixel));
}

// Rays started at the primary hits of the camera: ambient occlusion, shadow or path rays,
// the image grown until its hits give `count` rays, up to max_secondary_pixels; a view
// whose hits give fewer even then is an Error saying so.
std::vector<Ray> secondary_rays(const Mesh& mesh, const Tracer& tracer, const RaySetConfig& config,
                                const Camera& camera, uint64_t count) {
  const Box box = mesh_bounds(mesh);
  const float diagonal = length(box.extent());
  // Secondary rays start this far off the surface, along the normal, so they cannot hit
  // the triangle they leave through rounding of the hit point.
  const float offset = 1e-5f * std::max(diagonal, 1e-30f);
  uint32_t per_pixel = 1;
  if (config.kind == RayKind::ao) per_pixel = std::max<uint32_t>(config.ao_rays_per_hit, 1);
  if (config.kind == RayKind::path) per_pixel = 3;
  const float ao_length = config.ao_length_fraction * diagonal;
  const Vec3 light = config.light ? *config.light : default_light(mesh, config.up_axis);

  auto emit = [&](const Ray& primary, const Hit& h, const Triangle& tri, const Vec3& n, Rng& rng, Ray* out) -> uint32_t {
    const Vec3 p = hit_point(tri, h) + n * offset;
    if (config.kind == RayKind::ao) {
      for (uint32_t i = 0; i < per_pixel; ++i) {
        out[i].org = p;
        out[i].dir = cosine_direction(n, rng);
        out[i].tmin = 0.0f;
        out[i].tmax = ao_length;
      }
      return per_pixel;
    }
    if (config.kind == RayKind::shadow) {
      const Vec3 to_light = light - p;
      if (!(dot(to_light, n) > 0.0f)) return 0;  // the light is behind the surface
      out[0].org = p;
      out[0].dir = to_light;
      out[0].tmin = 0.0f;
      out[0].tmax = 1.0f;
      return 1;
    }
    // Path: the primary ray, then two diffuse bounces, each traced to find the next start.
    out[0] = primary;
    uint32_t n_out = 1;
    Vec3 start = p, normal = n;
    for (int bounce = 0; bounce < 2; ++bounce) {
      Ray r;
      r.org = start;
      r.dir = cosine_direction(normal, rng);
      out[n_out++] = r;
      if (bounce == 1) break;
      TraceCounters c;
      const Hit next = tracer.closest(r, c);
      if (!next.hit()) break;
      const Triangle t2 = mesh.triangle(next.triangle_id);
      if (!facing_normal(t2, r.dir, normal)) break;
      start = hit_point(t2, next) + normal * offset;
    }
    return n_out;
  };

  // Grow the image until its hits give enough rays; the rays of one pixel stay together.
  const double max_pixels = max_secondary_pixels(count, per_pixel);
  Camera cam = with_pixels(camera, std::min(max_pixels, std::max<double>(1.0, double(count) / per_pixel)));
  std::vector<Ray> rays;
  for (;;) {
    rays = from_primary_hits(mesh, tracer, cam, config.seed, per_pixel, count, emit);
    if (rays.size() >= count) break;
    const double pixels = double(cam.width) * cam.height;
    const double grow = rays.empty() ? 16.0 : std::min(16.0, 1.1 * double(count) / double(rays.size()));
    const Camera next = with_pixels(cam, std::min(max_pixels, pixels * std::max(grow, 1.1)));
    // At the limit, or unable to grow (rounding, or an extreme aspect ratio at its widest).
    if (double(next.width) * next.height <= pixels) {
      const std::string kind(ray_kind_name(config.kind));
      throw Error(mesh.name + ": " + kind + " rays: " + std::to_string(rays.size()) + " of the " +
                  std::to_string(count) + " wanted: the camera's hits at " + std::to_string(cam.width) + "x" +
                  std::to_string(cam.height) + " pixels (the limit for this count) give no more, as it sees geometry " +
                  "in too few pixels; aim the camera at the scene (--camera-position, --camera-target) or ask for fewer " +
                  "rays (--count)");
    }
    cam = next;
  }
  rays.resize(count);
  return rays;
}

}  // namespace

RayQuery default_query(RayKind kind) { return kind == RayKind::shadow ? RayQuery::any : RayQuery::closest; }

Vec3 default_light(const Mesh& mesh, int up_axis) {
  const Box box = mesh_bounds(mesh);
  return box.center() + axis_vector(up_axis, 0.4f * box.extent()[up_axis]);
}

RaySet make_ray_set(const Mesh& mesh, const Tracer& tracer, const RaySetConfig& config) {
  if (config.count > kMaxRayCount)
    throw Error(std::string(ray_kind_name(config.kind)) + " rays: count " + std::to_string(config.count) +
                " is above the limit of " + std::to_string(kMaxRayCount) + " rays in one set");
  if (config.light && !(std::isfinite(config.light->x) && std::isfinite(config.light->y) &&
                        std::isfinite(config.light->z)))
    throw Error(std::string(ray_kind_name(config.kind)) + " rays: the light (" + std::to_string(config.light->x) +
                ", " + std::to_string(config.light->y) + ", " + std::to_string(config.light->z) +
                ") is not a finite point");
  RaySet set;
  set.kind = config.kind;
  set.seed = config.seed;
  set.query = config.query ? *config.query : default_query(config.kind);
  if (config.kind == RayKind::random) {
    // No camera: a scene the default camera cannot frame (a single point) still gets its
    // own error from random_rays.
    set.rays = random_rays(mesh_bounds(mesh), config.count != 0 ? config.count : 1'000'000, config.seed);
    return set;
  }
  const Camera camera =
      config.camera ? *config.camera : default_camera(mesh, tracer, config.width, config.height, config.up_axis);
  const uint64_t count = config.count != 0 ? config.count
                         : config.kind == RayKind::primary ? uint64_t(camera.width) * camera.height
                                                           : 1'000'000;

  if (config.kind == RayKind::primary) {
    const Camera cam = config.count != 0 ? with_pixels(camera, double(count)) : camera;
    set.width = cam.width;
    set.height = cam.height;
    set.rays = camera_rays(cam);
  } else {
    set.rays = secondary_rays(mesh, tracer, config, camera, count);
  }
  return set;
}


}  // namespace bvhopt
