// The PLY pre-check that guards assimp's PLY reader (internal to bvhopt::io).
#pragma once

#include <filesystem>
#include <string>

namespace bvhopt {

// Throws Error naming `where` and the place for a PLY file that is short or inconsistent;
// returns without a word for anything that is not PLY.
void check_ply(const std::filesystem::path& path, const std::string& where);

}  // namespace bvhopt
