// The procedural built-in scene "atrium": a two-storey basilica hall in the spirit of
// Sponza and Conference. What matters for BVH work is the mix it reproduces: a few large
// triangles (walls, floors, vault), mid-sized tessellated architecture (columns, arches,
// stairs), a crowd of small detailed objects (tables, chairs, plants, shelves of books)
// and long thin slabs at odd angles whose boxes are mostly empty space.
//
// Scaling: the hall grows by bays and its tessellation gets finer with the cube root of the
// target; the rest of the budget is filled with furniture, and the last few hundred
// triangles with fallen leaves, so the count lands on the target exactly (unless the target
// is below the bare architecture, about 3,500 triangles).
//
// The generator runs twice with the same random stream: once counting, once writing into
// vectors sized exactly, so a 10M-triangle scene never reallocates.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "bvhopt/scene.h"
#include "tree/huge_pages.h"

namespace bvhopt {

namespace {

constexpr float kPi = 3.14159265358979323846f;

// Uniform numbers from the mt19937_64 stream, converted by hand: the standard fixes the
// engine's output but not the distributions', and the scene must be the same everywhere.
class Random {
 public:
  explicit Random(uint64_t seed) : engine_(seed) {}
  float uniform() { return static_cast<float>((engine_() >> 40) * (1.0 / 16777216.0)); }  // [0, 1)
  float uniform(float lo, float hi) { return lo + (hi - lo) * uniform(); }
  int integer(int lo, int hi) {  // [lo, hi]
    return lo + static_cast<int>((engine_() >> 33) % static_cast<uint64_t>(hi - lo + 1));
  }

 private:
  std::mt19937_64 engine_;
};

// A placement: origin plus orthonormal axes; local (x, y, z) maps to o + x*ex + y*ey + z*ez.
struct Frame {
  Vec3 o, ex{1, 0, 0}, ey{0, 1, 0}, ez{0, 0, 1};
  Vec3 at(float x, float y, float z) const { return o + ex * x + ey * y + ez * z; }
  Vec3 at(const Vec3& p) const { return at(p.x, p.y, p.z); }

  // Turned by `yaw` radians about the vertical.
  static Frame yawed(const Vec3& origin, float yaw) {
    float c = std::cos(yaw), s = std::sin(yaw);
    return {origin, {c, 0, s}, {0, 1, 0}, {-s, 0, c}};
  }
  // Local x along `dir` (any direction), the other two axes completing it.
  static Frame along(const Vec3& origin, const Vec3& dir) {
    Vec3 x = normalize(dir);
    Vec3 helper = std::fabs(x.y) < 0.9f ? Vec3(0, 1, 0) : Vec3(1, 0, 0);
    Vec3 z = normalize(cross(x, helper));
    Vec3 y = cross(z, x);
    // Local +y points up (or level), so a slab lying on the floor rises from it rather
    // than sinking into it.
    if (y.y < 0) {
      y = -y;
      z = -z;
    }
    return {origin, x, y, z};
  }
  // A sub-frame placed at local `p` with the same axes.
  Frame offset(const Vec3& p) const { return {at(p), ex, ey, ez}; }
};

// Emits triangles, or only counts them (mesh == nullptr).
class Emitter {
 public:
  explicit Emitter(Mesh* mesh) : mesh_(mesh) {}
  uint64_t triangles() const { return triangles_; }
  uint64_t vertices() const { return vertices_; }

  uint32_t vertex(const Vec3& p) {
    if (mesh_) mesh_->add_vertex(p);
    return static_cast<uint32_t>(vertices_++);
  }
  void tri(uint32_t a, uint32_t b, uint32_t c) {
    if (mesh_) mesh_->add_triangle(a, b, c);
    ++triangles_;
  }
  void quad(uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    tri(a, b, c);
    tri(a, c, d);
  }

