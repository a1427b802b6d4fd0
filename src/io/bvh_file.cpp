#include "bvhopt/bvh_file.h"

#include <unistd.h>

#include <bit>
#include <cmath>
#include <utility>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include "bvhopt/error.h"
#include "bvhopt/geometry_fingerprint.h"
#include "bvhopt/validate.h"
#include "bvhopt/atomic_file.h"
#include "bvhopt/testing/bvh_file_checksum.h"
#include "io/regular_file.h"
#include "tree/huge_pages.h"

// The layout is described byte for byte in docs/file-format.md; keep the two in step.

namespace bvhopt {
namespace {

// PNG's trick: a high-bit byte catches 7-bit transfers, CR LF catches CR LF <-> LF
// conversion, ^Z stops a DOS `type`, the final LF catches LF -> CR LF.
constexpr unsigned char kMagic[8] = {0x89, 'B', 'V', 'H', '\r', '\n', 0x1a, '\n'};
constexpr uint64_t kFixedHeaderSize = 80;  // up to and including the scene name's length
constexpr uint64_t kNodeRecord = 32;       // 6 floats + 2 uint32
constexpr uint64_t kSlotRecord = 4;
constexpr uint64_t kRefRecord = 28;        // 6 floats + 1 uint32
constexpr uint64_t kChecksumSize = 8;
constexpr uint64_t kFingerprintSize = 8;   // version 2: after the method string
constexpr uint64_t kMaxCount = 0xffffffffu;  // node and reference indices are 32-bit
constexpr size_t kIoChunk = size_t(1) << 20;

// ---- Little-endian encoding, whatever the host -------------------------------------

template <class T>
T to_le(T v) {
  if constexpr (std::endian::native == std::endian::big) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    std::memcpy(&v, b, sizeof(T));
  }
  return v;
}

template <class T>
void store(unsigned char* p, T v) {
  v = to_le(v);
  std::memcpy(p, &v, sizeof(T));
}
template <class T>
T load(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return to_le(v);  // the swap is its own inverse
}

void store_box(unsigned char* p, const Box& b) {
  store(p + 0, b.min.x);
  store(p + 4, b.min.y);
  store(p + 8, b.min.z);
  store(p + 12, b.max.x);
  store(p + 16, b.max.y);
  store(p + 20, b.max.z);
}
Box load_box(const unsigned char* p) {
  return Box(Vec3(load<float>(p + 0), load<float>(p + 4), load<float>(p + 8)),
             Vec3(load<float>(p + 12), load<float>(p + 16), load<float>(p + 20)));
}

// ---- Checksum ----------------------------------------------------------------------
// FNV-1a's xor-then-multiply, but on 64-bit words in four independent lanes (so the
// multiplies overlap and a gigabyte hashes in a fraction of a second) with an xorshift
// after each multiply (so high bits feed back into low ones). Every step is a bijection
// of the lane state, so changing any one word always changes the result.
class Checksum {
 public:
  static constexpr uint64_t kBasis = 0xcbf29ce484222325ull;  // FNV-1a 64 offset basis
  static constexpr uint64_t kMul = 0x9e3779b97f4a7c15ull;

  void update(const unsigned char* p, size_t n) {
    if (n == 0) return;
    total_ += n;
    if (pending_ > 0) {
      const size_t take = std::min(n, sizeof block_ - pending_);
      std::memcpy(block_ + pending_, p, take);
      pending_ += take;
      p += take;
      n -= take;
      if (pending_ < sizeof block_) return;
      mix_block(block_);
      pending_ = 0;
    }
    for (; n >= 32; p += 32, n -= 32) mix_block(p);
    std::memcpy(block_, p, n);
    pending_ = n;
  }

