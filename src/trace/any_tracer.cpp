// Dispatch from the one handle to the binary or the wide tracer.
#include "bvhopt/any_tracer.h"

#include "bvhopt/ray_triangle.h"
#include "bvhopt/testing/brute_force.h"

namespace bvhopt {

std::string_view trace_layout_name(TraceLayout layout) {
  switch (layout) {
    case TraceLayout::bvh2: return "bvh2";
    case TraceLayout::bvh4: return "bvh4";
    case TraceLayout::bvh8: return "bvh8";
  }
  return "?";
}

std::optional<TraceLayout> parse_trace_layout(std::string_view name) {
  for (TraceLayout l : {TraceLayout::bvh2, TraceLayout::bvh4, TraceLayout::bvh8})
    if (name == trace_layout_name(l)) return l;
  return std::nullopt;
}

std::unique_ptr<WideTracer> make_wide_tracer(const FlatBvh& flat, const Mesh& mesh, TraceLayout layout,
                                             const WideCostModel& cost, AnyHitOrder any_hit_order,
                                             ClosestHitOrder closest_hit_order) {
  if (layout == TraceLayout::bvh2) return nullptr;
  WideTracerOptions o;
  o.layout.collapse.width = uint32_t(layout);
  o.layout.collapse.cost = cost;
  o.any_hit_order = any_hit_order;
  o.closest_hit_order = closest_hit_order;
  return std::make_unique<WideTracer>(flat, mesh, o);
}

Hit AnyTracer::closest(const Ray& ray, TraceCounters& counters) const {
  return wide_ ? wide_->closest(ray, counters) : binary_->closest(ray, counters, order_);
}

bool AnyTracer::any(const Ray& ray, TraceCounters& counters) const {
  return wide_ ? wide_->any(ray, counters) : binary_->any(ray, counters, order_);
}

void AnyTracer::closest(const Ray* rays, size_t count, Hit* hits, TraceCounters& counters) const {
  if (wide_) return wide_->closest(rays, count, hits, counters);
  for (size_t i = 0; i < count; ++i) hits[i] = binary_->closest(rays[i], counters, order_);
}

void AnyTracer::any(const Ray* rays, size_t count, uint8_t* hit, TraceCounters& counters) const {
  if (wide_) return wide_->any(rays, count, hit, counters);
  for (size_t i = 0; i < count; ++i) hit[i] = binary_->any(rays[i], counters, order_) ? 1 : 0;
}

Hit AnyTracer::brute_force(const Mesh& mesh, const Ray& ray) const {
  if (wide_ && wide_->layout().triangle_test() == TriangleTest::moller_trumbore) return brute_force_closest_mt(mesh, ray);
  return brute_force_closest(mesh, ray);
}

bool AnyTracer::hits_at(const Mesh& mesh, const Ray& ray, uint32_t id, float t) const {
  Hit alone;
  const Triangle tri = mesh.triangle(id);
  const bool hit = wide_ && wide_->layout().triangle_test() == TriangleTest::moller_trumbore
                       ? intersect_triangle_mt(ray, tri, alone)
                       : intersect_triangle(ray, tri, alone);
  return hit && alone.t == t;
}

TraceLayout AnyTracer::layout() const {
  if (!wide_) return TraceLayout::bvh2;
  return wide_->layout().width() == 4 ? TraceLayout::bvh4 : TraceLayout::bvh8;
}

std::string_view AnyTracer::isa() const { return wide_ ? isa_name(wide_->isa()) : isa_name(Isa::sse42); }

}  // namespace bvhopt
