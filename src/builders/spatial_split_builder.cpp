#include "bvhopt/spatial_split_builder.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_group.h>

// SSE2 is part of x86-64; elsewhere the object binning runs axis by axis.
#if defined(__SSE2__) || defined(_M_X64)
#include <emmintrin.h>
#define BVHOPT_SBVH_SSE 1
#endif

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "builders/sah_common.h"
#include "builders/sorted_range_sweep.h"
#include "bvhopt/error.h"
#include "bvhopt/triangle_clipping.h"

namespace bvhopt {
namespace {

constexpr uint32_t kMaxBins = 128;
constexpr size_t kBlock = 2048;  // references per block of a parallel pass (fixed: deterministic)

// The builder's working reference: the box of the part of its triangle it stands for.
struct SRef {
  Box box;
  uint32_t tri;
};
// ObjectMapping::add loads box.max as four floats, the fourth being tri.
static_assert(sizeof(Box) == 24 && offsetof(SRef, tri) == sizeof(Box));

// What a node receives from its parent: its box and the bounds of its references' centres.
struct NodeState {
  Box box;
  Box centres;
};

// A subtree: references in slots [begin, begin + count), room for `capacity` of them in
// slots [room, room + capacity) (room <= begin: a right child built by one task keeps its
// references where its parent put them while its room grows down to where its left sibling
// ended), and nodes [base, base + 2 capacity - 1) to number its nodes in (as TopDownTree's
// NodeRange, with the room for spatial splits' new references counted in).
struct Task {
  size_t room, begin, count, capacity;
  uint32_t base, parent;
  NodeState state;
};

float overlap_area(const Box& a, const Box& b) { return intersect(a, b).area(); }

// A bin's box without a constructor, so that a node's bins cost only the n it uses (the
// arrays hold room for kMaxBins; small nodes use a few).
struct BinBox {
  Vec3 min, max;
  void clear() {
    min = Vec3(std::numeric_limits<float>::infinity());
    max = Vec3(-std::numeric_limits<float>::infinity());
  }
  void extend(const Box& b) {
    min = bvhopt::min(min, b.min);
    max = bvhopt::max(max, b.max);
  }
  void extend(const BinBox& b) {
    min = bvhopt::min(min, b.min);
    max = bvhopt::max(max, b.max);
  }
  Box box() const { return Box(min, max); }
};

// An object bin's box in four lanes (x, y, z and one unused): a reference extends it by two
// vector operations instead of six scalar ones, and object binning is the build's most
// frequent loop, run at every node over all of its references. Spatial bins keep BinBox:
// bin_crossing writes their lanes one at a time, and a vector load of a bin just written
// so waits for those stores (with four-lane spatial bins armadillo's, horse's and
// classroom's builds took 6-23 % longer on one thread).
struct alignas(16) ObjectBinBox {
  float min[4], max[4];
  void clear() {
    for (int a = 0; a < 4; ++a) min[a] = std::numeric_limits<float>::infinity();
    for (int a = 0; a < 4; ++a) max[a] = -std::numeric_limits<float>::infinity();
  }
  void extend(const ObjectBinBox& b) {
    for (int a = 0; a < 4; ++a) min[a] = std::min(min[a], b.min[a]);
    for (int a = 0; a < 4; ++a) max[a] = std::max(max[a], b.max[a]);
  }
  // The reference's box.
  void extend(const SRef& r) {
#ifdef BVHOPT_SBVH_SSE
    // Lanes x, y, z of min and max; the fourth holds the next field (max.x, then the
    // reference's triangle id), which box() never reads. The new value first: SSE's min
    // returns its second operand on a tie, as std::min(acc, new) returns acc (the sign of
    // a zero stays the scalar code's).
    _mm_store_ps(min, _mm_min_ps(_mm_loadu_ps(&r.box.min.x), _mm_load_ps(min)));
    _mm_store_ps(max, _mm_max_ps(_mm_loadu_ps(&r.box.max.x), _mm_load_ps(max)));
#else
    for (int a = 0; a < 3; ++a) min[a] = std::min(min[a], r.box.min[a]);
    for (int a = 0; a < 3; ++a) max[a] = std::max(max[a], r.box.max[a]);
#endif
  }
  Box box() const { return Box(Vec3(min[0], min[1], min[2]), Vec3(max[0], max[1], max[2])); }
};

// ---- Object split: centres binned per axis over the node's centre bounds.

struct ObjectBins {
  uint32_t n;
  ObjectBinBox box[3][kMaxBins];
  uint32_t count[3][kMaxBins];
  explicit ObjectBins(uint32_t bins) { reset(bins); }
  void reset(uint32_t bins) {
    n = bins;
    for (int a = 0; a < 3; ++a) {
      std::fill(count[a], count[a] + n, 0u);
      for (uint32_t b = 0; b < n; ++b) box[a][b].clear();
    }
  }
  void merge(const ObjectBins& o) {
    for (int a = 0; a < 3; ++a)
      for (uint32_t b = 0; b < n; ++b) {
        box[a][b].extend(o.box[a][b]);
        count[a][b] += o.count[a][b];
      }
  }
};

struct ObjectMapping {
  float origin[4] = {}, scale[4] = {};  // the fourth lane for add()'s loads
  uint32_t last;
  ObjectMapping(const Box& centres, uint32_t bins) : last(bins - 1) {
    for (int a = 0; a < 3; ++a) {
      origin[a] = centres.min[a];
      const float extent = centres.max[a] - centres.min[a];
      // Slightly under bins / extent so the largest centre lands in the last bin; a
      // denormal extent would give an infinite scale: treated as flat.
      const float s = extent > 0.0f ? float(bins) * 0.99999f / extent : 0.0f;
      scale[a] = std::isfinite(s) ? s : 0.0f;
    }
  }
  uint32_t bin(const Box& b, int a) const { return bin_of_centre(b.center()[a], a); }
  // Clamped in float, then truncated: the arithmetic of add() below lane for lane (SSE's
  // max returns its second operand for a NaN), so the binning and the partition agree.
  uint32_t bin_of_centre(float c, int a) const {
    float x = (c - origin[a]) * scale[a];
    x = x > 0.0f ? x : 0.0f;
    x = x < float(last) ? x : float(last);
    return static_cast<uint32_t>(x);
  }
  // Bins the reference's box on all three axes.
  void add(ObjectBins& bins, const SRef& r) const {
    const Box& b = r.box;
#ifdef BVHOPT_SBVH_SSE
    // Lanes x, y, z of min and max; the fourth holds the next field (max.x, then the
    // reference's triangle id), which no bin box reads.
    const __m128 lo = _mm_loadu_ps(&b.min.x), hi = _mm_loadu_ps(&b.max.x);
    const __m128 centre = _mm_mul_ps(_mm_add_ps(lo, hi), _mm_set1_ps(0.5f));
    __m128 x = _mm_mul_ps(_mm_sub_ps(centre, _mm_loadu_ps(origin)), _mm_loadu_ps(scale));
    x = _mm_min_ps(_mm_max_ps(x, _mm_setzero_ps()), _mm_set1_ps(float(last)));
    const __m128i k = _mm_cvttps_epi32(x);
    const uint32_t k0 = uint32_t(_mm_cvtsi128_si32(k)), k1 = uint32_t(_mm_cvtsi128_si32(_mm_shuffle_epi32(k, 0x55))),
                   k2 = uint32_t(_mm_cvtsi128_si32(_mm_shuffle_epi32(k, 0xAA)));
    const uint32_t ks[3] = {k0, k1, k2};
    for (int a = 0; a < 3; ++a) {
      ObjectBinBox& bin = bins.box[a][ks[a]];
      _mm_store_ps(bin.min, _mm_min_ps(lo, _mm_load_ps(bin.min)));
      _mm_store_ps(bin.max, _mm_max_ps(hi, _mm_load_ps(bin.max)));
      bins.count[a][ks[a]]++;
    }
#else
    for (int a = 0; a < 3; ++a) {
      const uint32_t k = bin(b, a);
      bins.box[a][k].extend(r);
      bins.count[a][k]++;
    }
#endif
  }
};

// ---- Spatial split: the node's box cut into equal slabs per axis.

struct SpatialBins {
  uint32_t n;
  BinBox box[3][kMaxBins];
  uint32_t enter[3][kMaxBins], exit[3][kMaxBins];
  explicit SpatialBins(uint32_t bins) { reset(bins); }
  void reset(uint32_t bins) {
    n = bins;
    for (int a = 0; a < 3; ++a) {
      std::fill(enter[a], enter[a] + n, 0u);
      std::fill(exit[a], exit[a] + n, 0u);
      for (uint32_t b = 0; b < n; ++b) box[a][b].clear();
    }
  }
  void merge(const SpatialBins& o) {
    for (int a = 0; a < 3; ++a)
      for (uint32_t b = 0; b < n; ++b) {
        box[a][b].extend(o.box[a][b]);
        enter[a][b] += o.enter[a][b];
        exit[a][b] += o.exit[a][b];
      }
  }
};

// Bin boundaries as floats, so the binning and the partition compare against the very same
// planes: boundary k (0..n) is min + k * width, and n is the box's max. They are tabled once
// per node: computing them in the binning's search was most of its cost per reference.
struct SpatialMapping {
  float min[3], width[3], max[3], inv[3];
  float planes[3][kMaxBins + 1];
  uint32_t n;
  SpatialMapping(const Box& box, uint32_t bins) : n(bins) {
    for (int a = 0; a < 3; ++a) {
      min[a] = box.min[a];
      max[a] = box.max[a];
      width[a] = (box.max[a] - box.min[a]) / float(bins);
      const float i = width[a] > 0.0f ? 1.0f / width[a] : 0.0f;
      inv[a] = std::isfinite(i) ? i : 0.0f;
      for (uint32_t k = 0; k < n; ++k) planes[a][k] = min[a] + float(k) * width[a];
      planes[a][n] = max[a];
    }
  }
  bool usable(int a) const { return inv[a] > 0.0f; }
  float plane(int a, uint32_t k) const { return planes[a][std::min(k, n)]; }
  uint32_t guess(int a, float x) const {
    const int k = static_cast<int>((x - min[a]) * inv[a]);
    return static_cast<uint32_t>(std::clamp(k, 0, static_cast<int>(n - 1)));
  }
  // The bin a box starting at x enters: the last k with plane(k) <= x.
  uint32_t enter_bin(int a, float x) const {
    const float* p = planes[a];
    uint32_t k = guess(a, x);
    while (k > 0 && x < p[k]) --k;
    while (k + 1 < n && x >= p[k + 1]) ++k;
    return k;
  }
  // The bin a box ending at x leaves: the first k with x <= plane(k + 1).
  uint32_t exit_bin(int a, float x) const {
    const float* p = planes[a];
    uint32_t k = guess(a, x);
    while (k > 0 && x <= p[k]) --k;
    while (k + 1 < n && x > p[k + 1]) ++k;
    return k;
  }
};

struct Split {
  enum Kind { none, object, spatial, halve, sweep } kind = none;
  int axis = -1;
  uint32_t bin = 0;  // first bin of the right side
  float cost = std::numeric_limits<float>::infinity();
  Box left, right;   // the bins' estimate of the children's boxes
  uint32_t left_count = 0, right_count = 0;
  std::vector<uint8_t> left_flag;  // sweep: per position in the node, 1 if it goes left
};

// Per side, what a partition pass found.
struct Sides {
  size_t left = 0, right = 0, cut = 0, unsplit = 0;
  NodeState l, r;
  void add(const Sides& o) {
    left += o.left, right += o.right, cut += o.cut, unsplit += o.unsplit;
    l.box.extend(o.l.box), l.centres.extend(o.l.centres);
    r.box.extend(o.r.box), r.centres.extend(o.r.centres);
  }
};

// The bounds of n references' boxes and of their centres, as Box::extend would give them.
NodeState bounds_of(const SRef* refs, size_t n) {
  NodeState b;
#ifdef BVHOPT_SBVH_SSE
  // Four running bounds in registers, no branch (lanes as in ObjectBinBox::extend(const SRef&)).
  __m128 lo = _mm_set1_ps(std::numeric_limits<float>::infinity()), hi = _mm_sub_ps(_mm_setzero_ps(), lo);
  __m128 clo = lo, chi = hi;
  const __m128 half = _mm_set1_ps(0.5f);
  for (size_t i = 0; i < n; ++i) {
    const __m128 l = _mm_loadu_ps(&refs[i].box.min.x), h = _mm_loadu_ps(&refs[i].box.max.x);
    const __m128 c = _mm_mul_ps(_mm_add_ps(l, h), half);
    lo = _mm_min_ps(l, lo), hi = _mm_max_ps(h, hi);
    clo = _mm_min_ps(c, clo), chi = _mm_max_ps(c, chi);
  }
  alignas(16) float out[4][4];
  _mm_store_ps(out[0], lo), _mm_store_ps(out[1], hi), _mm_store_ps(out[2], clo), _mm_store_ps(out[3], chi);
  b.box = Box(Vec3(out[0][0], out[0][1], out[0][2]), Vec3(out[1][0], out[1][1], out[1][2]));
  b.centres = Box(Vec3(out[2][0], out[2][1], out[2][2]), Vec3(out[3][0], out[3][1], out[3][2]));
#else
  for (size_t i = 0; i < n; ++i) {
    b.box.extend(refs[i].box);
    b.centres.extend(refs[i].box.center());
  }
#endif
  return b;
}

// What the splits of a task did, for SpatialSplitStats.
struct alignas(64) SplitCounts {
  size_t spatial = 0, object = 0, cut = 0, unsplit = 0;
};

// A partition's scratch: each reference's pieces and sides, and each block's counts.
struct PartitionScratch {
  std::vector<SRef> whole, left, right;  // the node's references; pieces of the cut ones
  std::vector<uint8_t> side;
  std::vector<Sides> per_block;
  std::vector<size_t> left_at, right_at;
  void reserve(size_t count, size_t blocks) {
    if (whole.size() < count) whole.resize(count), left.resize(count), right.resize(count), side.resize(count);
    reserve_blocks(blocks);
  }
  void reserve_blocks(size_t blocks) {
    if (left_at.size() < blocks) left_at.resize(blocks), right_at.resize(blocks);
    per_block.assign(blocks, Sides{});
  }
};

// Raw storage for types whose members have initializers, to be written in parallel (or
// only where used) rather than constructed by one thread.
struct FreeStorage {
  void operator()(void* p) const { ::operator delete(p); }
};
template <class T>
std::unique_ptr<T[], FreeStorage> uninitialized_array(size_t n) {
  return std::unique_ptr<T[], FreeStorage>(static_cast<T*>(::operator new(n * sizeof(T))));
}

class SpatialSplitBuilder {
 public:
  SpatialSplitBuilder(const Mesh& mesh, const PrimitiveRefs& refs, const SpatialSplitConfig& config,
                      SpatialSplitResult& out)
      : mesh_(mesh), refs_(refs), config_(config), out_(out) {}