  uint64_t finish() const {
    uint64_t lanes[4] = {lane_[0], lane_[1], lane_[2], lane_[3]};
    // Whole words of the last partial block go to lanes 0, 1, 2; a last partial word is
    // zero-padded and goes to the next lane. The length, mixed in below, tells padding
    // from real zeros.
    size_t k = 0;
    for (size_t off = 0; off < pending_; off += 8, ++k) {
      unsigned char w[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      std::memcpy(w, block_ + off, std::min<size_t>(8, pending_ - off));
      lanes[k] = step(lanes[k], load<uint64_t>(w));
    }
    uint64_t h = total_;
    for (uint64_t l : lanes) h = step(h, l);
    h ^= h >> 29;
    h *= 0xbf58476d1ce4e5b9ull;
    h ^= h >> 32;
    return h;
  }

 private:
  static uint64_t step(uint64_t h, uint64_t w) {
    h = (h ^ w) * kMul;
    return h ^ (h >> 32);
  }
  void mix_block(const unsigned char* p) {
    lane_[0] = step(lane_[0], load<uint64_t>(p));
    lane_[1] = step(lane_[1], load<uint64_t>(p + 8));
    lane_[2] = step(lane_[2], load<uint64_t>(p + 16));
    lane_[3] = step(lane_[3], load<uint64_t>(p + 24));
  }

  uint64_t lane_[4] = {kBasis, kBasis + 1, kBasis + 2, kBasis + 3};
  unsigned char block_[32] = {};
  size_t pending_ = 0;
  uint64_t total_ = 0;
};

std::string sys_error(int err) { return std::generic_category().message(err); }

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// ---- Writing -----------------------------------------------------------------------

class Writer {
 public:
  Writer(std::FILE* f, const std::string& name) : f_(f), name_(name) { buf_.reserve(kIoChunk); }

  // Room for `n` bytes at the end of the buffer; the caller fills them.
  unsigned char* reserve(size_t n) {
    if (buf_.size() + n > kIoChunk) flush();
    size_t at = buf_.size();
    buf_.resize(at + n);
    return buf_.data() + at;
  }
  void bytes(const void* p, size_t n) {
    const unsigned char* c = static_cast<const unsigned char*>(p);
    while (n > 0) {
      size_t take = std::min(n, kIoChunk);
      std::memcpy(reserve(take), c, take);
      c += take;
      n -= take;
    }
  }
  void flush() {
    if (buf_.empty()) return;
    if (hashing_) sum_.update(buf_.data(), buf_.size());
    if (std::fwrite(buf_.data(), 1, buf_.size(), f_) != buf_.size())
      throw Error(name_ + ": write failed: " + sys_error(errno));
    buf_.clear();
  }
  // Everything written so far is covered by the checksum; what follows is not.
  uint64_t end_checksum() {
    flush();
    hashing_ = false;
    return sum_.finish();
  }

