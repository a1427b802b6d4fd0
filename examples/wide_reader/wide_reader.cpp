// wide_reader: reads a wide BVH written by `bvhopt export` (format flat, 4- or 8-wide, or
// format cwbvh, compressed 8-wide nodes) and a ray file (`bvhopt trace --save-rays`), traces
// every ray with plain scalar code and writes one line per ray in the hit-file format of
// `bvhopt trace --save-hits`: equal files mean equal hits.
//
//   wide_reader EXPORT_FILE RAY_FILE HITS_FILE
//
// Self-contained: it knows only the documented formats (docs/wide-export-format.md and
// docs/ray-file-format.md), little-endian, as a renderer would. Kept short and plain rather
// than fast: a renderer would keep the data in place and use SIMD.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using Bytes = std::vector<unsigned char>;

struct Failure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

Bytes read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Failure(path + ": cannot open");
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

uint64_t fnv1a(uint64_t h, const unsigned char* p, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001B3ull;
  }
  return h;
}
constexpr uint64_t kFnvBasis = 0xCBF29CE484222325ull;

// A little-endian field at `offset`, read on a little-endian host (checked with the header's
// byte-order mark).
template <class T>
T field(const Bytes& b, size_t offset) {
  T v;
  std::memcpy(&v, b.data() + offset, sizeof v);
  return v;
}

// ---- Rays (docs/ray-file-format.md) ----------------------------------------------------------

struct Ray {
  float org[3], tmin, dir[3], tmax;
};

struct RaySet {
  bool any_hit = false;
  std::vector<Ray> rays;
};

RaySet read_rays(const std::string& path) {
  const Bytes b = read_file(path);
  if (b.size() < 64 || std::memcmp(b.data(), "BVHORAYS", 8) != 0) throw Failure(path + ": not a ray file");
  if (field<uint32_t>(b, 8) != 1) throw Failure(path + ": ray file version " + std::to_string(field<uint32_t>(b, 8)));
  const uint64_t count = field<uint64_t>(b, 40);
  if (count > (b.size() - 64) / 32 || b.size() != 64 + 32 * count) throw Failure(path + ": size does not match its ray count");
  const uint64_t sum = fnv1a(fnv1a(kFnvBasis, b.data(), 48), b.data() + 64, 32 * count);
  if (sum != field<uint64_t>(b, 48)) throw Failure(path + ": checksum mismatch");
  RaySet set;
  set.any_hit = field<uint32_t>(b, 16) == 1;
  set.rays.resize(count);
  std::memcpy(set.rays.data(), b.data() + 64, 32 * count);
  return set;
}

// ---- The export file (docs/wide-export-format.md) ----------------------------------------------

struct Export {
  uint32_t format = 0, width = 0, triangles = 0, root = 0, stack_entries = 0;
  uint64_t nodes = 0;
  Bytes file;
  size_t section0 = 0, section0_bytes = 0, section1 = 0, section1_bytes = 0;
};

Export read_export(const std::string& path) {
  Export e;
  e.file = read_file(path);
  const Bytes& b = e.file;
  if (b.size() < 128 || std::memcmp(b.data(), "BVHOWIDE", 8) != 0) throw Failure(path + ": not a wide BVH export file");
  if (field<uint32_t>(b, 8) != 1) throw Failure(path + ": version " + std::to_string(field<uint32_t>(b, 8)) + ", this reader knows 1");
  if (field<uint32_t>(b, 12) != 0x01020304u) throw Failure(path + ": byte order mark does not read as little-endian");
  e.format = field<uint32_t>(b, 16);
  e.width = field<uint32_t>(b, 20);
  e.triangles = field<uint32_t>(b, 24);
  e.root = field<uint32_t>(b, 28);
  e.nodes = field<uint64_t>(b, 40);
  e.section0 = field<uint64_t>(b, 56);
  e.section0_bytes = field<uint64_t>(b, 64);
  e.section1 = field<uint64_t>(b, 72);
  e.section1_bytes = field<uint64_t>(b, 80);
  e.stack_entries = field<uint32_t>(b, 88);
  if (e.format != 1 && e.format != 2) throw Failure(path + ": unknown format " + std::to_string(e.format));
  if (e.width != 4 && e.width != 8) throw Failure(path + ": width " + std::to_string(e.width));
  if (e.triangles > 1) throw Failure(path + ": unknown triangle layout " + std::to_string(e.triangles));
  auto in_file = [&](size_t offset, size_t bytes) { return offset % 64 == 0 && offset <= b.size() && bytes <= b.size() - offset; };
  if (!in_file(e.section0, e.section0_bytes) || !in_file(e.section1, e.section1_bytes))
    throw Failure(path + ": a section lies outside the file (truncated?)");
  uint64_t sum = fnv1a(kFnvBasis, b.data(), 120);
  sum = fnv1a(sum, b.data() + e.section0, e.section0_bytes);
  sum = fnv1a(sum, b.data() + e.section1, e.section1_bytes);
  if (sum != field<uint64_t>(b, 120)) throw Failure(path + ": checksum mismatch");
  if (e.format == 2 && (e.width != 8 || e.section0_bytes != 80 * e.nodes || e.section1_bytes % 48 != 0))
    throw Failure(path + ": cwbvh sections do not match the node count");
  return e;
}