  // A box [lo, hi] in the frame's coordinates: 8 vertices, 12 triangles.
  void box(const Frame& f, const Vec3& lo, const Vec3& hi) {
    uint32_t v[8];
    for (int i = 0; i < 8; ++i)
      v[i] = vertex(f.at(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z));
    quad(v[0], v[2], v[3], v[1]);  // z = lo
    quad(v[4], v[5], v[7], v[6]);  // z = hi
    quad(v[0], v[1], v[5], v[4]);  // y = lo
    quad(v[2], v[6], v[7], v[3]);  // y = hi
    quad(v[0], v[4], v[6], v[2]);  // x = lo
    quad(v[1], v[3], v[7], v[5]);  // x = hi
  }

  // The parallelogram o + [0,1]*du + [0,1]*dv as an nu x nv grid of quads.
  void grid(const Vec3& o, const Vec3& du, const Vec3& dv, int nu, int nv) {
    uint32_t first = static_cast<uint32_t>(vertices_);
    for (int j = 0; j <= nv; ++j)
      for (int i = 0; i <= nu; ++i) vertex(o + du * (float(i) / nu) + dv * (float(j) / nv));
    for (int j = 0; j < nv; ++j)
      for (int i = 0; i < nu; ++i) {
        uint32_t a = first + j * (nu + 1) + i;
        quad(a, a + 1, a + nu + 2, a + nu + 1);
      }
  }

  // An open or capped cylinder along the frame's y axis from y = 0 to y = h:
  // 2*segments*rings side triangles plus `segments` per cap.
  void cylinder(const Frame& f, float radius, float h, int segments, int rings, bool bottom_cap, bool top_cap) {
    uint32_t first = static_cast<uint32_t>(vertices_);
    for (int j = 0; j <= rings; ++j)
      for (int i = 0; i < segments; ++i) {
        float a = 2.0f * kPi * i / segments;
        vertex(f.at(radius * std::cos(a), h * j / rings, radius * std::sin(a)));
      }
    for (int j = 0; j < rings; ++j)
      for (int i = 0; i < segments; ++i) {
        uint32_t a = first + j * segments + i, b = first + j * segments + (i + 1) % segments;
        quad(a, b, b + segments, a + segments);
      }
    if (bottom_cap) {
      uint32_t c = vertex(f.at(0, 0, 0));
      for (int i = 0; i < segments; ++i) tri(c, first + (i + 1) % segments, first + i);
    }
    if (top_cap) {
      uint32_t ring = first + rings * segments;
      uint32_t c = vertex(f.at(0, h, 0));
      for (int i = 0; i < segments; ++i) tri(c, ring + i, ring + (i + 1) % segments);
    }
  }

  // A semicircular arch in the frame's x-y plane, centred on the origin, between radii
  // r_in and r_out and depth [-d/2, d/2] in z: 8 triangles per segment.
  void arch(const Frame& f, float r_in, float r_out, float depth, int segments) {
    uint32_t first = static_cast<uint32_t>(vertices_);
    for (int i = 0; i <= segments; ++i) {
      float a = kPi * i / segments, c = std::cos(a), s = std::sin(a);
      vertex(f.at(r_in * c, r_in * s, -0.5f * depth));
      vertex(f.at(r_out * c, r_out * s, -0.5f * depth));
      vertex(f.at(r_out * c, r_out * s, 0.5f * depth));
      vertex(f.at(r_in * c, r_in * s, 0.5f * depth));
    }
    for (int i = 0; i < segments; ++i) {
      uint32_t a = first + 4 * i, b = a + 4;
      for (int k = 0; k < 4; ++k) quad(a + k, a + (k + 1) % 4, b + (k + 1) % 4, b + k);
    }
  }

  // A leaf: a diamond of two triangles from `base` along `dir`, `width` across.
  void leaf(const Vec3& base, const Vec3& dir, const Vec3& side, float len, float width) {
    uint32_t a = vertex(base);
    uint32_t b = vertex(base + dir * (0.45f * len) + side * (0.5f * width));
    uint32_t c = vertex(base + dir * len);
    uint32_t d = vertex(base + dir * (0.45f * len) - side * (0.5f * width));
    tri(a, b, c);
    tri(a, c, d);
  }