 private:
  std::FILE* f_;
  const std::string& name_;
  std::vector<unsigned char> buf_;
  Checksum sum_;
  bool hashing_ = true;
};

std::vector<unsigned char> encode_header(uint32_t root, uint64_t nodes, uint64_t refs, uint64_t slots,
                                         const BvhFileInfo& info) {
  const uint64_t header_size = kFixedHeaderSize + info.scene_name.size() + 4 + info.method.size() + kFingerprintSize;
  std::vector<unsigned char> h(header_size, 0);
  unsigned char* p = h.data();
  std::memcpy(p, kMagic, 8);
  store<uint32_t>(p + 8, kBvhFileVersion);
  store<uint32_t>(p + 12, static_cast<uint32_t>(header_size));
  store<uint32_t>(p + 16, 0);  // flags: none defined
  store<uint32_t>(p + 20, root);
  store<uint64_t>(p + 24, nodes);
  store<uint64_t>(p + 32, refs);
  store<uint64_t>(p + 40, slots);
  store<double>(p + 48, info.cost.traversal);
  store<double>(p + 56, info.cost.intersection);
  store<uint64_t>(p + 64, info.scene_triangles);
  store<uint32_t>(p + 72, 0);  // reserved
  store<uint32_t>(p + 76, static_cast<uint32_t>(info.scene_name.size()));
  std::memcpy(p + 80, info.scene_name.data(), info.scene_name.size());
  unsigned char* q = p + 80 + info.scene_name.size();
  store<uint32_t>(q, static_cast<uint32_t>(info.method.size()));
  std::memcpy(q + 4, info.method.data(), info.method.size());
  store<uint64_t>(q + 4 + info.method.size(), info.geometry_fingerprint);
  return h;
}

void write_contents(std::FILE* f, const std::string& name, const Bvh& bvh, const PrimitiveRefs& refs,
                    const BvhFileInfo& info) {
  const std::vector<uint32_t> order = bvh.depth_first_order();
  std::vector<uint32_t> new_index(bvh.nodes.size(), kInvalidNode);
  for (uint32_t i = 0; i < order.size(); ++i) new_index[order[i]] = i;
  uint64_t slots = 0;
  for (uint32_t n : order)
    if (bvh[n].is_leaf()) slots += bvh[n].ref_count();

  Writer w(f, name);
  const std::vector<unsigned char> header =
      encode_header(order.empty() ? kInvalidNode : 0, order.size(), refs.size(), slots, info);
  w.bytes(header.data(), header.size());

  // Nodes as Bvh::renumber_depth_first() would renumber them: depth-first, leaf slots in leaf order.
  uint32_t next_slot = 0;
  for (uint32_t n : order) {
    const BvhNode& nd = bvh[n];
    unsigned char* p = w.reserve(kNodeRecord);
    store_box(p, nd.box);
    if (nd.is_leaf()) {
      store<uint32_t>(p + 24, next_slot);
      store<uint32_t>(p + 28, nd.ref_count() | BvhNode::kLeafFlag);
      next_slot += nd.ref_count();
    } else {
      store<uint32_t>(p + 24, new_index[nd.left()]);
      store<uint32_t>(p + 28, new_index[nd.right()]);
    }
  }
  for (uint32_t n : order) {
    const BvhNode& nd = bvh[n];
    if (!nd.is_leaf()) continue;
    for (uint32_t k = 0; k < nd.ref_count(); ++k) store<uint32_t>(w.reserve(kSlotRecord), bvh.ref_indices[nd.first_ref() + k]);
  }
  for (size_t r = 0; r < refs.size(); ++r) {
    unsigned char* p = w.reserve(kRefRecord);
    store_box(p, refs.boxes[r]);
    store<uint32_t>(p + 24, refs.triangle_ids[r]);
  }
  const uint64_t sum = w.end_checksum();
  unsigned char tail[8];
  store<uint64_t>(tail, sum);
  if (std::fwrite(tail, 1, 8, f) != 8) throw Error(name + ": write failed: " + sys_error(errno));
}

// ---- Reading -----------------------------------------------------------------------

class Reader {
 public:
  Reader(std::FILE* f, const std::string& name) : f_(f), name_(name) {}
  // Reads exactly n bytes (the caller has checked the file is long enough) and hashes them.
  void read(unsigned char* p, size_t n, bool hash = true) {
    if (std::fread(p, 1, n, f_) != n) {
      if (std::ferror(f_)) throw Error(name_ + ": read failed: " + sys_error(errno));
      throw Error(name_ + ": truncated: file ended while reading (it shrank while being read?)");
    }
    if (hash) sum_.update(p, n);
  }
  uint64_t checksum() const { return sum_.finish(); }

