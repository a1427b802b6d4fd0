// Text from an input file as an error message may show it (internal to bvhopt::io).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace bvhopt {

// Control and non-ASCII bytes as \xNN, at most `limit` characters then "...", so a corrupt
// file cannot put raw bytes on the terminal.
inline std::string printable(std::string_view text, size_t limit = 60) {
  static const char* const kHex = "0123456789abcdef";
  std::string out;
  for (unsigned char c : text.substr(0, limit)) {
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  if (text.size() > limit) out += "...";
  return out;
}

}  // namespace bvhopt
