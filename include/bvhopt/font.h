// Text in images: a TrueType font drawn through stb_truetype (bvhopt::io).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "bvhopt/images.h"

namespace bvhopt {

class Font {
 public:
  // Reads a TrueType file; throws Error naming the file when it is missing or not a font.
  static Font load(const std::filesystem::path& path);
  // $BVHOPT_FONT when set, else the font the build found (fonts-dejavu-core's DejaVuSans.ttf).
  static std::filesystem::path default_path();
  // The default font, or nullopt with `problem` saying why (pictures then go without text).
  static std::optional<Font> load_default(std::string& problem);

  // Width in pixels of UTF-8 `text` at a line height of `pixels`.
  int text_width(std::string_view text, float pixels) const;
  // Draws UTF-8 `text` with the top of its line at (x, y), blended over the image in
  // `rgb`; clipped at the image's edges. Returns the width drawn.
  int draw(Image& image, int x, int y, std::string_view text, float pixels, const uint8_t rgb[3]) const;

 private:
  struct Data;
  std::shared_ptr<const Data> data_;
};

}  // namespace bvhopt