 private:
  std::FILE* f_;
  const std::string& name_;
  Checksum sum_;
};

}  // namespace

uint64_t bvh_file_checksum(const void* data, uint64_t size) {
  Checksum sum;
  sum.update(static_cast<const unsigned char*>(data), static_cast<size_t>(size));
  return sum.finish();
}

void write_bvh_file(const std::filesystem::path& path, const Bvh& bvh, const PrimitiveRefs& refs,
                    const BvhFileInfo& info) {
  const std::string name = path.string();
  // The reader validates every tree; writing one it would refuse helps nobody.
  ValidationReport report = validate(bvh, refs, ValidationOptions{.allow_dropped_duplicates = true});
  if (!report.ok()) throw Error(name + ": refusing to write an invalid tree: " + report.summary());
  if (refs.size() > kMaxCount) throw Error(name + ": too many references for the format");
  if (info.scene_name.size() > kMaxCount || info.method.size() > kMaxCount)
    throw Error(name + ": scene name or method too long");

  write_atomically(path, [&](const std::filesystem::path& tmp) {
    FilePtr f(std::fopen(tmp.c_str(), "wb"));
    if (!f) throw Error(name + ": cannot create temporary file " + tmp.string() + ": " + sys_error(errno));
    std::setvbuf(f.get(), nullptr, _IONBF, 0);  // Writer buffers in 1 MiB chunks already
    write_contents(f.get(), name, bvh, refs, info);
    if (std::fflush(f.get()) != 0 || std::ferror(f.get())) throw Error(name + ": write failed: " + sys_error(errno));
    if (std::fclose(f.release()) != 0) throw Error(name + ": closing the file failed: " + sys_error(errno));
  });
}

namespace {

// The counts and sizes of the header, as read and range-checked.
struct Header {
  uint64_t header_size = 0;
  uint32_t flags = 0;
  uint32_t root = 0;
  uint64_t node_count = 0, ref_count = 0, slot_count = 0;
};

// The fixed header, the scene and method names, and the header bytes this version does not
// know; fills `info`. Every size is checked against the file's before anything is
// allocated, so a bogus count costs an error message, not a huge allocation.
Header read_header(Reader& in, const std::string& name, uint64_t file_size, BvhFileInfo& info) {
  auto truncated = [&](uint64_t expected, const std::string& what) {
    return Error(name + ": truncated: expected " + std::to_string(expected) + " bytes" + what + ", file has " +
                 std::to_string(file_size));
  };

  unsigned char fixed[kFixedHeaderSize];
  const size_t magic_have = static_cast<size_t>(std::min<uint64_t>(file_size, 8));
  in.read(fixed, magic_have);
  if (file_size == 0) throw Error(name + ": empty file, not a bvhopt BVH file");
  if (std::memcmp(fixed, kMagic, magic_have) != 0)
    throw Error(name + ": not a bvhopt BVH file (wrong magic bytes)");
  if (file_size < kFixedHeaderSize) throw truncated(kFixedHeaderSize, " at least (the fixed header)");
  in.read(fixed + 8, kFixedHeaderSize - 8);

  const uint32_t version = load<uint32_t>(fixed + 8);
  if (version > kBvhFileVersion)
    throw Error(name + ": written by a newer bvhopt: version " + std::to_string(version) + ", this reads up to " +
                std::to_string(kBvhFileVersion));
  if (version == 0) throw Error(name + ": corrupt header: version 0 does not exist");
  Header h;
  h.header_size = load<uint32_t>(fixed + 12);
  h.flags = load<uint32_t>(fixed + 16);
  h.root = load<uint32_t>(fixed + 20);
  h.node_count = load<uint64_t>(fixed + 24);
  h.ref_count = load<uint64_t>(fixed + 32);
  h.slot_count = load<uint64_t>(fixed + 40);
  info.cost.traversal = load<double>(fixed + 48);
  info.cost.intersection = load<double>(fixed + 56);
  info.scene_triangles = load<uint64_t>(fixed + 64);
  const uint64_t name_len = load<uint32_t>(fixed + 76);

  if (kFixedHeaderSize + name_len + 4 > file_size)
    throw truncated(kFixedHeaderSize + name_len + 4, " at least (header with a scene name of " +
                                                         std::to_string(name_len) + " bytes)");
  info.scene_name.resize(name_len);
  in.read(reinterpret_cast<unsigned char*>(info.scene_name.data()), name_len);
  unsigned char len4[4];
  in.read(len4, 4);
  const uint64_t method_len = load<uint32_t>(len4);
  const uint64_t strings_end = kFixedHeaderSize + name_len + 4 + method_len;
  if (strings_end > file_size)
    throw truncated(strings_end, " at least (header with a method name of " + std::to_string(method_len) + " bytes)");
  info.method.resize(method_len);
  in.read(reinterpret_cast<unsigned char*>(info.method.data()), method_len);
  // Version 2 adds the geometry fingerprint after the method string.
  const uint64_t known_end = strings_end + (version >= 2 ? kFingerprintSize : 0);
  if (known_end > file_size)
    throw truncated(known_end, " at least (header with the geometry fingerprint)");
  if (h.header_size < known_end)
    throw Error(name + ": corrupt header: header size " + std::to_string(h.header_size) +
                " is smaller than its contents (" + std::to_string(known_end) + " bytes)");
  if (version >= 2) {
    unsigned char fp[kFingerprintSize];
    in.read(fp, kFingerprintSize);
    info.geometry_fingerprint = load<uint64_t>(fp);
  }

  if (h.node_count > kMaxCount || h.ref_count > kMaxCount || h.slot_count > kMaxCount)
    throw Error(name + ": corrupt header: counts out of range (" + std::to_string(h.node_count) + " nodes, " +
                std::to_string(h.slot_count) + " leaf slots, " + std::to_string(h.ref_count) +
                " references; at most 4294967295 each)");
  // No overflow: each count is below 2^32 and each record at most 32 bytes.
  const uint64_t expected = h.header_size + h.node_count * kNodeRecord + h.slot_count * kSlotRecord +
                            h.ref_count * kRefRecord + kChecksumSize;
  const std::string counts = " (header: " + std::to_string(h.node_count) + " nodes, " +
                             std::to_string(h.slot_count) + " leaf slots, " + std::to_string(h.ref_count) +
                             " references)";
  if (file_size < expected) throw truncated(expected, counts);
  if (file_size > expected)
    throw Error(name + ": corrupt: expected " + std::to_string(expected) + " bytes" + counts + ", file has " +
                std::to_string(file_size) + " (trailing data)");

  // Header bytes this version does not know (a later minor addition) are skipped.
  std::vector<unsigned char> chunk(kIoChunk);
  for (uint64_t left = h.header_size - known_end; left > 0;) {
    size_t take = static_cast<size_t>(std::min<uint64_t>(left, chunk.size()));
    in.read(chunk.data(), take);
    left -= take;
  }
  return h;
}

// Reads `count` records of `record_size` bytes a chunk at a time, handing each to
// `take(index, bytes)`: the file is never held in memory twice.
template <class TakeRecord>
void read_in_chunks(Reader& in, std::vector<unsigned char>& chunk, uint64_t count, size_t record_size,
                    const TakeRecord& take) {
  const size_t per_chunk = chunk.size() / record_size;
  for (uint64_t i = 0; i < count;) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(count - i, per_chunk));
    in.read(chunk.data(), n * record_size);
    for (size_t k = 0; k < n; ++k) take(i + k, chunk.data() + k * record_size);
    i += n;
  }
}

