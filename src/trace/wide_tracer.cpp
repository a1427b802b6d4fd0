// The wide tracer: the layout plus the kernel of the chosen ISA.
#include "bvhopt/wide_tracer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "bvhopt/error.h"
#include "trace/wide_kernels.h"

namespace bvhopt {
namespace {

using KernelFn = void (*)(const wide_kernels::Batch&);

KernelFn kernel_for(Isa isa) {
  switch (isa) {
    case Isa::sse42: return wide_kernels::trace_sse42;
    case Isa::avx2: return wide_kernels::trace_avx2;
    case Isa::avx512: return wide_kernels::trace_avx512;
  }
  return wide_kernels::trace_sse42;
}

WideTracer::OneRayFn one_ray_kernel_for(Isa isa, const WideBvh& bvh, NearFirst order, bool any) {
  if (bvh.stack_entries() > wide_kernels::kOneRayStackEntries) return nullptr;
  switch (isa) {
    case Isa::sse42: return wide_kernels::one_ray_sse42(bvh.width(), bvh.triangle_test(), order, any);
    case Isa::avx2: return wide_kernels::one_ray_avx2(bvh.width(), bvh.triangle_test(), order, any);
    case Isa::avx512: return wide_kernels::one_ray_avx512(bvh.width(), bvh.triangle_test(), order, any);
  }
  return nullptr;
}

// The lanes' stacks fit on the C stack for most trees (each lane's the tree's stack need,
// rounded up to whole cache lines); deeper trees or more lanes get them on the heap. (Sized
// for every lane at 512 entries, the frame was 64 KiB with 16 lanes.)
constexpr uint32_t kFixedEntries = 2048;
static_assert(kMaxTraceLanes == wide_kernels::kMaxLanes);

}  // namespace

std::string_view any_hit_order_name(AnyHitOrder order) {
  switch (order) {
    case AnyHitOrder::near_first:
      return "near";
    case AnyHitOrder::adaptive:
      return "auto";
    case AnyHitOrder::far_first:
      break;
  }
  return "far";
}

std::optional<AnyHitOrder> parse_any_hit_order(std::string_view name) {
  for (AnyHitOrder o : {AnyHitOrder::adaptive, AnyHitOrder::far_first, AnyHitOrder::near_first})
    if (name == any_hit_order_name(o)) return o;
  return std::nullopt;
}

std::string_view closest_hit_order_name(ClosestHitOrder order) {
  return order == ClosestHitOrder::near_first ? "near" : "auto";
}

std::optional<ClosestHitOrder> parse_closest_hit_order(std::string_view name) {
  for (ClosestHitOrder o : {ClosestHitOrder::adaptive, ClosestHitOrder::near_first})
    if (name == closest_hit_order_name(o)) return o;
  return std::nullopt;
}

WideTracer::WideTracer(const FlatBvh& bvh, const Mesh& mesh, const WideTracerOptions& options)
    : bvh_(bvh, mesh, options.layout), isa_(options.isa ? *options.isa : default_isa()), near_first_(options.near_first),
      any_octant_flip_(options.any_hit_order == AnyHitOrder::near_first ? 0u : 7u),
      any_hit_order_(options.any_hit_order), closest_hit_order_(options.closest_hit_order),
      lanes_(options.lanes == 0 ? kMaxTraceLanes : options.lanes),
      scatter_distance_(bvh.nodes.empty() ? 0.0f : wide_kernels::scatter_distance(bvh.nodes[0].box)) {
  if (!isa_supported(isa_)) throw Error("wide tracer: this CPU does not support " + std::string(isa_name(isa_)));
  if (options.lanes > kMaxTraceLanes)
    throw Error("wide tracer: " + std::to_string(options.lanes) + " lanes asked for, at most " +
                std::to_string(kMaxTraceLanes));
  one_closest_ = one_ray_kernel_for(isa_, bvh_, near_first_, false);
  one_any_ = one_ray_kernel_for(isa_, bvh_, near_first_, true);
}

namespace wide_kernels {
namespace {
// Where the k-th of the 32 pairs lies in a batch, as a fraction of it: the fractional part of
// 0.5 + k / phi. Spread by the golden ratio, not evenly: an even stride can fall in step with
// an image's rows and land every pair on a row's end or its middle, where neighbours differ.
// A table made at compile time: computed per call with std::fmod (a library call of about a
// hundred cycles), the 64 of a batch's two samplings cost some 2 us a call, which calls of 256
// ambient occlusion rays on staircase paid as 30 % of their time.
constexpr std::array<double, 32> kPairSpread = [] {
  std::array<double, 32> spread{};
  for (size_t k = 0; k < spread.size(); ++k) {
    const double x = 0.5 + 0.6180339887498949 * double(k);
    spread[k] = x - double(uint64_t(x));  // x - floor(x), exact, as fmod(x, 1.0) is
  }
  // In increasing order, so that the samples read a batch front to back (order-free result).
  for (size_t i = 1; i < spread.size(); ++i)
    for (size_t j = i; j > 0 && spread[j - 1] > spread[j]; --j) std::swap(spread[j - 1], spread[j]);
  return spread;
}();

// The first of the k-th pair of neighbours the batch tests are judged by (0 <= k < 32, count
// >= 2).
size_t sample_pair(size_t k, size_t count) {
  return std::min(count - 2, size_t(kPairSpread[k] * double(count - 1)));
}
}  // namespace

bool rays_coherent(const Ray* rays, size_t count) {
  // One ray alone (a renderer's call per ray): the branches' history carries over from call
  // to call, which is what coherent rays need.
  if (count < 2) return true;
  const size_t pairs = std::min<size_t>(32, count - 1);
  size_t alike = 0;
  for (size_t k = 0; k < pairs; ++k) {
    const size_t i = sample_pair(k, count);
    const Vec3 a = rays[i].dir, b = rays[i + 1].dir;
    const bool same_octant = (a.x < 0) == (b.x < 0) && (a.y < 0) == (b.y < 0) && (a.z < 0) == (b.z < 0);
    const double dot = double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z;
    const double aa = double(a.x) * a.x + double(a.y) * a.y + double(a.z) * a.z;
    const double bb = double(b.x) * b.x + double(b.y) * b.y + double(b.z) * b.z;
    // cos >= 0.999, about 2.6 degrees, without a square root: dot^2 >= 0.998 |a|^2 |b|^2.
    if (same_octant && dot > 0.0 && dot * dot >= 0.998001 * aa * bb) ++alike;
  }
  return alike * 8 >= pairs * 7;
}

float scatter_distance(const Box& scene) {
  if (!(scene.min.x <= scene.max.x)) return 0.0f;
  const double dx = double(scene.max.x) - scene.min.x, dy = double(scene.max.y) - scene.min.y,
               dz = double(scene.max.z) - scene.min.z;
  return float(std::sqrt(dx * dx + dy * dy + dz * dz) / 64.0);
}

bool rays_scattered(const Ray* rays, size_t count, float distance) {
  if (count < 2) return false;
  const size_t pairs = std::min<size_t>(32, count - 1);
  const double limit = double(distance) * double(distance);
  size_t apart = 0;
  for (size_t k = 0; k < pairs; ++k) {
    const size_t i = sample_pair(k, count);
    const Vec3 a = rays[i].org, b = rays[i + 1].org;
    const double dx = double(a.x) - b.x, dy = double(a.y) - b.y, dz = double(a.z) - b.z;
    // Written so that a NaN origin counts as not apart.
    if (dx * dx + dy * dy + dz * dz > limit) ++apart;
  }
  return apart * 2 >= pairs;
}
}  // namespace wide_kernels

namespace {
template <class Fill>
void run_kernel(const WideBvh& bvh, Isa isa, NearFirst order, uint32_t any_octant_flip, uint32_t lanes,
                float scatter_distance, TraceCounters& counters, Fill&& fill) {
  alignas(64) uint32_t fixed_words[kFixedEntries];
  alignas(64) float fixed_t[kFixedEntries];
  std::vector<uint32_t> heap_words;
  std::vector<float> heap_t;
  wide_kernels::Batch b{};
  b.stack_words = fixed_words;
  b.stack_t = fixed_t;
  b.stack_stride = (bvh.stack_entries() + 15) / 16 * 16;
  if (size_t(lanes) * b.stack_stride > kFixedEntries) {
    heap_words.resize(size_t(lanes) * b.stack_stride);
    heap_t.resize(size_t(lanes) * b.stack_stride);
    b.stack_words = heap_words.data();
    b.stack_t = heap_t.data();
  }
  b.arena = bvh.data();
  b.root = bvh.root();
  b.width = bvh.width();
  b.test = bvh.triangle_test();
  b.near_first = order;
  b.any_octant_flip = any_octant_flip;
  b.counters = &counters;
  fill(b);
  b.coherent = wide_kernels::rays_coherent(b.rays, b.count);
  const bool scattered = !b.coherent && wide_kernels::rays_scattered(b.rays, b.count, scatter_distance);
  b.lanes = scattered ? lanes : 1;
  kernel_for(isa)(b);
}
}  // namespace

// Batches this small go ray by ray through the per-ray kernel: a batch's set-up (judging
// its rays coherent or scattered from up to 32 pairs of them) costs more than it can gain
// there, and side by side tracing starts only after the first 16 rays anyway.
constexpr size_t kMaxRaysOneByOne = 16;

void WideTracer::closest(const Ray* rays, size_t count, Hit* hits, TraceCounters& counters) const {
  if (count <= kMaxRaysOneByOne && one_closest_) {
    for (size_t i = 0; i < count; ++i) one_closest_(bvh_.data(), bvh_.root(), rays[i], hits[i], counters, 0);
    return;
  }
  run_kernel(bvh_, isa_, near_first_, any_octant_flip_, lanes_, scatter_distance_, counters, [&](wide_kernels::Batch& b) {
    b.rays = rays;
    b.count = count;
    b.hits = hits;
    b.slot_order_when_missing = closest_hit_order_ == ClosestHitOrder::adaptive;
  });
}

void WideTracer::any(const Ray* rays, size_t count, uint8_t* hit, TraceCounters& counters) const {
  if (count <= kMaxRaysOneByOne && one_any_) {
    Hit unused;
    for (size_t i = 0; i < count; ++i) hit[i] = one_any_(bvh_.data(), bvh_.root(), rays[i], unused, counters, any_octant_flip_) ? 1 : 0;
    return;
  }
  run_kernel(bvh_, isa_, near_first_, any_octant_flip_, lanes_, scatter_distance_, counters, [&](wide_kernels::Batch& b) {
    b.rays = rays;
    b.count = count;
    b.any_hits = hit;
    b.slot_order_when_missing = any_hit_order_ == AnyHitOrder::adaptive;
  });
}

Hit WideTracer::closest(const Ray& ray, TraceCounters& counters) const {
  Hit hit;
  closest(&ray, 1, &hit, counters);
  return hit;
}

bool WideTracer::any(const Ray& ray, TraceCounters& counters) const {
  uint8_t hit = 0;
  any(&ray, 1, &hit, counters);
  return hit != 0;
}

}  // namespace bvhopt