 private:
  Mesh* mesh_;
  uint64_t vertices_ = 0, triangles_ = 0;
};

// A random unit vector, rejection-sampled so it is uniform and never zero.
Vec3 random_direction(Random& rng) {
  for (;;) {
    Vec3 v(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
    float l2 = dot(v, v);
    if (l2 > 0.01f && l2 <= 1.0f) return v / std::sqrt(l2);
  }
}

// Dimensions of the hall (metres, y up). The nave runs along x, aisles on both sides,
// a gallery floor over the aisles, a barrel vault over the nave.
struct Hall {
  int bays;
  float bay = 5.0f;                  // column spacing along x
  float length;                      // bays * bay
  float nave_half = 10.0f;           // nave: |z| < 10
  float outer_half = 15.0f;          // aisles: 10 < |z| < 15
  float gallery = 6.3f;              // gallery floor top
  float arcade_height = 3.5f;        // ground column shaft height
  float gallery_column_base = 6.3f;  // upper columns start on the gallery floor
  float eaves = 12.5f;               // vault springing, aisle ceiling
};

// Tessellation levels, all growing with the cube root of the target.
struct Detail {
  int column_segments, column_rings;
  int vault_segments, vault_rings_per_bay;
  int arch_segments;
  int leg_segments;
  int pot_segments;
  int plant_leaves;
  int books_per_shelf;
};

struct Generator {
  const BuiltinSceneConfig& config;
  Emitter& out;
  Random rng;
  Hall hall;
  Detail detail;

  Generator(const BuiltinSceneConfig& c, Emitter& e) : config(c), out(e), rng(c.seed ^ 0x61747269756dULL) {
    const float q = std::cbrt(static_cast<float>(std::max<uint64_t>(c.target_triangles, 1)) / 250000.0f);
    auto level = [&](float base, int lo, int hi) { return std::clamp(static_cast<int>(std::lround(base * q)), lo, hi); };
    hall.bays = level(10, 3, 200);
    hall.length = hall.bays * hall.bay;
    detail.column_segments = level(16, 6, 128);
    detail.column_rings = level(6, 1, 64);
    detail.vault_segments = level(32, 8, 256);
    detail.vault_rings_per_bay = level(6, 1, 32);
    detail.arch_segments = level(12, 4, 96);
    detail.leg_segments = level(5, 4, 24);
    detail.pot_segments = level(12, 6, 48);
    detail.plant_leaves = level(40, 12, 400);
    detail.books_per_shelf = 18;
  }

  // ---- architecture -------------------------------------------------------------------

  void floors_walls_ceilings() {
    const float L = hall.length, W = hall.outer_half, N = hall.nave_half, H = hall.eaves;
    // Ground floor in large stone slabs (2.5 m): few, large triangles.
    int nx = std::max(1, static_cast<int>(std::lround(L / 2.5f)));
    // Surfaces face the inside of the hall (grid normals are du x dv), as modelled interiors
    // do, so that front faces mean "seen from inside".
    out.grid({0, 0, -W}, {0, 0, 2 * W}, {L, 0, 0}, 12, nx);
    // Gallery floors over both aisles: slabs one bay long, with their undersides.
    for (int side = -1; side <= 1; side += 2) {
      float z0 = side < 0 ? -W : N, z1 = side < 0 ? -N : W;
      for (int b = 0; b < hall.bays; ++b)
        out.box({}, {b * hall.bay, hall.gallery - 0.3f, z0}, {(b + 1) * hall.bay, hall.gallery, z1});
      // Aisle ceiling, one panel per bay.
      out.grid({0, H, z0}, {L, 0, 0}, {0, 0, z1 - z0}, hall.bays, 1);
      // Outer wall: one panel per bay and storey, the largest triangles of the scene.
      float zw = side * W;
      if (side < 0)
        out.grid({0, 0, zw}, {L, 0, 0}, {0, H, 0}, hall.bays, 2);
      else
        out.grid({0, 0, zw}, {0, H, 0}, {L, 0, 0}, 2, hall.bays);
    }
    // End walls, and the lunettes under the vault as fans of long triangles.
    for (int end = 0; end <= 1; ++end) {
      float x = end * L;
      if (end == 0)
        out.grid({x, 0, -W}, {0, H, 0}, {0, 0, 2 * W}, 2, 6);
      else
        out.grid({x, 0, -W}, {0, 0, 2 * W}, {0, H, 0}, 6, 2);
      uint32_t c = out.vertex({x, H, 0});
      uint32_t prev = out.vertex({x, H, N});
      for (int i = 1; i <= detail.vault_segments; ++i) {
        float a = kPi * i / detail.vault_segments;
        uint32_t v = out.vertex({x, H + N * std::sin(a), N * std::cos(a)});
        if (end == 0)
          out.tri(c, v, prev);
        else
          out.tri(c, prev, v);
        prev = v;
      }
    }
  }

  void vault() {
    // Barrel vault over the nave: a half cylinder along x, open at the ends.
    const int around = detail.vault_segments, along = detail.vault_rings_per_bay * hall.bays;
    const float R = hall.nave_half, H = hall.eaves;
    uint32_t first = static_cast<uint32_t>(out.vertices());
    for (int j = 0; j <= along; ++j)
      for (int i = 0; i <= around; ++i) {
        float a = kPi * i / around;
        out.vertex({hall.length * j / along, H + R * std::sin(a), R * std::cos(a)});
      }
    for (int j = 0; j < along; ++j)
      for (int i = 0; i < around; ++i) {
        uint32_t a = first + j * (around + 1) + i;
        out.quad(a, a + 1, a + around + 2, a + around + 1);
      }
    // Transverse ribs under the vault at every column pair.
    for (int b = 0; b <= hall.bays; ++b) {
      Frame f = {{b * hall.bay, H, 0}, {0, 0, 1}, {0, 1, 0}, {-1, 0, 0}};
      out.arch(f, R - 0.35f, R, 0.5f, detail.vault_segments);
    }
  }

  void column(const Vec3& base, float height) {
    const float r = 0.35f;
    out.box({}, base + Vec3(-0.5f, 0, -0.5f), base + Vec3(0.5f, 0.3f, 0.5f));  // plinth
    out.cylinder(Frame{base + Vec3(0, 0.3f, 0)}, r, height - 0.6f, detail.column_segments, detail.column_rings,
                 false, false);
    out.box({}, base + Vec3(-0.55f, height - 0.3f, -0.55f), base + Vec3(0.55f, height, 0.55f));  // capital
  }

  void arcades() {
    // Two rows of columns on each storey, arches between neighbours along x.
    const float storey_base[2] = {0.0f, hall.gallery_column_base};
    const float storey_height[2] = {hall.arcade_height, hall.eaves - hall.gallery_column_base - 2.6f};
    for (int s = 0; s < 2; ++s)
      for (int side = -1; side <= 1; side += 2) {
        float z = side * hall.nave_half;
        for (int b = 0; b <= hall.bays; ++b) column({b * hall.bay, storey_base[s], z}, storey_height[s]);
        for (int b = 0; b < hall.bays; ++b) {
          Frame f{{(b + 0.5f) * hall.bay, storey_base[s] + storey_height[s], z}};
          out.arch(f, 0.5f * hall.bay - 0.55f, 0.5f * hall.bay - 0.15f, 0.7f, detail.arch_segments);
        }
        // Balustrade of the gallery: a rail and thin balusters on the upper storey.
        if (s == 1) {
          out.box({}, {0, hall.gallery + 0.95f, z - 0.06f}, {hall.length, hall.gallery + 1.05f, z + 0.06f});
          for (float x = 0.6f; x < hall.length - 0.3f; x += 0.5f)
            out.cylinder(Frame{{x, hall.gallery, z}}, 0.04f, 0.95f, 6, 1, false, false);
        }
      }
  }

  // A straight run of solid steps from the floor to the gallery, climbing along +x or -x.
  void staircase(float x_start, int direction, float z0, float z1) {
    const int steps = 21;
    const float rise = hall.gallery / steps, run = 0.3f;
    for (int i = 0; i < steps; ++i) {
      float xa = x_start + direction * i * run, xb = xa + direction * run;
      out.box({}, {std::min(xa, xb), 0, z0}, {std::max(xa, xb), (i + 1) * rise, z1});
    }
    // Handrail: a long thin slab along the slope, so tilted off the axes.
    float zr = z0 + 0.05f;
    Vec3 from(x_start, rise + 0.9f, zr), to(x_start + direction * steps * run, hall.gallery + 0.9f, zr);
    Vec3 d = to - from;
    out.box(Frame::along(from, d), {0, -0.03f, -0.03f}, {length(d), 0.03f, 0.03f});
    for (int i = 0; i < steps; ++i)
      out.cylinder(Frame{{x_start + direction * (i + 0.5f) * run, (i + 1) * rise, zr}}, 0.02f, 0.9f, 6, 1, false,
                   false);
  }

  void stairs() {
    // One staircase every few bays, alternating sides.
    int count = std::max(2, hall.bays / 5);
    for (int k = 0; k < count; ++k) {
      int side = k % 2 ? 1 : -1;
      float z0 = side > 0 ? hall.outer_half - 1.6f : -hall.outer_half + 0.1f;
      // Spread along the hall, each run of 6.3 m kept inside it.
      int direction = k % 4 < 2 ? 1 : -1;
      float x = 0.5f + (hall.length - 7.3f) * (k + 0.5f) / count;
      staircase(direction > 0 ? x : x + 6.3f, direction, z0, z0 + 1.5f);
    }
  }

  void slabs() {
    // Roof trusses: diagonal braces from the nave wall up into the vault.
    for (int b = 0; b < hall.bays; ++b)
      for (int side = -1; side <= 1; side += 2) {
        Vec3 from(b * hall.bay + 0.3f, hall.eaves, side * (hall.nave_half - 0.4f));
        Vec3 to((b + 0.7f) * hall.bay, hall.eaves + 7.0f, side * 1.0f);
        Vec3 d = to - from;
        out.box(Frame::along(from, d), {0, -0.08f, -0.05f}, {length(d), 0.08f, 0.05f});
      }
    // Planks and poles lying or leaning at random headings all through the hall: long,
    // thin, and aligned with no axis, so their boxes are mostly empty space.
    for (int i = 0; i < 3 * hall.bays; ++i) {
      Vec3 from = random_spot() + Vec3(0, 0.01f, 0);
      // Any heading, rising at most 50 degrees: Frame::along then keeps the slab's
      // cross-section axes level or rising, so no corner dips below the floor.
      const float heading = rng.uniform(0, 2 * kPi), elevation = rng.uniform(0.0f, 0.87f);
      Vec3 d(std::cos(elevation) * std::cos(heading), std::sin(elevation), std::cos(elevation) * std::sin(heading));
      // As long as 3 to 9 m, but no longer than the hall allows in that direction.
      float len = rng.uniform(3.0f, 9.0f);
      const float lo[3] = {0.1f, from.y, -hall.outer_half + 0.1f};
      const float hi[3] = {hall.length - 0.1f, hall.eaves - 0.5f, hall.outer_half - 0.1f};
      for (int a = 0; a < 3; ++a) {
        if (d[a] > 1e-6f) len = std::min(len, (hi[a] - from[a]) / d[a]);
        if (d[a] < -1e-6f) len = std::min(len, (lo[a] - from[a]) / d[a]);
      }
      len = std::max(len, 0.5f);
      out.box(Frame::along(from, d), {0, 0, 0}, {len, rng.uniform(0.04f, 0.14f), rng.uniform(0.02f, 0.05f)});
    }
  }

  // ---- furniture ----------------------------------------------------------------------

  int leg_triangles() const { return 2 * detail.leg_segments; }
  int table_set_bound() const { return 12 + 4 * leg_triangles() + 4 * (24 + 4 * leg_triangles()); }
  // Upper bounds on each object's triangles, so that furnishing stops before the target
  // and the leaves on the floor make up the exact difference.
  int plant_bound() const { return 6 * detail.pot_segments + 12 + 2 * detail.plant_leaves; }
  int shelf_bound() const { return 8 * 12 + 4 * detail.books_per_shelf * 12; }
  int object_bound() const { return std::max({table_set_bound(), plant_bound(), shelf_bound()}); }

  void legs(const Frame& f, float hx, float hz, float height, float radius) {
    for (int i = 0; i < 4; ++i)
      out.cylinder(f.offset({i & 1 ? hx : -hx, 0, i & 2 ? hz : -hz}), radius, height, detail.leg_segments, 1, false,
                   false);
  }

  void chair(const Frame& f) {
    legs(f, 0.19f, 0.19f, 0.45f, 0.018f);
    out.box(f, {-0.23f, 0.45f, -0.23f}, {0.23f, 0.49f, 0.23f});   // seat
    out.box(f, {-0.23f, 0.49f, 0.2f}, {0.23f, 0.95f, 0.23f});     // back
  }

  void table_set(const Vec3& pos) {
    Frame f = Frame::yawed(pos, rng.uniform(0, 2 * kPi));
    legs(f, 0.55f, 0.35f, 0.72f, 0.025f);
    out.box(f, {-0.6f, 0.72f, -0.4f}, {0.6f, 0.76f, 0.4f});
    int chairs = rng.integer(2, 4);
    for (int c = 0; c < chairs; ++c) {
      // Chairs on the table's four sides, pushed out a little at random, facing the table
      // (a chair's back is its local +z, so its -z must point at the table).
      float out_by = rng.uniform(0.0f, 0.3f);
      Vec3 local = c == 0 ? Vec3(0.75f + out_by, 0, 0)
                 : c == 1 ? Vec3(0, 0, 0.6f + out_by)
                 : c == 2 ? Vec3(-0.75f - out_by, 0, 0)
                          : Vec3(0, 0, -0.6f - out_by);
      Vec3 p = f.at(local);
      Vec3 d = normalize(pos - p);
      chair(Frame::yawed(p, std::atan2(d.x, -d.z) + rng.uniform(-0.3f, 0.3f)));
    }
  }

  void plant(const Vec3& pos) {
    const float pot_r = rng.uniform(0.12f, 0.25f), pot_h = rng.uniform(0.2f, 0.4f);
    Frame f{pos};
    out.cylinder(f, pot_r, pot_h, detail.pot_segments, 1, true, false);
    out.cylinder(f.offset({0, pot_h - 0.03f, 0}), pot_r * 0.95f, 0.01f, detail.pot_segments, 1, false, true);
    const float stem_h = rng.uniform(0.4f, 1.4f);
    out.cylinder(f.offset({0, pot_h, 0}), 0.012f, stem_h, 6, 1, false, false);
    int leaves = rng.integer(detail.plant_leaves / 2, detail.plant_leaves);
    for (int i = 0; i < leaves; ++i) {
      Vec3 base = pos + Vec3(0, pot_h + stem_h * rng.uniform(0.3f, 1.0f), 0);
      Vec3 dir = random_direction(rng);
      dir.y = std::fabs(dir.y) * 0.8f + 0.2f;  // leaves point up and out
      dir = normalize(dir);
      Vec3 side = normalize(cross(dir, random_direction(rng)));
      if (!is_finite(side)) side = normalize(cross(dir, Vec3(1, 0, 0)));
      out.leaf(base, dir, side, rng.uniform(0.06f, 0.18f), rng.uniform(0.02f, 0.06f));
    }
  }

  void bookshelf(const Vec3& pos, float yaw) {
    Frame f = Frame::yawed(pos, yaw);
    const float w = 0.9f, d = 0.3f, h = 2.0f;
    out.box(f, {-w / 2, 0, 0}, {-w / 2 + 0.02f, h, d});
    out.box(f, {w / 2 - 0.02f, 0, 0}, {w / 2, h, d});
    for (int s = 0; s < 5; ++s) {
      float y = 0.05f + s * 0.45f;
      out.box(f, {-w / 2 + 0.02f, y - 0.02f, 0}, {w / 2 - 0.02f, y, d});
      if (s == 4) break;
      // Books of random thickness and height, left to right until the shelf is full.
      float x = -w / 2 + 0.03f;
      for (int k = 0; k < detail.books_per_shelf; ++k) {
        float t = rng.uniform(0.015f, 0.05f);
        if (x + t > w / 2 - 0.03f) break;
        out.box(f, {x, y, 0.02f}, {x + t, y + rng.uniform(0.18f, 0.38f), rng.uniform(0.18f, 0.27f)});
        x += t + 0.002f;
      }
    }
    out.box(f, {-w / 2, h - 0.02f, 0}, {w / 2, h, d});
  }

  // A random spot on a walkable floor, weighted by area: the nave, the two aisles, the two
  // galleries. Returns the floor height in y.
  Vec3 random_spot(float margin = 0.8f) {
    const float L = hall.length, N = hall.nave_half, W = hall.outer_half;
    const float nave = L * 2 * N, aisle = L * (W - N);
    float r = rng.uniform(0, nave + 4 * aisle);
    float x = rng.uniform(margin, L - margin);
    if (r < nave) return {x, 0, rng.uniform(-N + margin + 0.2f, N - margin - 0.2f)};
    int k = static_cast<int>((r - nave) / aisle);
    float y = k < 2 ? 0.0f : hall.gallery;
    float side = k % 2 ? 1.0f : -1.0f;
    return {x, y, side * rng.uniform(N + margin, W - margin)};
  }

  void furnish(uint64_t target) {
    const uint64_t bound = static_cast<uint64_t>(object_bound());
    while (out.triangles() + bound <= target) {
      float kind = rng.uniform();
      // Table sets need room for their chairs (up to 1.4 m from the centre).
      Vec3 p = random_spot(kind < 0.45f ? 1.45f : 0.6f);
      if (kind < 0.45f) {
        table_set(p);
      } else if (kind < 0.8f) {
        plant(p);
      } else {
        // Against the outer wall of whichever aisle or gallery the spot is in, else along
        // the nave arcade.
        float side = p.z < 0 ? -1.0f : 1.0f;
        float wall = std::fabs(p.z) > hall.nave_half ? hall.outer_half : hall.nave_half - 0.5f;
        float z = side * (wall - 0.32f);
        bookshelf({p.x, p.y, z}, side > 0 ? 0.0f : kPi);
      }
    }
    // The last few hundred triangles: fallen leaves on the floor, one triangle each.
    while (out.triangles() < target) {
      Vec3 p = random_spot() + Vec3(0, 0.002f, 0);
      float a = rng.uniform(0, 2 * kPi), b = a + rng.uniform(0.6f, 2.4f);
      float r1 = rng.uniform(0.03f, 0.1f), r2 = rng.uniform(0.03f, 0.1f);
      uint32_t v0 = out.vertex(p);
      uint32_t v1 = out.vertex(p + Vec3(r1 * std::cos(a), 0, r1 * std::sin(a)));
      uint32_t v2 = out.vertex(p + Vec3(r2 * std::cos(b), 0.004f, r2 * std::sin(b)));
      out.tri(v0, v2, v1);
    }
  }

  void run() {
    floors_walls_ceilings();
    vault();
    arcades();
    stairs();
    slabs();
    furnish(config.target_triangles);
  }
};

}  // namespace

uint64_t min_builtin_scene_triangles(uint64_t seed) {
  Emitter counter(nullptr);
  Generator(BuiltinSceneConfig{seed, 1}, counter).run();
  return counter.triangles();
}

Mesh make_builtin_scene(const BuiltinSceneConfig& config) {
  Emitter counter(nullptr);
  Generator(config, counter).run();
  Mesh mesh;
  mesh.name = "builtin:atrium";
  detail::reserve_on_huge_pages(mesh.positions, 3 * counter.vertices());
  detail::reserve_on_huge_pages(mesh.indices, 3 * counter.triangles());
  Emitter writer(&mesh);
  Generator(config, writer).run();
  return mesh;
}

}  // namespace bvhopt
