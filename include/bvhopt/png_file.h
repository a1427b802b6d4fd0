// PNG files of images (bvhopt::io).
#pragma once

#include <filesystem>

#include "bvhopt/images.h"

namespace bvhopt {

// Through a temporary file renamed into place; throws Error naming the file on failure.
void write_png(const std::filesystem::path& path, const Image& image);

}  // namespace bvhopt
