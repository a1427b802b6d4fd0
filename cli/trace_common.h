// What `bvhopt trace` and `bvhopt render` share: a BVH file checked against its scene and
// made ready to trace.
#pragma once

#include <memory>
#include <string>

#include "bvhopt/bvh_file.h"
#include "bvhopt/error.h"
#include "bvhopt/finalize.h"
#include "bvhopt/mesh.h"
#include "bvhopt/traversal.h"

namespace bvhopt::cli {

struct LoadedTree {
  BvhFileInfo info;
  double sah = 0.0;
  std::unique_ptr<Tracer> tracer;
};

// Reads the BVH file and refuses a scene whose triangle count differs from the one the
// tree was built over (the ids would point at the wrong triangles, or past the end).
inline LoadedTree load_tree_for_scene(const std::string& file, const Mesh& mesh) {
  BvhFile f = read_bvh_file(file);
  if (f.info.scene_triangles != mesh.triangle_count())
    throw Error(file + ": built over scene '" + f.info.scene_name + "' with " +
                std::to_string(f.info.scene_triangles) + " triangles, but scene '" + mesh.name + "' has " +
                std::to_string(mesh.triangle_count()) + " (pass the scene the tree was built from)");
  LoadedTree t;
  t.info = f.info;
  t.tracer = std::make_unique<Tracer>(finalize(f.bvh, f.refs), mesh);
  return t;
}

}  // namespace bvhopt::cli
