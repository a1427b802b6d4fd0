// The wide traversal kernel for AVX2 + FMA (compiled with -mavx2 -mfma): 8 boxes in one 256-bit vector, fused slab test.
#include "trace/wide_kernel.h"

namespace bvhopt::wide_kernels {

void trace_avx2(const Batch& batch) { trace_batch(batch); }

}  // namespace bvhopt::wide_kernels