// The node, slot and reference records, hashed as they are read, then the checksum: a
// flipped byte is reported as corruption rather than as whatever it broke.
void read_records(Reader& in, const std::string& name, const Header& h, Bvh& bvh, PrimitiveRefs& refs) {
  std::vector<unsigned char> chunk(kIoChunk);
  detail::reserve_on_huge_pages(bvh.nodes, h.node_count);
  bvh.nodes.resize(h.node_count);
  read_in_chunks(in, chunk, h.node_count, kNodeRecord, [&](uint64_t i, const unsigned char* p) {
    BvhNode& nd = bvh.nodes[i];
    nd.set_box(load_box(p));
    nd.left_or_first = load<uint32_t>(p + 24);
    nd.right_or_count = load<uint32_t>(p + 28);
  });
  detail::reserve_on_huge_pages(bvh.ref_indices, h.slot_count);
  bvh.ref_indices.resize(h.slot_count);
  read_in_chunks(in, chunk, h.slot_count, kSlotRecord,
                 [&](uint64_t i, const unsigned char* p) { bvh.ref_indices[i] = load<uint32_t>(p); });
  refs.resize(h.ref_count);
  read_in_chunks(in, chunk, h.ref_count, kRefRecord, [&](uint64_t i, const unsigned char* p) {
    refs.boxes[i] = load_box(p);
    refs.centroids[i] = refs.boxes[i].center();
    refs.triangle_ids[i] = load<uint32_t>(p + 24);
  });
  const uint64_t computed = in.checksum();
  unsigned char tail[8];
  in.read(tail, 8, false);
  if (load<uint64_t>(tail) != computed) throw Error(name + ": corrupt: checksum mismatch");
}

