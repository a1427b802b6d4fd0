// The built-in scene's spec parser on arbitrary text: it either throws Error or returns a
// config within its documented range; small scenes are also generated and checked.
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bvhopt/error.h"
#include "bvhopt/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string spec(reinterpret_cast<const char*>(data), size);
  try {
    const bvhopt::BuiltinSceneConfig config = bvhopt::parse_builtin_scene_spec(spec);
    if (config.target_triangles == 0 || config.target_triangles > bvhopt::kMaxBuiltinTriangles) {
      std::fprintf(stderr, "parse_builtin_scene_spec accepted triangles=%llu\n",
                   static_cast<unsigned long long>(config.target_triangles));
      std::abort();
    }
    // Generating is the slow part; a few thousand triangles keep the fuzzer fast.
    if (config.target_triangles <= 4000) bvhopt::check_mesh(bvhopt::load_builtin_scene(spec));
  } catch (const bvhopt::Error&) {
  }
  return 0;
}
