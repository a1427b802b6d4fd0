// load_mesh_file (our pre-checks, then assimp) on arbitrary bytes: the first byte picks the
// format the file is named as (.obj, .ply, .gltf, .glb), the rest is its content. It either
// throws Error or returns a mesh that check_mesh accepts.
#include <cstdio>
#include <cstdlib>

#include "bvhopt/error.h"
#include "bvhopt/scene_file.h"
#include "fuzz_input_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  static const char* const kExtensions[] = {".obj", ".ply", ".gltf", ".glb"};
  const auto path = bvhopt::fuzz::write_input_file(data + 1, size - 1, kExtensions[data[0] % 4]);
  try {
    const bvhopt::Mesh mesh = bvhopt::load_mesh_file(path);
    try {
      bvhopt::check_mesh(mesh);
    } catch (const bvhopt::Error& e) {
      std::fprintf(stderr, "load_mesh_file returned a mesh check_mesh refuses: %s\n", e.what());
      std::abort();
    }
  } catch (const bvhopt::Error&) {
  }
  return 0;
}
