// The OBJ pre-check that gives assimp's OBJ errors a line number (internal to bvhopt::io).
#pragma once

#include <filesystem>
#include <string>

namespace bvhopt {

// Throws Error naming `where`, the line and the problem for an OBJ file with a vertex whose
// coordinates are not three finite numbers, or a face naming a vertex index that is 0 or
// out of range at that line; returns without a word for anything not named .obj.
void check_obj(const std::filesystem::path& path, const std::string& where);

}  // namespace bvhopt
