#include "bvhopt/references.h"

#include <tbb/parallel_for.h>

namespace bvhopt {

PrimitiveRefs make_references(const Mesh& mesh) {
  PrimitiveRefs refs;
  const size_t n = mesh.triangle_count();
  refs.resize(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t t = r.begin(); t < r.end(); ++t) {
      Box b = mesh.triangle(t).bounds();
      refs.boxes[t] = b;
      refs.centroids[t] = b.center();
      refs.triangle_ids[t] = static_cast<uint32_t>(t);
    }
  });
  return refs;
}

PrimitiveRefs make_references(const std::vector<Box>& boxes) {
  PrimitiveRefs refs;
  refs.resize(boxes.size());
  for (size_t i = 0; i < boxes.size(); ++i) {
    refs.boxes[i] = boxes[i];
    refs.centroids[i] = boxes[i].center();
    refs.triangle_ids[i] = static_cast<uint32_t>(i);
  }
  return refs;
}

}  // namespace bvhopt
