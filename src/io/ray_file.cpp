// The binary ray file (docs/ray-file-format.md): a 64-byte header and the rays as stored
// in memory, checksummed so a damaged file is refused rather than traced.
#include "bvhopt/ray_file.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>

#include "bvhopt/atomic_file.h"
#include "bvhopt/error.h"
#include "io/fnv1a.h"
#include "io/regular_file.h"

namespace bvhopt {
namespace {

static_assert(std::endian::native == std::endian::little, "ray files are little-endian; add byte swapping");

using detail::fnv1a;
using detail::kFnvBasis;

constexpr char kMagic[8] = {'B', 'V', 'H', 'O', 'R', 'A', 'Y', 'S'};
constexpr size_t kHeaderSize = 64;

struct Header {
  char magic[8];
  uint32_t version;
  uint32_t kind;
  uint32_t query;
  uint32_t width;
  uint32_t height;
  uint32_t reserved0;
  uint64_t seed;
  uint64_t count;
  uint64_t checksum;  // FNV-1a 64 over bytes 0..47 of the header, then the payload
  uint64_t reserved1;
};
static_assert(sizeof(Header) == kHeaderSize);

uint64_t checksum_of(const Header& h, const std::vector<Ray>& rays) {
  uint64_t c = fnv1a(kFnvBasis, &h, 48);
  return fnv1a(c, rays.data(), rays.size() * sizeof(Ray));
}

}  // namespace

void write_ray_file(const std::filesystem::path& path, const RaySet& set) {
  Header h{};
  std::memcpy(h.magic, kMagic, 8);
  h.version = kRayFileVersion;
  h.kind = static_cast<uint32_t>(set.kind);
  h.query = static_cast<uint32_t>(set.query);
  h.width = set.width;
  h.height = set.height;
  h.seed = set.seed;
  h.count = set.rays.size();
  h.checksum = checksum_of(h, set.rays);
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path.string() + ": cannot create temporary file " + tmp.string());
    out.write(reinterpret_cast<const char*>(&h), sizeof h);
    out.write(reinterpret_cast<const char*>(set.rays.data()), std::streamsize(set.rays.size() * sizeof(Ray)));
    out.close();
    if (!out) throw Error(path.string() + ": write failed (disk full or no permission?)");
  });
}

RaySet read_ray_file(const std::filesystem::path& path) {
  const std::string name = path.string();
  require_regular_file(path, "ray file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(name + ": cannot open ray file (missing or unreadable)");
  in.seekg(0, std::ios::end);
  const uint64_t size = static_cast<uint64_t>(in.tellg());
  in.seekg(0);
  if (size < kHeaderSize)
    throw Error(name + ": " + std::to_string(size) + " bytes, too short for the 64-byte ray file header");
  Header h;
  in.read(reinterpret_cast<char*>(&h), sizeof h);
  if (std::memcmp(h.magic, kMagic, 8) != 0) throw Error(name + ": offset 0: not a bvhopt ray file (wrong magic)");
  if (h.version == 0 || h.version > kRayFileVersion)
    throw Error(name + ": offset 8: ray file version " + std::to_string(h.version) + ", this program reads up to " +
                std::to_string(kRayFileVersion));
  if (h.kind > static_cast<uint32_t>(RayKind::shadow))
    throw Error(name + ": offset 12: unknown ray kind " + std::to_string(h.kind));
  if (h.query > 1) throw Error(name + ": offset 16: unknown ray query " + std::to_string(h.query));
  const uint64_t payload = size - kHeaderSize;
  if (h.count > payload / sizeof(Ray) || payload != h.count * sizeof(Ray))
    throw Error(name + ": header says " + std::to_string(h.count) + " rays (" + std::to_string(h.count * 32) +
                " bytes after the header) but the file has " + std::to_string(payload) +
                " (truncated or trailing bytes)");
  RaySet set;
  set.kind = static_cast<RayKind>(h.kind);
  set.query = static_cast<RayQuery>(h.query);
  set.width = h.width;
  set.height = h.height;
  set.seed = h.seed;
  set.rays.resize(h.count);
  in.read(reinterpret_cast<char*>(set.rays.data()), std::streamsize(h.count * sizeof(Ray)));
  if (!in) throw Error(name + ": read failed in the ray records");
  if (checksum_of(h, set.rays) != h.checksum) throw Error(name + ": checksum mismatch (the file is corrupt)");
  if (set.kind == RayKind::primary && set.width != 0 && uint64_t(set.width) * set.height != h.count)
    throw Error(name + ": offset 20: primary image " + std::to_string(set.width) + "x" + std::to_string(set.height) +
                " does not match " + std::to_string(h.count) + " rays");
  for (size_t i = 0; i < set.rays.size(); ++i) {
    const Ray& r = set.rays[i];
    const bool ok = is_finite(r.org) && is_finite(r.dir) && !(r.dir == Vec3(0.0f)) && std::isfinite(r.tmin) &&
                    !std::isnan(r.tmax) && r.tmin <= r.tmax;
    if (!ok)
      throw Error(name + ": ray " + std::to_string(i) + " (offset " + std::to_string(kHeaderSize + 32 * i) +
                  "): not traceable (non-finite value, zero direction or tmin > tmax)");
  }
  return set;
}

}  // namespace bvhopt
