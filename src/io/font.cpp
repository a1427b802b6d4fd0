// TrueType text through stb_truetype (implementation in libstb).
#include "bvhopt/font.h"

#include <stb/stb_truetype.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <vector>

#include "bvhopt/error.h"

#ifndef BVHOPT_DEFAULT_FONT
#define BVHOPT_DEFAULT_FONT "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"
#endif

namespace bvhopt {

struct Font::Data {
  std::vector<unsigned char> bytes;  // stbtt_fontinfo points into these
  stbtt_fontinfo info{};
};

namespace {

// The next code point of UTF-8 text; a malformed byte reads as U+FFFD.
char32_t next_code_point(std::string_view text, size_t& i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(text[k]); };
  const unsigned char b = byte(i++);
  if (b < 0x80) return b;
  const int extra = b >= 0xF0 ? 3 : b >= 0xE0 ? 2 : b >= 0xC0 ? 1 : -1;
  if (extra < 0 || i + size_t(extra) > text.size()) return 0xFFFD;
  char32_t c = b & (0x3F >> extra);
  for (int k = 0; k < extra; ++k) {
    if ((byte(i) & 0xC0) != 0x80) return 0xFFFD;
    c = (c << 6) | (byte(i++) & 0x3F);
  }
  return c;
}

// Calls `glyph(code_point, pen_x)` for each character, pen_x in pixels from the start,
// and returns the width of the whole text.
template <class Glyph>
float walk_text(const stbtt_fontinfo& info, std::string_view text, float scale, Glyph glyph) {
  float pen = 0.0f;
  char32_t previous = 0;
  for (size_t i = 0; i < text.size();) {
    const char32_t c = next_code_point(text, i);
    if (previous) pen += scale * float(stbtt_GetCodepointKernAdvance(&info, int(previous), int(c)));
    glyph(c, pen);
    int advance = 0, bearing = 0;
    stbtt_GetCodepointHMetrics(&info, int(c), &advance, &bearing);
    pen += scale * float(advance);
    previous = c;
  }
  return pen;
}

}  // namespace

Font Font::load(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open the font file");
  auto data = std::make_shared<Data>();
  data->bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  const int offset = data->bytes.empty() ? -1 : stbtt_GetFontOffsetForIndex(data->bytes.data(), 0);
  if (offset < 0 || !stbtt_InitFont(&data->info, data->bytes.data(), offset))
    throw Error(path.string() + ": not a TrueType font");
  Font font;
  font.data_ = std::move(data);
  return font;
}

std::filesystem::path Font::default_path() {
  const char* env = std::getenv("BVHOPT_FONT");
  return env && *env ? std::filesystem::path(env) : std::filesystem::path(BVHOPT_DEFAULT_FONT);
}

std::optional<Font> Font::load_default(std::string& problem) {
  try {
    return load(default_path());
  } catch (const Error& e) {
    problem = std::string(e.what()) + " (install fonts-dejavu-core, or set BVHOPT_FONT to a .ttf file)";
    return std::nullopt;
  }
}

int Font::text_width(std::string_view text, float pixels) const {
  const float scale = stbtt_ScaleForPixelHeight(&data_->info, pixels);
  return int(std::ceil(walk_text(data_->info, text, scale, [](char32_t, float) {})));
}

int Font::draw(Image& image, int x, int y, std::string_view text, float pixels, const uint8_t rgb[3]) const {
  const stbtt_fontinfo& info = data_->info;
  const float scale = stbtt_ScaleForPixelHeight(&info, pixels);
  int ascent = 0, descent = 0, gap = 0;
  stbtt_GetFontVMetrics(&info, &ascent, &descent, &gap);
  const int baseline = y + int(std::lround(scale * float(ascent)));
  std::vector<unsigned char> coverage;
  const float width = walk_text(info, text, scale, [&](char32_t c, float pen) {
    int x0, y0, x1, y1;
    stbtt_GetCodepointBitmapBox(&info, int(c), scale, scale, &x0, &y0, &x1, &y1);
    const int w = x1 - x0, h = y1 - y0;
    if (w <= 0 || h <= 0) return;
    coverage.assign(size_t(w) * h, 0);
    stbtt_MakeCodepointBitmap(&info, coverage.data(), w, h, w, scale, scale, int(c));
    const int left = x + int(std::lround(pen)) + x0, top = baseline + y0;
    for (int row = 0; row < h; ++row)
      for (int col = 0; col < w; ++col) {
        const int px = left + col, py = top + row;
        if (px < 0 || py < 0 || px >= int(image.width) || py >= int(image.height)) continue;
        const float a = float(coverage[size_t(row) * w + col]) / 255.0f;
        uint8_t* p = &image.rgb[3 * (size_t(py) * image.width + px)];
        for (int k = 0; k < 3; ++k) p[k] = uint8_t(std::lround(float(p[k]) * (1.0f - a) + float(rgb[k]) * a));
      }
  });
  return int(std::ceil(width));
}

}  // namespace bvhopt
