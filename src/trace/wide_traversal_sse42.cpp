// The wide traversal kernel for SSE4.2 (compiled with -msse4.2): 8-wide boxes as two 4-lane halves, no fused multiply-add.
#include "trace/wide_kernel.h"

namespace bvhopt::wide_kernels {

void trace_sse42(const Batch& batch) { trace_batch(batch); }
OneRayFn one_ray_sse42(uint32_t width, TriangleTest test, NearFirst order, bool any) {
  return one_ray_kernel(width, test, order, any);
}

}  // namespace bvhopt::wide_kernels
