// PNG images through stb_image_write (implementation in libstb).
#include "bvhopt/png_file.h"

#include <stb/stb_image_write.h>

#include <string>

#include "bvhopt/atomic_file.h"
#include "bvhopt/error.h"

namespace bvhopt {

void write_png(const std::filesystem::path& path, const Image& image) {
  if (image.width == 0 || image.height == 0 || image.rgb.size() != size_t(image.width) * image.height * 3)
    throw Error(path.string() + ": cannot write an empty or malformed image");
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    if (!stbi_write_png(tmp.c_str(), int(image.width), int(image.height), 3, image.rgb.data(), int(image.width * 3)))
      throw Error(path.string() + ": PNG write failed (no permission, missing folder or disk full?)");
  });
}

}  // namespace bvhopt