// ---- Ray, box and triangle tests ----------------------------------------------------------

constexpr float kLargest = 3.40282347e+38f;
// Slab distances are scaled up by a few ulps (Ize 2013) so rounding never culls a box the
// ray touches; boxes are already padded in the file.
constexpr float kExitScale = 1.0f + 2.0f * (3.0f * 0x1p-24f / (1.0f - 3.0f * 0x1p-24f));

struct RayData {
  Ray ray;
  float rdir[3];
  // The triangle test runs on dir * t_scale, a power of two bringing the largest component
  // to [0.5, 1) (exact; its determinant would otherwise be a cube of the scene's scale).
  float sdir[3];
  float t_scale;
};

RayData prepare(const Ray& ray) {
  RayData r{ray, {}, {}, 1.0f};
  const float biggest = std::max(std::fabs(ray.dir[0]), std::max(std::fabs(ray.dir[1]), std::fabs(ray.dir[2])));
  if (biggest > 0.0f && std::isfinite(biggest)) {
    int e = 0;
    std::frexp(biggest, &e);
    r.t_scale = std::ldexp(1.0f, -std::clamp(e, -126, 127));
  }
  for (int a = 0; a < 3; ++a) r.sdir[a] = ray.dir[a] * r.t_scale;
  for (int a = 0; a < 3; ++a) {
    float c = ray.dir[a];
    // A zero component becomes tiny (sign kept): finite inverse, no 0 * inf.
    if (std::fabs(c) < biggest * 1e-20f) c = std::signbit(c) ? -biggest * 1e-20f : biggest * 1e-20f;
    r.rdir[a] = 1.0f / c;
  }
  return r;
}

// Whether the box is entered within [tmin, limit]; its entry distance goes to `tnear`.
bool slab(const RayData& r, const float lo[3], const float hi[3], float limit, float& tnear) {
  float tn = r.ray.tmin, tf = limit;
  for (int a = 0; a < 3; ++a) {
    float t0 = (lo[a] - r.ray.org[a]) * r.rdir[a], t1 = (hi[a] - r.ray.org[a]) * r.rdir[a];
    if (r.rdir[a] < 0.0f) std::swap(t0, t1);
    tn = std::max(tn, t0);
    tf = std::min(tf, t1);
  }
  tnear = tn;
  return tn <= tf * kExitScale;
}

struct Best {
  float t, u = 0.0f, v = 0.0f;
  uint32_t id = 0xffffffffu;
};

// Moller-Trumbore in the operation order the format documents (its reference test), so it
// rounds exactly as bvhopt's tracer; t must lie in [tmin, best.t], ties go to the lower id.
bool triangle(const RayData& r, const float v0[3], const float e1[3], const float e2[3], uint32_t id, Best& best) {
  const float* d = r.sdir;
  const float p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]};
  const float det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
  const float adet = std::fabs(det);
  const bool flip = std::signbit(det);
  const float s[3] = {r.ray.org[0] - v0[0], r.ray.org[1] - v0[1], r.ray.org[2] - v0[2]};
  float uu = s[0] * p[0] + s[1] * p[1] + s[2] * p[2];
  const float q[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]};
  float vv = d[0] * q[0] + d[1] * q[1] + d[2] * q[2];
  if (flip) uu = -uu, vv = -vv;
  if (!(det != 0.0f && uu >= 0.0f && vv >= 0.0f && uu + vv <= adet)) return false;
  const float inv = 1.0f / adet;
  // e2 . (q / det), not (e2 . q) / det, which overflows a float for large scenes.
  const float sinv = flip ? -inv : inv;
  const float t = (e2[0] * (q[0] * sinv) + e2[1] * (q[1] * sinv) + e2[2] * (q[2] * sinv)) * r.t_scale;
  if (!(t >= r.ray.tmin && t <= best.t)) return false;
  if (t < best.t || id < best.id) best = {t, uu * inv, vv * inv, id};
  return true;
}