// Children must follow their parent (depth-first order, hence no cycles) and stay in
// range; each node gets at most one parent, whose link is set here, and every node but the
// root gets one. Leaves hold slots in range.
void link_parents(const std::string& name, const Header& h, Bvh& bvh) {
  for (uint64_t i = 0; i < h.node_count; ++i) {
    BvhNode& nd = bvh.nodes[i];
    auto where = [&] { return name + ": node " + std::to_string(i) + ": "; };  // only on failure
    if (nd.is_leaf()) {
      const uint64_t first = nd.first_ref(), count = nd.ref_count();
      if (count == 0) throw Error(where() + "leaf holds no references");
      if (first + count > h.slot_count)
        throw Error(where() + "leaf slots [" + std::to_string(first) + ", " + std::to_string(first + count) +
                    ") out of range (" + std::to_string(h.slot_count) + " slots)");
      continue;
    }
    for (int side = 0; side < 2; ++side) {
      const uint64_t c = nd.child(side);
      const char* which = side == 0 ? "left" : "right";
      if (c >= h.node_count)
        throw Error(where() + which + " child " + std::to_string(c) + " out of range (" +
                    std::to_string(h.node_count) + " nodes)");
      if (c <= i)
        throw Error(where() + which + " child " + std::to_string(c) +
                    " does not follow its parent (nodes must be stored depth-first)");
      BvhNode& child = bvh.nodes[c];
      if (child.parent != kInvalidNode)
        throw Error(name + ": node " + std::to_string(c) + " is a child of both node " + std::to_string(child.parent) +
                    " and node " + std::to_string(i));
      child.parent = static_cast<uint32_t>(i);
    }
  }
  // Writers store only what the root reaches; a node without a parent is extra content (and
  // could hold slots a reachable leaf also claims).
  for (uint64_t i = 1; i < h.node_count; ++i)
    if (bvh.nodes[i].parent == kInvalidNode)
      throw Error(name + ": node " + std::to_string(i) + ": unreachable from the root (no node has it as a child)");
}

// After the checksum: flags, cost constants, root, links, and every index the records hold.
void check_references(const std::string& name, const Header& h, BvhFile& out) {
  Bvh& bvh = out.bvh;
  const PrimitiveRefs& refs = out.refs;
  if (h.flags != 0) throw Error(name + ": unsupported flags 0x" + [&] {
                             char b[16];
                             std::snprintf(b, sizeof b, "%x", h.flags);
                             return std::string(b);
                           }() + " (no flag is defined)");
  if (h.node_count == 0 ? h.root != kInvalidNode : h.root != 0)
    throw Error(name + ": corrupt: root " + std::to_string(h.root) +
                " (nodes are stored depth-first: the root is node 0" +
                std::string(h.node_count == 0 ? ", and an empty tree has none)" : ")"));
  // A negative or non-finite constant turns every cost comparison into nonsense (c_I = -2 makes
  // one leaf look cheapest); the checksum cannot tell, so the value is checked.
  for (const auto& [value, what] : {std::pair{out.info.cost.traversal, "c_T"}, std::pair{out.info.cost.intersection, "c_I"}})
    if (!std::isfinite(value) || value < 0)
      throw Error(name + ": corrupt header: cost constant " + what + " = " + std::to_string(value) +
                  " (must be a finite number >= 0)");
  bvh.root = h.root;
  link_parents(name, h, bvh);
  for (uint64_t s = 0; s < h.slot_count; ++s)
    if (bvh.ref_indices[s] >= h.ref_count)
      throw Error(name + ": leaf slot " + std::to_string(s) + " holds reference " + std::to_string(bvh.ref_indices[s]) +
                  ", out of range (" + std::to_string(h.ref_count) + " references)");
  if (out.info.scene_triangles > 0)
    for (uint64_t r = 0; r < h.ref_count; ++r)
      if (refs.triangle_ids[r] >= out.info.scene_triangles)
        throw Error(name + ": reference " + std::to_string(r) + ": triangle id " +
                    std::to_string(refs.triangle_ids[r]) + " out of range (the scene has " +
                    std::to_string(out.info.scene_triangles) + " triangles)");
}

}  // namespace