  void run() {
    const size_t n = refs_.size();
    capacity_ = std::max(n, static_cast<size_t>(std::floor(config_.budget * double(mesh_.triangle_count()))));
    check_reference_count(capacity_, "spatial-split builder");
    slots_.reset(new SRef[capacity_]);
    NodeState root = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, n, kBlock), NodeState{},
        [&](const tbb::blocked_range<size_t>& r, NodeState acc) {
          for (size_t i = r.begin(); i < r.end(); ++i) {
            slots_[i] = SRef{refs_.boxes[i], refs_.triangle_ids[i]};
            acc.box.extend(refs_.boxes[i]);
            acc.centres.extend(refs_.boxes[i].center());
          }
          return acc;
        },
        [](NodeState a, const NodeState& b) {
          a.box.extend(b.box);
          a.centres.extend(b.centres);
          return a;
        });
    root_area_ = root.box.area();
    // Room for every node a subtree might make, never built unless marked: filled in
    // parallel (as a vector, one thread wrote all of each of them).
    work_size_ = 2 * capacity_ - 1;
    work_ = uninitialized_array<BvhNode>(work_size_);
    if (parallel(n)) {  // no node holds more references than the root
      parallel_scratch_.whole = uninitialized_array<SRef>(capacity_);
      parallel_scratch_.left = uninitialized_array<SRef>(capacity_);
      parallel_scratch_.right = uninitialized_array<SRef>(capacity_);
      parallel_scratch_.side = uninitialized_array<uint8_t>(capacity_);
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, work_size_, kBlock), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) new (&work_[i]) BvhNode{};
    });
    build(Task{0, 0, n, capacity_, 0, kInvalidNode, root});
    tasks_.wait();
    parallel_scratch_ = {};
    compact();
    SpatialSplitStats& s = out_.stats;
    s.input_references = n;
    s.references = out_.refs.size();
    s.budget = capacity_;
    for (const SplitCounts& c : counts_) {
      s.spatial_splits += c.spatial;
      s.object_splits += c.object;
      s.split_references += c.cut;
      s.unsplit_references += c.unsplit;
    }
  }

 private:
  // The loop of TopDownTree::build, over tasks that carry their room for new references.
  // Nodes of fewer than parallel_threshold references are built by one task, packed.
  void build(Task t) {
    SplitCounts counts;
    for (;;) {
      if (t.count < config_.parallel_threshold) {
        add_counts(counts);
        build_packed(t);
        return;
      }
      BvhNode& node = work_[t.base];
      node.parent = t.parent;
      node.set_box(t.state.box);
      Task l, r;
      if (!split(t, node.area(), l, r, counts)) {
        add_counts(counts);
        make_leaf(node, t);
        return;
      }
      node.make_inner(l.base, r.base);
      const bool left_smaller = l.count < r.count;
      const Task small = left_smaller ? l : r;
      tasks_.run([this, small] { build(small); });
      t = left_smaller ? r : l;
    }
  }

  // A subtree built by one task, depth first, left before right, its references packed at
  // the start of its slots and its nodes numbered in order from its root: the room a left
  // subtree leaves unused goes to its right sibling instead of being lost (with a fixed
  // range per child, Sponza used 1.188 references per triangle of 1.3, 2CylinderEngine
  // 1.242; packed, 1.267 and 1.283, at 1.1 and 1.1 % lower cost). The right child's
  // references stay where the partition wrote them, its room reaching down to the left
  // one's end (Task::room): they move only when it is split or made a leaf. The order is
  // fixed, so the tree is still the same on any number of threads. A subtree that ends up
  // with u references has at most 2u - 1 nodes, so a right sibling placed after the left
  // one's last node and slot still fits the range its parent was given.
  void build_packed(Task t) {
    struct Pending {
      size_t at, count, end;  // the right child's references, and the end of its room
      uint32_t parent;
      NodeState state;
    };
    std::vector<Pending> pending;  // local: split() may wait in oneTBB and run another subtree here
    size_t cursor = t.room;        // first free slot
    uint32_t next_node = t.base;
    SplitCounts counts;
    for (;;) {
      const uint32_t index = next_node++;
      t.base = index;
      BvhNode& node = work_[index];
      node.parent = t.parent;
      node.set_box(t.state.box);
      Task l, r;
      if (split(t, node.area(), l, r, counts)) {
        pending.push_back(Pending{r.begin, r.count, t.room + t.capacity, index, r.state});
        l.parent = index;
        t = l;
        continue;
      }
      cursor += make_leaf(node, t);
      if (pending.empty()) {
        add_counts(counts);
        return;
      }
      const Pending p = pending.back();
      pending.pop_back();
      work_[p.parent].make_inner(p.parent + 1, next_node);
      t = Task{cursor, p.at, p.count, p.end - cursor, next_node, p.parent, p.state};
    }
  }

  // A leaf holds each triangle once: pieces of one triangle merge into one reference.
  size_t make_leaf(BvhNode& node, const Task& t) {
    SRef* s = slots_.get() + t.begin;
    if (t.count > 1) std::sort(s, s + t.count, [](const SRef& a, const SRef& b) { return a.tri < b.tri; });
    size_t kept = 0;
    for (size_t i = 0; i < t.count; ++i) {
      if (kept > 0 && s[kept - 1].tri == s[i].tri)
        s[kept - 1].box.extend(s[i].box);
      else
        s[kept++] = s[i];
    }
    if (t.room != t.begin) std::copy(s, s + kept, slots_.get() + t.room);
    node.make_leaf(static_cast<uint32_t>(t.room), static_cast<uint32_t>(kept));
    return kept;
  }

  uint32_t object_bin_count(size_t count) const {
    const size_t bins = std::clamp<size_t>(count / 256, config_.object_bins, std::max<uint32_t>(config_.object_bins, kMaxBins));
    return static_cast<uint32_t>(std::max<size_t>(2, std::min<size_t>(bins, 4 + count / 5)));
  }

  // A node of n references cuts its box into min(spatial_bins, 4 + n / 2) slabs: near the
  // leaves each reference crosses most of 32 slabs, and binning its pieces there was half
  // the build, for splits that more bins than references rarely improve (on staircase,
  // Sponza, Conference and bunny the cost even fell slightly, by 0.02-0.2 %).
  uint32_t spatial_bin_count(size_t count) const {
    return static_cast<uint32_t>(std::min<size_t>(config_.spatial_bins, 4 + count / 2));
  }

  bool parallel(size_t count) const { return count >= config_.parallel_binning_threshold; }

  // Runs body(begin, end) over the node's references in fixed blocks (min, max and integer
  // sums merge exactly in any grouping). Each body of oneTBB's imperative form keeps bins of
  // its own on the heap (tasks run on this thread meanwhile may reuse `acc`'s storage) and
  // is merged once: the functional form copied 12 KB of bins into and out of every block.
  template <class Acc, class Body>
  void reduce(const Task& t, Acc& acc, const Body& body) const {
    if (!parallel(t.count)) {
      body(acc, t.begin, t.begin + t.count);
      return;
    }
    struct Reducer {
      const Body& body;
      uint32_t n;
      std::unique_ptr<Acc> bins;
      Reducer(const Body& b, uint32_t bin_count) : body(b), n(bin_count), bins(new Acc(bin_count)) {}
      Reducer(Reducer& o, tbb::split) : Reducer(o.body, o.n) {}
      void operator()(const tbb::blocked_range<size_t>& r) { body(*bins, r.begin(), r.end()); }
      void join(Reducer& o) { bins->merge(*o.bins); }
    };
    Reducer reducer(body, acc.n);
    tbb::parallel_reduce(tbb::blocked_range<size_t>(t.begin, t.begin + t.count, kBlock), reducer);
    acc = *reducer.bins;
  }

  // Small nodes: the exact sweep over the references sorted by centre on each axis (ties by
  // position in the node, so the order is unique), as the sweep builder does.
  Split find_sweep_split(const Task& t) const {
    thread_local std::vector<uint32_t> order;
    thread_local std::vector<float> key, suffix;
    const size_t n = t.count;
    order.resize(n);
    key.resize(n);
    suffix.resize(n);
    const SRef* s = slots_.get() + t.begin;
    auto sort_axis = [&](int a) {
      for (size_t i = 0; i < n; ++i) {
        order[i] = static_cast<uint32_t>(i);
        key[i] = s[i].box.min[a] + s[i].box.max[a];
      }
      std::sort(order.begin(), order.end(),
                [&](uint32_t x, uint32_t y) { return key[x] < key[y] || (key[x] == key[y] && x < y); });
    };
    detail::SweepCandidate best;
    int best_axis = -1;
    for (int a = 0; a < 3; ++a) {
      sort_axis(a);
      const detail::SweepCandidate c = detail::sweep_sorted_range(
          n, [&](Box& b, size_t k) { b.extend(s[order[k]].box); }, [&](size_t k) -> float& { return suffix[k]; });
      if (best_axis < 0 || detail::better_candidate(c, best)) best = c, best_axis = a;
    }
    Split split;
    split.kind = Split::sweep;
    split.axis = best_axis;
    split.cost = best.cost;
    split.left_count = static_cast<uint32_t>(best.left_count);
    split.right_count = static_cast<uint32_t>(n - best.left_count);
    sort_axis(best_axis);
    split.left_flag.assign(n, 0);
    for (size_t k = 0; k < n; ++k) {
      const Box& b = s[order[k]].box;
      if (k < best.left_count) {
        split.left_flag[order[k]] = 1;
        split.left.extend(b);
      } else {
        split.right.extend(b);
      }
    }
    return split;
  }

  // A node of two references, the commonest (a third of all nodes): the split binning and
  // the sweep would find, without clearing and sweeping bins. On each axis the two centres
  // either share a bin (no split) or the lower one goes left; the cost is the sweep's own
  // arithmetic (the left area in double, the right one stored as float), and the first
  // axis of the lowest cost wins (both sides hold one: every balance ties).
  Split find_pair_split(const Task& t) const {
    const ObjectMapping m(t.state.centres, object_bin_count(2));
    const Box& b0 = slots_[t.begin].box;
    const Box& b1 = slots_[t.begin + 1].box;
    const Vec3 c0 = b0.center(), c1 = b1.center();
    const double area0 = b0.area(), area1 = b1.area();
    const float cost_0_left = static_cast<float>(area0 + double(static_cast<float>(area1)));
    const float cost_1_left = static_cast<float>(area1 + double(static_cast<float>(area0)));
    Split best;
    best.kind = Split::object;
    bool first_left = true;
    for (int a = 0; a < 3; ++a) {
      const uint32_t k0 = m.bin_of_centre(c0[a], a), k1 = m.bin_of_centre(c1[a], a);
      if (k0 == k1) continue;
      const float c = k0 < k1 ? cost_0_left : cost_1_left;
      if (c < best.cost) best.axis = a, best.bin = std::min(k0, k1) + 1, best.cost = c, first_left = k0 < k1;
    }
    if (best.axis < 0) return best;
    best.left = first_left ? b0 : b1;
    best.right = first_left ? b1 : b0;
    best.left_count = best.right_count = 1;
    return best;
  }

  Split find_object_split(const Task& t) const {
    if (t.count <= config_.exact_sweep_below) return find_sweep_split(t);
    if (t.count == 2) return find_pair_split(t);
    const uint32_t nb = object_bin_count(t.count);
    const ObjectMapping m(t.state.centres, nb);
    // 13 KB kept per thread rather than cleared whole at every node. A task oneTBB runs on
    // this thread while it waits in reduce() may use them too, but reduce() assigns the
    // result only after, and nothing here waits between that and the sweep.
    thread_local std::unique_ptr<ObjectBins> storage;
    if (!storage) storage.reset(new ObjectBins(nb));
    ObjectBins& bins = *storage;
    bins.reset(nb);
    reduce(t, bins, [&](ObjectBins& acc, size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) m.add(acc, slots_[i]);
    });
    Split best;
    best.kind = Split::object;
    sweep_bins(nb, best, [&](int a, uint32_t k) { return bins.box[a][k].box(); },
               [&](int a, uint32_t k) { return bins.count[a][k]; }, [&](int a, uint32_t k) { return bins.count[a][k]; },
               std::numeric_limits<size_t>::max());
    return best;
  }

  // The SAH sweep over bins, for both kinds: left of boundary k are the bins below it.
  // `entering(a, k)` counts the references that start in bin k, `leaving(a, k)` those that
  // end there (the same for object bins). Splits whose two sides hold more than `room`
  // references are skipped. Ties go to the more balanced split, then the lower axis and bin.
  template <class BoxOf, class Entering, class Leaving>
  void sweep_bins(uint32_t nb, Split& best, const BoxOf& box_of, const Entering& entering, const Leaving& leaving,
                  size_t room, const SpatialMapping* usable = nullptr) const {
    float right_area[kMaxBins];
    uint32_t right_count[kMaxBins];
    bool active[kMaxBins];
    uint32_t best_balance = std::numeric_limits<uint32_t>::max();
    for (int a = 0; a < 3; ++a) {
      if (usable && !usable->usable(a)) continue;
      Box right;
      uint32_t rc = 0;
      float area = 0.0f;  // an empty box's
      for (uint32_t k = nb - 1; k > 0; --k) {
        // A bin nothing enters, leaves or passes through changes neither side: the area
        // stays, and the boundary above it is the same split as the one below, which the
        // left sweep has judged already (small nodes leave most of their bins empty; the
        // sweep was a sixth of the build, most of it areas in double).
        const Box b = box_of(a, k);
        const uint32_t leave = leaving(a, k);
        active[k] = !b.is_empty() || leave != 0 || entering(a, k) != 0;
        if (active[k]) {
          right.extend(b);
          rc += leave;
          area = static_cast<float>(right.area());
        }
        right_area[k] = area;
        right_count[k] = rc;
      }
      Box left;
      uint32_t lc = 0;
      for (uint32_t k = 1; k < nb; ++k) {
        if (k > 1 && !active[k - 1]) continue;
        left.extend(box_of(a, k - 1));
        lc += entering(a, k - 1);
        if (lc == 0 || right_count[k] == 0 || size_t(lc) + right_count[k] > room) continue;
        const float c = left.area() * float(lc) + right_area[k] * float(right_count[k]);
        const uint32_t balance = lc > right_count[k] ? lc - right_count[k] : right_count[k] - lc;
        if (c < best.cost || (c == best.cost && balance < best_balance)) {
          best.axis = a;
          best.bin = k;
          best.cost = c;
          best.left_count = lc;
          best.right_count = right_count[k];
          best_balance = balance;
        }
      }
    }
    if (best.axis < 0) return;
    best.left = best.right = Box();
    for (uint32_t k = 0; k < nb; ++k) (k < best.bin ? best.left : best.right).extend(box_of(best.axis, k));
  }

  Triangle triangle(uint32_t tri) const { return mesh_.triangle(tri); }

  // Adds a reference crossing bins [enter, exit] of axis a: each slab's piece of its triangle
  // (bounded within the reference's box) goes to its bin. The reference enters at its first
  // non-empty piece and leaves at its last. The bins only estimate the split's cost, so the
  // pieces are bounded in float (the partition cuts the chosen split's references exactly,
  // with slice_triangle): a piece is bounded by the triangle's sections at its slab's planes
  // and the corners between them. With the corners sorted on the axis, a section is the
  // segment from the long edge (first to last corner) to a short one, and the first corner
  // lies in the first piece, the last in the last (the reference's box lies within the
  // triangle's), the middle one in the piece its position falls in.
  void bin_crossing(SpatialBins& bins, const SpatialMapping& m, int a, const SRef& r, const Triangle& tri,
                    uint32_t enter, uint32_t exit) const {
    // Sorted by rank (ties by corner order) rather than by swaps: no branch to mispredict.
    const float x0 = tri.v0[a], x1 = tri.v1[a], x2 = tri.v2[a];
    Vec3 c[3];
    c[int(x0 > x1) + int(x0 > x2)] = tri.v0;
    c[int(x1 >= x0) + int(x1 > x2)] = tri.v1;
    c[int(x2 >= x0) + int(x2 >= x1)] = tri.v2;
    const int u = a == 2 ? 0 : a + 1, w = a == 0 ? 2 : a - 1;
    // An edge too short for its inverse in float counts as flat: its sections are its start
    // (an estimate still inside the triangle, never a NaN from 0 * infinity).
    auto inverse = [](float d) {
      const float inv = d > 0.0f ? 1.0f / d : 0.0f;
      return std::isfinite(inv) ? inv : 0.0f;
    };
    const float inv_long = inverse(c[2][a] - c[0][a]), inv_low = inverse(c[1][a] - c[0][a]),
                inv_high = inverse(c[2][a] - c[1][a]);
    // Corners as scalars, so the loops below are plain float arithmetic the compiler can
    // vectorize (this was the build's hottest function, a quarter of classroom's time).
    const float c0a = c[0][a], c1a = c[1][a];
    const float c0u = c[0][u], c1u = c[1][u], c2u = c[2][u];
    const float c0w = c[0][w], c1w = c[1][w], c2w = c[2][w];
    const uint32_t cuts = exit - enter;
    // Piece k is bounded by sections k and k + 1: section 0 is the first corner, section
    // cuts + 1 the last, those between are the triangle's sections at the planes, so no
    // piece needs a case of its own (the middle corner is added to its piece below).
    float sa[kMaxBins + 1], ulo[kMaxBins + 1], uhi[kMaxBins + 1], wlo[kMaxBins + 1], whi[kMaxBins + 1];
    sa[0] = c0a, ulo[0] = uhi[0] = c0u, wlo[0] = whi[0] = c0w;
    sa[cuts + 1] = c[2][a], ulo[cuts + 1] = uhi[cuts + 1] = c2u, wlo[cuts + 1] = whi[cuts + 1] = c2w;
    const float* planes = m.planes[a] + enter + 1;
    uint32_t middle = 0;  // the piece of the middle corner: the planes below it
    for (uint32_t j = 0; j < cuts; ++j) {
      const float x = planes[j];
      const float tl = std::min(std::max((x - c0a) * inv_long, 0.0f), 1.0f);
      const bool low = x <= c1a;
      const float s0a = low ? c0a : c1a, inv = low ? inv_low : inv_high;
      const float s0u = low ? c0u : c1u, s1u = low ? c1u : c2u;
      const float s0w = low ? c0w : c1w, s1w = low ? c1w : c2w;
      const float ts = std::min(std::max((x - s0a) * inv, 0.0f), 1.0f);
      const float lu = c0u + tl * (c2u - c0u), lw = c0w + tl * (c2w - c0w);
      const float su = s0u + ts * (s1u - s0u), sw = s0w + ts * (s1w - s0w);
      sa[j + 1] = x;
      ulo[j + 1] = std::min(lu, su), uhi[j + 1] = std::max(lu, su);
      wlo[j + 1] = std::min(lw, sw), whi[j + 1] = std::max(lw, sw);
      middle += x < c1a;
    }
    const float rlo_a = r.box.min[a], rhi_a = r.box.max[a], rlo_u = r.box.min[u], rhi_u = r.box.max[u],
                rlo_w = r.box.min[w], rhi_w = r.box.max[w];
    uint32_t first = kMaxBins, last = 0;
    BinBox* bin = bins.box[a] + enter;
    for (uint32_t k = 0; k <= cuts; ++k) {
      float alo = std::min(sa[k], sa[k + 1]), ahi = std::max(sa[k], sa[k + 1]);
      float blo = std::min(ulo[k], ulo[k + 1]), bhi = std::max(uhi[k], uhi[k + 1]);
      float clo = std::min(wlo[k], wlo[k + 1]), chi = std::max(whi[k], whi[k + 1]);
      if (k == middle) {
        alo = std::min(alo, c1a), ahi = std::max(ahi, c1a);
        blo = std::min(blo, c1u), bhi = std::max(bhi, c1u);
        clo = std::min(clo, c1w), chi = std::max(chi, c1w);
      }
      alo = std::max(alo, rlo_a), ahi = std::min(ahi, rhi_a);
      blo = std::max(blo, rlo_u), bhi = std::min(bhi, rhi_u);
      clo = std::max(clo, rlo_w), chi = std::min(chi, rhi_w);
      if (alo > ahi || blo > bhi || clo > chi) continue;
      BinBox& b = bin[k];
      b.min[a] = std::min(b.min[a], alo), b.max[a] = std::max(b.max[a], ahi);
      b.min[u] = std::min(b.min[u], blo), b.max[u] = std::max(b.max[u], bhi);
      b.min[w] = std::min(b.min[w], clo), b.max[w] = std::max(b.max[w], chi);
      first = std::min(first, enter + k);
      last = enter + k;
    }
    if (first == kMaxBins) {  // no piece inside the reference's box: count it whole
      bins.box[a][enter].extend(r.box);
      first = last = enter;
    }
    bins.enter[a][first]++;
    bins.exit[a][last]++;
  }

  Split find_spatial_split(const Task& t) const {
    const uint32_t nb = spatial_bin_count(t.count);
    const SpatialMapping m(t.state.box, nb);
    thread_local std::unique_ptr<SpatialBins> storage;  // as find_object_split's
    if (!storage) storage.reset(new SpatialBins(nb));
    SpatialBins& bins = *storage;
    bins.reset(nb);
    reduce(t, bins, [&](SpatialBins& acc, size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) {
        const SRef& r = slots_[i];
        uint32_t enter[3], exit[3];
        bool crossing = false;
        for (int a = 0; a < 3; ++a) {
          if (!m.usable(a)) continue;
          enter[a] = m.enter_bin(a, r.box.min[a]);
          exit[a] = std::max(enter[a], m.exit_bin(a, r.box.max[a]));
          if (enter[a] == exit[a]) {
            acc.box[a][enter[a]].extend(r.box);
            acc.enter[a][enter[a]]++;
            acc.exit[a][exit[a]]++;
          } else {
            crossing = true;
          }
        }
        if (!crossing) continue;
        const Triangle tri = triangle(r.tri);
        for (int a = 0; a < 3; ++a)
          if (m.usable(a) && enter[a] != exit[a]) bin_crossing(acc, m, a, r, tri, enter[a], exit[a]);
      }
    });
    Split best;
    best.kind = Split::spatial;
    sweep_bins(nb, best, [&](int a, uint32_t k) { return bins.box[a][k].box(); },
               [&](int a, uint32_t k) { return bins.enter[a][k]; }, [&](int a, uint32_t k) { return bins.exit[a][k]; },
               t.capacity, &m);
    return best;
  }

  // Whether an object split's overlap is large enough to try a spatial split: against the
  // root's area (the paper's alpha) and the node's own (node_alpha).
  bool worth_spatial(float overlap, double node_area) const {
    return overlap > float(config_.alpha) * root_area_ && double(overlap) > config_.node_alpha * node_area;
  }

  // Chooses the node's split (false: make it a leaf) and partitions its references.
  bool split(const Task& t, double node_area, Task& l, Task& r, SplitCounts& counts) {
    if (t.count <= 1) return false;
    Split object = find_object_split(t);
    Split spatial;
    const bool room = t.capacity > t.count && t.count >= config_.spatial_from &&
                      (config_.spatial_max == 0 || t.count <= config_.spatial_max);
    if (room && (object.axis < 0 || worth_spatial(overlap_area(object.left, object.right), node_area)))
      spatial = find_spatial_split(t);
    const bool use_spatial = spatial.axis >= 0 && spatial.cost < object.cost;
    if (use_spatial || object.axis >= 0) {
      const Split& s = use_spatial ? spatial : object;
      if (detail::sah_prefers_leaf(config_, node_area, t.count, s.cost)) return false;
      if (use_spatial && partition(t, spatial, l, r, counts)) return true;
      if (object.axis >= 0) {
        if (use_spatial && detail::sah_prefers_leaf(config_, node_area, t.count, object.cost)) return false;
        partition(t, object, l, r, counts);
        return true;
      }
    }
    // No plane separates the references (their centres coincide): halve them in slot order.
    Split halve;
    halve.kind = Split::halve;
    halve.bin = static_cast<uint32_t>(t.count / 2);
    const SRef* s = slots_.get() + t.begin;
    for (size_t i = 0; i < t.count; ++i) (i < halve.bin ? halve.left : halve.right).extend(s[i].box);
    halve.cost = halve.left.area() * float(halve.bin) + halve.right.area() * float(t.count - halve.bin);
    if (detail::sah_prefers_leaf(config_, node_area, t.count, halve.cost)) return false;
    partition(t, halve, l, r, counts);
    return true;
  }

  // Where a reference goes: bit 1 left, bit 2 right; with bit 4 its pieces are in `left` and
  // `right` (written only then), without it the reference goes whole.
  static constexpr uint8_t kLeft = 1, kRight = 2, kPieces = 4;
  uint8_t classify(const Split& s, const SpatialMapping* m, const ObjectMapping* om, size_t index, const SRef& ref,
                   SRef& left, SRef& right, Sides& sides) const {
    switch (s.kind) {
      case Split::halve:
        return index < s.bin ? kLeft : kRight;
      case Split::object:
        return om->bin(ref.box, s.axis) < s.bin ? kLeft : kRight;
      case Split::sweep:
        return s.left_flag[index] ? kLeft : kRight;
      default:
        break;
    }
    const int a = s.axis;
    const uint32_t enter = m->enter_bin(a, ref.box.min[a]);
    const uint32_t exit = std::max(enter, m->exit_bin(a, ref.box.max[a]));
    if (exit < s.bin) return kLeft;
    if (enter >= s.bin) return kRight;
    const float plane = m->plane(a, s.bin);
    left = right = ref;
    Box pieces[2];
    slice_triangle(triangle(ref.tri), a, &plane, 1, pieces);
    left.box = intersect(pieces[0], ref.box);
    right.box = intersect(pieces[1], ref.box);
    if (left.box.is_empty() && right.box.is_empty())  // rounding lost both pieces: keep the reference whole
      return enter < s.bin ? kLeft : kRight;
    if (left.box.is_empty()) return kRight | kPieces;
    if (right.box.is_empty()) return kLeft | kPieces;
    // Unsplitting: the whole reference on one side, if that costs less than cutting it
    // (each reference judged against the split's own boxes and counts, so the order in
    // which they are judged does not matter).
    const float nl = float(s.left_count), nr = float(s.right_count);
    const float al = s.left.area(), ar = s.right.area();
    const float c_split = al * nl + ar * nr;
    const float c_left = merge(s.left, ref.box).area() * nl + ar * (nr - 1.0f);
    const float c_right = al * (nl - 1.0f) + merge(s.right, ref.box).area() * nr;
    if (c_left < c_split && c_left <= c_right) {
      ++sides.unsplit;
      return kLeft;
    }
    if (c_right < c_split) {
      ++sides.unsplit;
      return kRight;
    }
    ++sides.cut;
    return kLeft | kRight | kPieces;
  }

  // Two passes over fixed blocks: each reference's pieces go to a scratch copy and each
  // block counts its sides; then, with the children's room known, the pieces are written
  // back, left ones from the node's first slot and right ones from the right child's.
  // False (nothing changed) when a side would be empty or the node's room too small.
  bool partition(const Task& t, const Split& s, Task& l, Task& r, SplitCounts& counts) {
    if (s.kind != Split::spatial && !parallel(t.count)) return partition_whole(t, s, l, r, counts);
    const SpatialMapping m(t.state.box, spatial_bin_count(t.count));
    const ObjectMapping om(t.state.centres, object_bin_count(t.count));
    const size_t blocks = (t.count + kBlock - 1) / kBlock;
    // A serial partition takes its scratch from its thread (nothing else runs on the thread
    // meanwhile); a parallel one waits in parallel_for, where this thread may run another.
    // A parallel one takes the part of the build's scratch arrays that matches its slots,
    // which no other node uses meanwhile (allocated per partition and constructed by one
    // thread, they were a twentieth of classroom's build).
    PartitionScratch own;
    thread_local PartitionScratch reused;
    const bool in_parallel = parallel(t.count);
    PartitionScratch& scratch = in_parallel ? own : reused;
    SRef *left, *right, *whole;
    uint8_t* side;
    if (in_parallel) {
      scratch.reserve_blocks(blocks);
      left = parallel_scratch_.left.get() + t.room;
      right = parallel_scratch_.right.get() + t.room;
      whole = parallel_scratch_.whole.get() + t.room;
      side = parallel_scratch_.side.get() + t.room;
    } else {
      scratch.reserve(t.count, blocks);
      left = scratch.left.data(), right = scratch.right.data(), whole = scratch.whole.data();
      side = scratch.side.data();
    }
    Sides* per_block = scratch.per_block.data();
    auto classify_block = [&](size_t b) {
      Sides& sides = per_block[b];
      const size_t end = std::min(t.count, (b + 1) * kBlock);
      for (size_t i = b * kBlock; i < end; ++i) {
        const SRef& ref = slots_[t.begin + i];
        whole[i] = ref;
        const uint8_t to = classify(s, &m, &om, i, ref, left[i], right[i], sides);
        side[i] = to;
        if (to & kLeft) {
          const Box& box = to & kPieces ? left[i].box : ref.box;
          ++sides.left;
          sides.l.box.extend(box);
          sides.l.centres.extend(box.center());
        }
        if (to & kRight) {
          const Box& box = to & kPieces ? right[i].box : ref.box;
          ++sides.right;
          sides.r.box.extend(box);
          sides.r.centres.extend(box.center());
        }
      }
    };
    if (parallel(t.count))
      tbb::parallel_for(size_t(0), blocks, classify_block);
    else
      for (size_t b = 0; b < blocks; ++b) classify_block(b);
    Sides total;
    size_t* left_at = scratch.left_at.data();
    size_t* right_at = scratch.right_at.data();
    for (size_t b = 0; b < blocks; ++b) {
      left_at[b] = total.left;
      right_at[b] = total.right;
      total.add(per_block[b]);
    }
    if (total.left == 0 || total.right == 0 || total.left + total.right > t.capacity) return false;

    const size_t left_room = left_room_of(t, total);
    auto write_block = [&](size_t b) {
      SRef* lo = slots_.get() + t.room + left_at[b];
      SRef* hi = slots_.get() + t.room + left_room + right_at[b];
      const size_t end = std::min(t.count, (b + 1) * kBlock);
      for (size_t i = b * kBlock; i < end; ++i) {
        if (side[i] & kLeft) *lo++ = side[i] & kPieces ? left[i] : whole[i];
        if (side[i] & kRight) *hi++ = side[i] & kPieces ? right[i] : whole[i];
      }
    };
    if (parallel(t.count))
      tbb::parallel_for(size_t(0), blocks, write_block);
    else
      for (size_t b = 0; b < blocks; ++b) write_block(b);

    finish_partition(t, s, total, left_room, l, r, counts);
    return true;
  }

  // A split that sends every reference whole to one side, in one serial pass: left ones
  // packed forward in place (never past the one being read), right ones through scratch to
  // the right child's first slot. The same children, in the same order, as the two passes
  // above, without copying every reference out and back (on classroom and staircase the
  // partition was a quarter of the build, nearly all of it object splits).
  bool partition_whole(const Task& t, const Split& s, Task& l, Task& r, SplitCounts& counts) {
    const ObjectMapping om(t.state.centres, object_bin_count(t.count));
    // Nothing here waits in oneTBB, so no other task runs on this thread meanwhile.
    thread_local std::vector<SRef> right_scratch;
    if (right_scratch.size() < t.count) right_scratch.resize(t.count);
    SRef* rs = right_scratch.data();
    const SRef* node = slots_.get() + t.begin;
    SRef* to = slots_.get() + t.room;  // at or below `node`: writing never overtakes reading
    Sides total;
    SRef unused;
    const bool object = s.kind == Split::object;  // the common case, without classify()'s dispatch
    // Without a branch on the side, which is as good as random within a node: the reference
    // is written to both places and only its side's count moves on (writing to `to` at
    // total.left <= i overwrites nothing unread). The sides' bounds come after, from the
    // packed runs.
    for (size_t i = 0; i < t.count; ++i) {
      // Read in place, not copied: a copy went to the stack as two overlapping stores, and
      // loading it back waited for both (a quarter of the partition's time). `to` reaches
      // node[i] at most, where the reference is copied onto itself.
      const SRef& ref = node[i];
      const bool left = object ? om.bin_of_centre(ref.box.center()[s.axis], s.axis) < s.bin
                               : (classify(s, nullptr, &om, i, ref, unused, unused, total) & kLeft) != 0;
      to[total.left] = ref;
      rs[total.right] = ref;
      total.left += left ? 1 : 0;
      total.right += left ? 0 : 1;
    }
    total.l = bounds_of(to, total.left);
    total.r = bounds_of(rs, total.right);
    if (total.left == 0 || total.right == 0) {  // put back as they were
      SRef* back = slots_.get() + t.begin;
      if (total.left == 0)
        std::copy(rs, rs + total.right, back);
      else if (to != back)
        std::copy_backward(to, to + total.left, back + total.left);
      return false;
    }
    const size_t left_room = left_room_of(t, total);
    std::copy(rs, rs + total.right, to + left_room);
    finish_partition(t, s, total, left_room, l, r, counts);
    return true;
  }

  size_t left_room_of(const Task& t, const Sides& total) const {
    // The spare room is shared by the children's SAH weights, count times surface area: the
    // share of the cost each child stands for is where splits can save. By counts alone,
    // large sparse children (Sponza's and Conference's open halls, 2CylinderEngine's long
    // parts) ran short while compact dense ones kept room they never used: with the left
    // child's leftover passed on (build_packed), 2CylinderEngine 260.94 -> 256.55,
    // Conference 102.82 -> 100.62, Sponza 171.06 -> 169.79 (area alone: 259.71, 104.43,
    // 170.80).
    const size_t spare = t.capacity - total.left - total.right;
    const double wl = double(total.left) * double(total.l.box.area());
    const double wr = double(total.right) * double(total.r.box.area());
    double share = wl / (wl + wr);
    if (!std::isfinite(share)) share = double(total.left) / double(total.left + total.right);  // 0/0, inf/inf
    return total.left + std::min(spare, static_cast<size_t>(double(spare) * share));
  }

  void finish_partition(const Task& t, const Split& s, const Sides& total, size_t left_room, Task& l, Task& r,
                        SplitCounts& c) {
    ++(s.kind == Split::spatial ? c.spatial : c.object);
    c.cut += total.cut;
    c.unsplit += total.unsplit;
    l = Task{t.room, t.room, total.left, left_room, t.base + 1, t.base, total.l};
    r = Task{t.room + left_room, t.room + left_room, total.right, t.capacity - left_room,
             t.base + static_cast<uint32_t>(2 * left_room), t.base, total.r};
  }

  // The slots the leaves use become the result's references, numbered depth-first; the
  // unused nodes and slots are dropped; boxes are refitted to the final pieces (a node's
  // pieces can be smaller than the box its parent measured before cutting them). Each
  // subtree numbers its nodes after its root, the left subtree's before the right's, and
  // its slots likewise, so depth-first order is ascending order of nodes and of slots: the
  // new numbers are each block's count of used nodes (and slots) before it, and a subtree is
  // a range of the result, [node, end), its left child next to it. All in parallel over
  // fixed blocks (the same result on any number of threads): serial, this was a twentieth of
  // classroom's and staircase's build on two threads.
  void compact() {
    const size_t total = work_size_;
    const size_t blocks = (total + kBlock - 1) / kBlock;
    std::vector<uint32_t> node_at(blocks + 1, 0), slot_at(blocks + 1, 0);
    std::unique_ptr<uint32_t[]> new_index(new uint32_t[total]);
    const BvhNode* work = work_.get();
    auto block_end = [&](size_t b) { return std::min(total, (b + 1) * kBlock); };
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      uint32_t nodes = 0, slots = 0;
      for (size_t i = b * kBlock; i < block_end(b); ++i) {
        const BvhNode& nd = work[i];
        if (nd.left_or_first == kInvalidNode) continue;  // never built
        ++nodes;
        if (nd.is_leaf()) slots += nd.ref_count();
      }
      node_at[b + 1] = nodes;
      slot_at[b + 1] = slots;
    });
    for (size_t b = 0; b < blocks; ++b) node_at[b + 1] += node_at[b], slot_at[b + 1] += slot_at[b];
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      uint32_t next = node_at[b];
      for (size_t i = b * kBlock; i < block_end(b); ++i)
        new_index[i] = work[i].left_or_first == kInvalidNode ? kInvalidNode : next++;
    });
    Bvh& bvh = out_.bvh;
    PrimitiveRefs& refs = out_.refs;
    const uint32_t used_nodes = node_at[blocks], used_slots = slot_at[blocks];
    std::vector<BvhNode> nodes(used_nodes);
    refs.resize(used_slots);
    bvh.ref_indices.resize(used_slots);
    tbb::parallel_for(size_t(0), blocks, [&](size_t b) {
      uint32_t ref = slot_at[b];
      for (size_t i = b * kBlock; i < block_end(b); ++i) {
        if (new_index[i] == kInvalidNode) continue;
        BvhNode nd = work[i];
        if (nd.parent != kInvalidNode) nd.parent = new_index[nd.parent];
        if (nd.is_leaf()) {
          const uint32_t first = ref;
          Box box;
          for (uint32_t k = 0; k < nd.ref_count(); ++k, ++ref) {
            const SRef& s = slots_[nd.first_ref() + k];
            refs.boxes[ref] = s.box;
            refs.centroids[ref] = s.box.center();
            refs.triangle_ids[ref] = s.tri;
            bvh.ref_indices[ref] = ref;
            box.extend(s.box);
          }
          nd.make_leaf(first, nd.ref_count());
          nd.set_box(box);
        } else {
          nd.make_inner(new_index[nd.left()], new_index[nd.right()]);
        }
        nodes[new_index[i]] = nd;
      }
    });
    slots_.reset();
    work_.reset();
    if (used_nodes > 0) refit(nodes.data(), 0, used_nodes);
    bvh.nodes = std::move(nodes);
    bvh.root = 0;
  }

  // Inner boxes of the subtree of `node`, which is [node, end) in depth-first order, its left
  // child at node + 1: two subtrees in parallel down to ranges small enough for one backward
  // scan (children after parents). Leaves already have their boxes.
  static void refit(BvhNode* nodes, uint32_t node, uint32_t end) {
    constexpr uint32_t kSerialRange = 4096;
    if (nodes[node].is_leaf()) return;
    if (end - node <= kSerialRange) {
      for (uint32_t i = end; i-- > node;)
        if (!nodes[i].is_leaf()) nodes[i].set_box(merge(nodes[nodes[i].left()].box, nodes[nodes[i].right()].box));
      return;
    }
    const uint32_t right = nodes[node].right();
    tbb::parallel_invoke([&] { refit(nodes, node + 1, right); }, [&] { refit(nodes, right, end); });
    nodes[node].set_box(merge(nodes[node + 1].box, nodes[right].box));
  }

  const Mesh& mesh_;
  const PrimitiveRefs& refs_;
  const SpatialSplitConfig& config_;
  SpatialSplitResult& out_;
  size_t capacity_ = 0;
  float root_area_ = 0.0f;
  std::unique_ptr<SRef[]> slots_;
  // The nodes while building, numbered as the tasks reserve them (compact() renumbers them
  // into the result).
  std::unique_ptr<BvhNode[], FreeStorage> work_;
  size_t work_size_ = 0;
  // The parallel partitions' scratch, one place per slot: a node uses the places of its own
  // slots, so nodes partitioned at the same time never share any.
  struct {
    std::unique_ptr<SRef[], FreeStorage> whole, left, right;
    std::unique_ptr<uint8_t[], FreeStorage> side;
  } parallel_scratch_;
  tbb::task_group tasks_;
  // Per thread, added to once per task: shared atomic counters, three locked adds at every
  // node from both threads, were an eighth of the partition's time.
  tbb::enumerable_thread_specific<SplitCounts> counts_;
  void add_counts(const SplitCounts& c) {
    SplitCounts& mine = counts_.local();
    mine.spatial += c.spatial, mine.object += c.object, mine.cut += c.cut, mine.unsplit += c.unsplit;
  }
};

}  // namespace

SpatialSplitResult build_spatial_split(const Mesh& mesh, const PrimitiveRefs& refs, const SpatialSplitConfig& config) {
  validate(config);
  SpatialSplitResult result;
  if (refs.empty()) return result;
  const size_t triangles = mesh.triangle_count();
  for (size_t i = 0; i < refs.size(); ++i)
    if (refs.triangle_ids[i] >= triangles)
      throw Error("spatial-split builder: reference " + std::to_string(i) + " names triangle " +
                  std::to_string(refs.triangle_ids[i]) + ", but the mesh has " + std::to_string(triangles));
  SpatialSplitBuilder(mesh, refs, config, result).run();
  return result;
}

}  // namespace bvhopt
