// The wide traversal kernel for AVX-512 F/VL/BW/DQ with 256-bit vectors (-mprefer-vector-width=256, so no frequency
// penalty of 512-bit operations): the AVX2 kernel with compares straight into mask registers.
#include "trace/wide_kernel.h"

namespace bvhopt::wide_kernels {

void trace_avx512(const Batch& batch) { trace_batch(batch); }
OneRayFn one_ray_avx512(uint32_t width, TriangleTest test, NearFirst order, bool any) {
  return one_ray_kernel(width, test, order, any);
}

}  // namespace bvhopt::wide_kernels
