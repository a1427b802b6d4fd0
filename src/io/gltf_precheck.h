// The glTF pre-check that guards assimp's glTF readers (internal to bvhopt::io).
#pragma once

#include <filesystem>
#include <string>

namespace bvhopt {

// Throws Error naming `where` and the accessor, buffer view or buffer for a .gltf or .glb
// file whose data references run past what they point into (assimp 5.2 copies such ranges
// without checking and reads outside its buffer); returns without a word for anything else.
void check_gltf(const std::filesystem::path& path, const std::string& where);

}  // namespace bvhopt
