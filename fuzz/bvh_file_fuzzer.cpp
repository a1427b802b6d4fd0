// read_bvh_file on arbitrary bytes: it either throws Error or returns a tree that validates
// against its own references.
#include <cstdio>
#include <cstdlib>

#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/validate.h"
#include "fuzz_input_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = bvhopt::fuzz::write_input_file(data, size, ".bvh");
  try {
    const bvhopt::BvhFile file = bvhopt::read_bvh_file(path);
    const bvhopt::ValidationReport report = bvhopt::validate(file.bvh, file.refs);
    if (!report.ok()) {
      std::fprintf(stderr, "read_bvh_file accepted an invalid tree: %s\n", report.summary().c_str());
      std::abort();
    }
  } catch (const bvhopt::Error&) {
  }
  return 0;
}
