// Scene specs as the command line takes them: the built-in scene with options, or a file.
#include <string>

#include "bvhopt/error.h"
#include "bvhopt/scene_file.h"

namespace bvhopt {

Mesh load_scene(const std::string& spec) {
  if (spec.empty()) throw Error("scene: empty name (expected a file or builtin[:atrium][?triangles=N&seed=S])");
  if (is_builtin_scene_spec(spec)) return load_builtin_scene(spec);
  return load_mesh_file(spec);
}

}  // namespace bvhopt
