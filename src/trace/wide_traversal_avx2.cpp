// The wide traversal kernel for AVX2 + FMA (compiled with -mavx2 -mfma): 8 boxes in one 256-bit vector, fused slab test.
#include "trace/wide_kernel.h"

namespace bvhopt::wide_kernels {

void trace_avx2(const Batch& batch) { trace_batch(batch); }
OneRayFn one_ray_avx2(uint32_t width, TriangleTest test, NearFirst order, bool any) {
  return one_ray_kernel(width, test, order, any);
}

}  // namespace bvhopt::wide_kernels
