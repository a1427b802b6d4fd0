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

// Rays started at the primary hits of a camera: up to `per_pixel` per pixel, made by
// `emit(pixel, hit, tri, normal, rng, out)`, gathered in pixel order.
template <class Emit>
std::vector<Ray> from_primary_hits(const Mesh& mesh, const Tracer& tracer, const Camera& camera, uint64_t seed,
                                   uint32_t per_pixel, Emit emit) {
  const std::vector<Ray> primary = camera_rays(camera);
  const size_t pixels = primary.size();
  std::vector<Ray> slots(pixels * per_pixel);
  std::vector<uint32_t> used(pixels, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pixels, 256), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t p = r.begin(); p < r.end(); ++p) {
      TraceCounters c;
      const Hit h = tracer.closest(primary[p], c);
      if (!h.hit()) continue;
      const Triangle tri = mesh.triangle(h.triangle_id);
      Vec3 n;
      if (!facing_normal(tri, primary[p].dir, n)) continue;
      Rng rng(seed, p);
      used[p] = emit(primary[p], h, tri, n, rng, &slots[p * per_pixel]);
    }
  });
  std::vector<Ray> out;
  for (size_t p = 0; p < pixels; ++p)
    out.insert(out.end(), slots.begin() + p * per_pixel, slots.begin() + p * per_pixel + used[p]);
  return out;
}

Camera with_pixels(Camera cam, double pixels) {
  const double aspect = double(cam.width) / double(std::max<uint32_t>(cam.height, 1));
  const double h = std::max(1.0, std::round(std::sqrt(pixels / aspect)));
  const double w = std::max(1.0, std::round(pixels / h));
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

std::vector<Ray> camera_rays(const Camera& cam) {
  const Vec3 forward_raw = cam.target - cam.position;
  if (!(length(forward_raw) > 0.0f) || !is_finite(forward_raw))
    throw Error("camera: position and target must differ and be finite");
  const Vec3 forward = normalize(forward_raw);
  Vec3 right = cross(forward, cam.up);
  if (!(length(right) > 1e-6f)) {
    // Looking straight along `up`: any perpendicular will do.
    right = cross(forward, std::fabs(forward.x) < 0.9f ? Vec3(1, 0, 0) : Vec3(0, 1, 0));
  }
  right = normalize(right);
  const Vec3 up = cross(right, forward);
  if (cam.width == 0 || cam.height == 0) throw Error("camera: resolution must be at least 1x1");
  if (!(cam.fov_degrees > 0.0f && cam.fov_degrees < 180.0f))
    throw Error("camera: field of view " + std::to_string(cam.fov_degrees) + " not in (0, 180) degrees");
  const float tan_half = std::tan(0.5f * cam.fov_degrees * std::numbers::pi_v<float> / 180.0f);
  const float aspect = float(cam.width) / float(cam.height);
  std::vector<Ray> rays(size_t(cam.width) * cam.height);
  for (uint32_t y = 0; y < cam.height; ++y)
    for (uint32_t x = 0; x < cam.width; ++x) {
      const float sx = (2.0f * (x + 0.5f) / cam.width - 1.0f) * tan_half * aspect;
      const float sy = (1.0f - 2.0f * (y + 0.5f) / cam.height) * tan_half;
      Ray& r = rays[size_t(y) * cam.width + x];
      r.org = cam.position;
      r.dir = normalize(forward + right * sx + up * sy);
    }
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

// Rays started at the primary hits of the camera: ambient occlusion, shadow or path rays,
// the image grown until its hits give `count` rays (or a sparse view gives what it can).
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
  const Vec3 light = config.light ? *config.light
                                  : box.center() + axis_vector(config.up_axis, 0.4f * box.extent()[config.up_axis]);

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
  Camera cam = with_pixels(camera, std::max<double>(1.0, double(count) / per_pixel));
  std::vector<Ray> rays;
  for (int attempt = 0;; ++attempt) {
    rays = from_primary_hits(mesh, tracer, cam, config.seed, per_pixel, emit);
    if (rays.size() >= count) break;
    if (attempt == 6 || rays.empty()) {
      if (rays.empty())
        throw Error(mesh.name + ": no " + std::string(ray_kind_name(config.kind)) +
                    " rays: the camera sees no geometry (set a camera position and target)");
      break;  // a sparse view: take what there is
    }
    const double grow = std::min(16.0, 1.1 * double(count) / double(rays.size()));
    cam = with_pixels(cam, double(cam.width) * cam.height * grow);
  }
  if (rays.size() > count) rays.resize(count);
  return rays;
}

}  // namespace

RaySet make_ray_set(const Mesh& mesh, const Tracer& tracer, const RaySetConfig& config) {
  RaySet set;
  set.kind = config.kind;
  set.seed = config.seed;
  set.query = config.kind == RayKind::shadow ? RayQuery::any : RayQuery::closest;
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
  } else if (config.kind == RayKind::random) {
    set.rays = random_rays(mesh_bounds(mesh), count, config.seed);
  } else {
    set.rays = secondary_rays(mesh, tracer, config, camera, count);
  }
  return set;
}


}  // namespace bvhopt