BvhFile read_bvh_file(const std::filesystem::path& path) {
  const std::string name = path.string();
  require_regular_file(path, "BVH file");
  FilePtr f(std::fopen(path.c_str(), "rb"));
  if (!f) throw Error(name + ": cannot open: " + sys_error(errno));
  std::error_code ec;
  const uint64_t file_size = std::filesystem::file_size(path, ec);
  if (ec) throw Error(name + ": cannot get the file size: " + ec.message());
  std::setvbuf(f.get(), nullptr, _IONBF, 0);  // reads come in 1 MiB chunks

  Reader in(f.get(), name);
  BvhFile out;
  const Header h = read_header(in, name, file_size, out.info);
  read_records(in, name, h, out.bvh, out.refs);
  check_references(name, h, out);
  ValidationReport report = validate(out.bvh, out.refs, ValidationOptions{.allow_dropped_duplicates = true});
  if (!report.ok()) throw Error(name + ": invalid tree: " + report.summary());
  return out;
}

}  // namespace bvhopt

namespace bvhopt {

bool has_bvh_file_magic(const std::filesystem::path& path) {
  FilePtr f(std::fopen(path.c_str(), "rb"));
  unsigned char head[sizeof kMagic];
  return f && std::fread(head, 1, sizeof head, f.get()) == sizeof head && std::memcmp(head, kMagic, sizeof head) == 0;
}

BvhFileInfo scene_info(const Mesh& mesh, const CostModel& cost, const std::string& method) {
  BvhFileInfo info;
  info.cost = cost;
  info.scene_name = mesh.name;
  info.scene_triangles = mesh.triangle_count();
  info.method = method;
  info.geometry_fingerprint = geometry_fingerprint(mesh);
  return info;
}

void check_tree_matches_scene(const std::string& file, const BvhFileInfo& info, const Mesh& mesh) {
  const std::string built = file + ": built over scene '" + info.scene_name + "' (" +
                            std::to_string(info.scene_triangles) + " triangles), ";
  const std::string hint = " (pass the scene the tree was built from, with the same --rotate)";
  if (info.scene_triangles != mesh.triangle_count())
    throw Error(built + "but scene '" + mesh.name + "' has " + std::to_string(mesh.triangle_count()) + " triangles" + hint);
  if (info.geometry_fingerprint != 0) {
    if (info.geometry_fingerprint != geometry_fingerprint(mesh))
      throw Error(built + "but scene '" + mesh.name +
                  "' has other geometry: its fingerprint differs (another scene of the same size, another "
                  "--rotate, or another built-in seed)" + hint);
    return;
  }
  // A version-1 file has no fingerprint: the name is all there is to tell scenes apart.
  if (info.scene_name != mesh.name)
    throw Error(built + "but the scene is '" + mesh.name +
                "' (the file has no geometry fingerprint, so the scene names must match)" + hint);
}

}  // namespace bvhopt