// A triangle given as three vertices, or as v0 and two edges (triangle layout 0).
bool triangle_rows(const RayData& r, const float a[3], const float b[3], const float c[3], bool edges, uint32_t id,
                   Best& best) {
  if (edges) return triangle(r, a, b, c, id, best);
  const float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  return triangle(r, a, e1, e2, id, best);
}

// ---- Traversal ----------------------------------------------------------------------------

struct Entry {
  uint32_t node;   // flat: a child word; cwbvh: a node index or a first triangle
  uint32_t count;  // cwbvh leaves: triangles (0: an inner node)
  float t;
};

// Pushes the entered children farthest first, so the nearest is popped next.
void push_sorted(std::vector<Entry>& stack, Entry* entered, int n) {
  std::sort(entered, entered + n, [](const Entry& a, const Entry& b) { return a.t > b.t; });
  stack.insert(stack.end(), entered, entered + n);
}

// Format flat: nodes and 4-triangle blocks in one arena, addressed in 32-byte units.
class FlatTracer {
 public:
  explicit FlatTracer(const Export& e) : e_(e), arena_(e.file.data() + e.section0) {}

  bool trace(const Ray& ray, bool any_hit, Best& best) const {
    const RayData r = prepare(ray);
    best = Best{ray.tmax < kLargest ? ray.tmax : kLargest};
    bool found = false;
    std::vector<Entry> stack{{e_.root, 0, ray.tmin}};
    while (!stack.empty()) {
      const Entry top = stack.back();
      stack.pop_back();
      if (top.t > best.t) continue;
      if (top.node & 0x80000000u) {
        found |= leaf(r, top.node, best, any_hit);
        if (found && any_hit) return true;
        continue;
      }
      Entry entered[8];
      int n = 0;
      const size_t node = unit(top.node);
      const uint32_t w = e_.width;
      for (uint32_t c = 0; c < w; ++c) {
        const uint32_t word = get<uint32_t>(node + 4 * (6 * w + c));
        if (word == 0xffffffffu) continue;
        float lo[3], hi[3], tnear;
        for (int a = 0; a < 3; ++a) {
          lo[a] = get<float>(node + 4 * ((2 * a) * w + c));
          hi[a] = get<float>(node + 4 * ((2 * a + 1) * w + c));
        }
        if (slab(r, lo, hi, best.t, tnear)) entered[n++] = {word, 0, tnear};
      }
      push_sorted(stack, entered, n);
    }
    return found;
  }

 private:
  static size_t unit(uint32_t word) { return size_t(word & 0x07ffffffu) * 32; }
  template <class T>
  T get(size_t offset) const {
    if (offset + sizeof(T) > e_.section0_bytes) throw Failure("a read past the arena's end");
    T v;
    std::memcpy(&v, arena_ + offset, sizeof v);
    return v;
  }

  bool leaf(const RayData& r, uint32_t word, Best& best, bool any_hit) const {
    const uint32_t blocks = ((word >> 27) & 15u) + 1;
    bool found = false;
    for (uint32_t k = 0; k < blocks; ++k) {
      const size_t block = size_t(word & 0x07ffffffu) * 32 + 160 * k;
      for (uint32_t lane = 0; lane < 4; ++lane) {
        float row[9];
        for (int i = 0; i < 9; ++i) row[i] = get<float>(block + 4 * (4 * i + lane));
        const uint32_t id = get<uint32_t>(block + 144 + 4 * lane);
        found |= triangle_rows(r, row, row + 3, row + 6, e_.triangles == 0, id, best);
        if (found && any_hit) return true;
      }
    }
    return found;
  }

  const Export& e_;
  const unsigned char* arena_;
};

// Format cwbvh: 80-byte nodes with quantized child boxes, and 48-byte triangles.
class CwbvhTracer {
 public:
  explicit CwbvhTracer(const Export& e)
      : e_(e), nodes_(e.file.data() + e.section0), tris_(e.file.data() + e.section1), triangles_(e.section1_bytes / 48) {}

  bool trace(const Ray& ray, bool any_hit, Best& best) const {
    const RayData r = prepare(ray);
    best = Best{ray.tmax < kLargest ? ray.tmax : kLargest};
    bool found = false;
    std::vector<Entry> stack{{0, 0, ray.tmin}};
    while (!stack.empty()) {
      const Entry top = stack.back();
      stack.pop_back();
      if (top.t > best.t) continue;
      if (top.count != 0) {
        for (uint32_t i = 0; i < top.count; ++i) found |= leaf_triangle(r, top.node + i, best);
        if (found && any_hit) return true;
        continue;
      }
      if (top.node >= e_.nodes) throw Failure("a child index past the last node");
      const unsigned char* n = nodes_ + 80 * size_t(top.node);
      float origin[3], scale[3];
      std::memcpy(origin, n, 12);
      for (int a = 0; a < 3; ++a) {
        const uint32_t bits = uint32_t(n[12 + a]) << 23;  // the exponent byte as a float's exponent field
        std::memcpy(&scale[a], &bits, 4);
      }
      const uint32_t inner_mask = n[15], child_base = field32(n + 16), triangle_base = field32(n + 20);
      Entry entered[8];
      int k = 0;
      for (uint32_t slot = 0; slot < 8; ++slot) {
        const uint8_t meta = n[24 + slot];
        if (meta == 0) continue;
        float lo[3], hi[3], tnear;
        for (int a = 0; a < 3; ++a) {
          lo[a] = origin[a] + float(n[32 + 8 * a + slot]) * scale[a];
          hi[a] = origin[a] + float(n[56 + 8 * a + slot]) * scale[a];
        }
        if (!slab(r, lo, hi, best.t, tnear)) continue;
        if (inner_mask & (1u << slot)) {
          const uint32_t below = uint32_t(__builtin_popcount(inner_mask & ((1u << slot) - 1)));
          entered[k++] = {child_base + below, 0, tnear};
        } else {
          entered[k++] = {triangle_base + (meta & 31u), uint32_t(__builtin_popcount(meta >> 5)), tnear};
        }
      }
      push_sorted(stack, entered, k);
    }
    return found;
  }

 private:
  static uint32_t field32(const unsigned char* p) {
    uint32_t v;
    std::memcpy(&v, p, 4);
    return v;
  }
  bool leaf_triangle(const RayData& r, uint32_t index, Best& best) const {
    if (index >= triangles_) throw Failure("a leaf triangle past the last one");
    float v[12];
    std::memcpy(v, tris_ + 48 * size_t(index), 48);  // v0 x y z id, v1 x y z pad, v2 x y z pad
    return triangle_rows(r, v, v + 4, v + 8, false, field32(tris_ + 48 * size_t(index) + 12), best);
  }

  const Export& e_;
  const unsigned char* nodes_;
  const unsigned char* tris_;
  size_t triangles_;
};

template <class Tracer>
std::string trace_all(const Tracer& tracer, const RaySet& set, size_t& hits) {
  std::string out;
  char line[128];
  for (const Ray& ray : set.rays) {
    Best best{0.0f};
    const bool hit = tracer.trace(ray, set.any_hit, best);
    hits += hit ? 1 : 0;
    if (set.any_hit) {
      out += hit ? "hit\n" : "miss\n";
    } else if (!hit) {
      out += "miss\n";
    } else {
      std::snprintf(line, sizeof line, "%u %a %a %a\n", best.id, double(best.t), double(best.u), double(best.v));
      out += line;
    }
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: wide_reader EXPORT_FILE RAY_FILE HITS_FILE\n");
    return 2;
  }
  try {
    const Export e = read_export(argv[1]);
    const RaySet set = read_rays(argv[2]);
    size_t hits = 0;
    const std::string text = e.format == 1 ? trace_all(FlatTracer(e), set, hits) : trace_all(CwbvhTracer(e), set, hits);
    std::ofstream out(argv[3], std::ios::binary | std::ios::trunc);
    out << text;
    out.close();
    if (!out) throw Failure(std::string(argv[3]) + ": write failed");
    std::printf("%s: %s, %u-wide, %llu nodes; %zu rays, %zu hit\n", argv[1], e.format == 1 ? "flat" : "cwbvh", e.width,
                static_cast<unsigned long long>(e.nodes), set.rays.size(), hits);
  } catch (const std::exception& ex) {
    std::fprintf(stderr, "wide_reader: %s\n", ex.what());
    return 1;
  }
  return 0;
}
