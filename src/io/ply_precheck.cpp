// The PLY pre-check: a PLY file walked element by element before assimp reads it.
#include "io/ply_precheck.h"

#include <cctype>
#include <charconv>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "bvhopt/error.h"
#include "io/printable_text.h"

namespace bvhopt {
namespace {

struct PlyProperty {
  int size = 0;        // bytes of a scalar, or of each list item
  int count_size = 0;  // lists only: bytes of the item count
};
struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};
struct PlyHeader {
  std::string format;  // ascii, binary_little_endian or binary_big_endian
  std::vector<PlyElement> elements;
  uint64_t vertex_count() const {
    uint64_t n = 0;
    for (const PlyElement& e : elements)
      if (e.name == "vertex") n = e.count;
    return n;
  }
};

// A count as the header states it: digits only (istream would wrap "-5" to 2^64 - 5).
bool parse_count(const std::string& word, uint64_t& count) {
  auto [ptr, ec] = std::from_chars(word.data(), word.data() + word.size(), count);
  return !word.empty() && ec == std::errc() && ptr == word.data() + word.size();
}

int type_size(const std::string& type, int line, const std::string& where) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "int32" || type == "uint32" || type == "float" || type == "float32")
    return 4;
  if (type == "double" || type == "float64") return 8;
  throw Error(where + ": header line " + std::to_string(line) + ": unknown property type '" + printable(type) + "'");
}

// The first byte of `line` below 0x20 other than a tab (and a CR where `cr_ok`), or -1.
// Both readers must split a line into the same words, and they agree on spaces and tabs
// only: assimp's tokenizer does not take the other control bytes as blanks.
int first_control_byte(std::string_view line, bool cr_ok) {
  for (const char c : line) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte < 0x20 && byte != '\t' && !(cr_ok && byte == '\r')) return byte;
  }
  return -1;
}

// The header after the "ply" line, up to end_header (left as the stream's position).
PlyHeader read_ply_header(std::istream& in, const std::string& where) {
  PlyHeader h;
  bool ended = false;
  std::string text;
  for (int line = 2; !ended && std::getline(in, text); ++line) {
    if (!text.empty() && text.back() == '\r') text.pop_back();
    // A header line's words are split at blanks here but not by assimp, which hangs on a
    // header whose end_header it does not see (found by fuzz/scene_file_fuzzer:
    // "end_header" then a vertical tab). The header is plain text: no control byte but tabs.
    if (const int byte = first_control_byte(text, false); byte >= 0)
      throw Error(where + ": header line " + std::to_string(line) + ": control byte " + std::to_string(byte) +
                  " (a PLY header is plain text)");
    std::istringstream words(text);
    std::string word;
    words >> word;
    if (word == "format") {
      // One "format TYPE VERSION" line. Assimp hangs on a second format line with more words
      // (found by fuzz/scene_file_fuzzer: "format ascii 1.0" then "format ascii 1.0 e 4").
      if (!h.format.empty())
        throw Error(where + ": header line " + std::to_string(line) + ": a second format line '" + printable(text) +
                    "' (a PLY header has one)");
      std::string version, extra;
      if (!(words >> h.format >> version) || (words >> extra))
        throw Error(where + ": header line " + std::to_string(line) + ": malformed format line '" + printable(text) +
                    "' (expected format TYPE VERSION)");
    } else if (word == "element") {
      PlyElement e;
      std::string count;
      if (!(words >> e.name >> count) || !parse_count(count, e.count))
        throw Error(where + ": header line " + std::to_string(line) + ": malformed element line '" + printable(text) +
                    "' (expected element NAME COUNT, COUNT a non-negative integer)");
      h.elements.push_back(std::move(e));
    } else if (word == "property") {
      if (h.elements.empty())
        throw Error(where + ": header line " + std::to_string(line) + ": property before any element");
      std::string type;
      words >> type;
      PlyProperty p;
      if (type == "list") {
        std::string count_type, item_type;
        words >> count_type >> item_type;
        p.count_size = type_size(count_type, line, where);
        p.size = type_size(item_type, line, where);
      } else {
        p.size = type_size(type, line, where);
      }
      h.elements.back().properties.push_back(p);
    } else if (word == "end_header") {
      ended = true;
    } else if (word != "comment" && word != "obj_info" && !word.empty() && !in.eof()) {
      // (A last line without its newline is a cut header, reported as such below.)
      // Assimp skips such a line too, but then reads the data by a different layout than the
      // one checked here (found by fuzz/scene_file_fuzzer: an assertion aborted the program).
      throw Error(where + ": header line " + std::to_string(line) + ": unknown keyword '" + printable(word) + "'");
    }
    if (line > 100000) break;
  }
  if (!ended) throw Error(where + ": PLY header has no end_header line (truncated or corrupt)");
  return h;
}

// Assimp fills the faces of a short ASCII file with whatever it finds, and reads one
// element per line: a line with more or fewer values than the header's properties shifts
// its reading against this walk (found by fuzz/scene_file_fuzzer: an assertion aborted the
// program). So each element is walked on its own line, and must fill it exactly. A control
// byte (a NUL above all) ends assimp's reading of a line where this walk goes on: it is
// refused too (found by fuzz/scene_file_fuzzer: a NUL inside a vertex line aborted the
// program in assimp's triangulation).
void check_ascii_ply(const std::vector<char>& data, const PlyHeader& h, const std::string& where) {
  const uint64_t vertex_count = h.vertex_count();
  size_t at = 0, line_end = 0;
  auto is_blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  auto next_token = [&](std::string_view& token) {
    while (at < line_end && is_blank(data[at])) ++at;
    const size_t start = at;
    while (at < line_end && !is_blank(data[at])) ++at;
    token = std::string_view(data.data() + start, at - start);
    return at > start;
  };
  auto to_integer = [](std::string_view t, int64_t& v) {
    auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    return ec == std::errc() && ptr == t.data() + t.size();
  };
  std::string_view token;
  for (const PlyElement& e : h.elements) {
    const bool is_face = e.name == "face";
    auto short_by = [&](uint64_t index) {
      if (line_end < data.size())
        return Error(where + ": " + e.name + " " + std::to_string(index) +
                     ": fewer values on its line than the header's properties");
      return Error(where + ": truncated: the data ends in " + e.name + " " + std::to_string(index) + " of " +
                   std::to_string(e.count));
    };
    for (uint64_t i = 0; i < e.count; ++i) {
      // Every element takes a line, one with no properties too: none left is a cut file
      // (found by fuzz/scene_file_fuzzer: such elements walked on past the data's end).
      if (at >= data.size()) {
        line_end = data.size();
        throw short_by(i);
      }
      line_end = at;
      while (line_end < data.size() && data[line_end] != '\n') ++line_end;
      if (const int byte = first_control_byte(std::string_view(data.data() + at, line_end - at), true); byte >= 0)
        throw Error(where + ": " + e.name + " " + std::to_string(i) + ": control byte " + std::to_string(byte) +
                    " in an ASCII line");
      for (const PlyProperty& prop : e.properties) {
        if (!next_token(token)) throw short_by(i);
        if (!prop.count_size) continue;
        int64_t n = 0;
        if (!to_integer(token, n) || n < 0)
          throw Error(where + ": " + e.name + " " + std::to_string(i) + ": bad list length '" + printable(token) + "'");
        for (int64_t k = 0; k < n; ++k) {
          if (!next_token(token)) throw short_by(i);
          int64_t index = 0;
          if (is_face && (!to_integer(token, index) || index < 0 || static_cast<uint64_t>(index) >= vertex_count))
            throw Error(where + ": face " + std::to_string(i) + ": vertex index '" + printable(token) +
                        "' out of range (" + std::to_string(vertex_count) + " vertices)");
        }
      }
      if (next_token(token))
        throw Error(where + ": " + e.name + " " + std::to_string(i) + ": more values on its line than the header's " +
                    "properties ('" + printable(token) + "')");
      at = line_end + 1;
    }
  }
}

// A corrupt vertex index crashes the binary reader as surely as missing data, so face lists
// are checked against the vertex count too (a negative index reads as a huge one).
void check_binary_ply(const std::vector<char>& data, const PlyHeader& h, const std::string& where) {
  const uint64_t vertex_count = h.vertex_count();
  const bool little = h.format == "binary_little_endian";
  const unsigned char* p = reinterpret_cast<const unsigned char*>(data.data());
  const size_t size = data.size();
  auto read_unsigned = [&](size_t offset, int bytes) {
    uint64_t n = 0;
    for (int b = 0; b < bytes; ++b) n |= uint64_t(p[offset + (little ? b : bytes - 1 - b)]) << (8 * b);
    return n;
  };
  size_t at = 0;
  for (const PlyElement& e : h.elements) {
    const bool is_face = e.name == "face";
    uint64_t fixed = 0;
    bool has_list = false;
    for (const PlyProperty& prop : e.properties) {
      if (prop.count_size) has_list = true;
      else fixed += prop.size;
    }
    auto short_by = [&](uint64_t index) {
      return Error(where + ": truncated: the data ends in " + e.name + " " + std::to_string(index) + " of " +
                   std::to_string(e.count) + " (" + std::to_string(size) + " bytes after the header)");
    };
    if (!has_list) {
      // Elements of fixed size are checked in one step.
      if (fixed && e.count > (size - at) / fixed) throw short_by((size - at) / fixed);
      at += fixed * e.count;
      continue;
    }
    for (uint64_t i = 0; i < e.count; ++i)
      for (const PlyProperty& prop : e.properties) {
        if (!prop.count_size) {
          if (size - at < static_cast<size_t>(prop.size)) throw short_by(i);
          at += prop.size;
          continue;
        }
        if (size - at < static_cast<size_t>(prop.count_size)) throw short_by(i);
        const uint64_t n = read_unsigned(at, prop.count_size);
        at += prop.count_size;
        if (n > (size - at) / prop.size) throw short_by(i);
        if (is_face)
          for (uint64_t k = 0; k < n; ++k) {
            const uint64_t index = read_unsigned(at + k * prop.size, prop.size);
            if (index >= vertex_count)
              throw Error(where + ": face " + std::to_string(i) + ": vertex index " + std::to_string(index) +
                          " out of range (" + std::to_string(vertex_count) + " vertices)");
          }
        at += n * prop.size;
      }
  }
}

}  // namespace

// Assimp 5.2's binary PLY reader runs off the end of its buffer (a crash, not an error) when
// the data stops short of what the header promises or a face names a vertex that does not
// exist, and its ASCII reader fills a short file's missing faces with junk. So PLY files
// are walked here first, element by element, and a short or inconsistent one is rejected
// with the place where it goes wrong. Other formats go straight to assimp.
void check_ply(const std::filesystem::path& path, const std::string& where) {
  std::ifstream in(path, std::ios::binary);
  // Assimp reads a file named .ply, or any file starting "ply", as PLY, wherever the "ply" is,
  // and hangs on some whose first line is not exactly that (found by fuzz/scene_file_fuzzer:
  // "ply" then NUL bytes; a blank line, then "ply").
  std::string extension = path.extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  std::string magic;
  const bool read = static_cast<bool>(std::getline(in, magic));
  if (extension != ".ply" && (!read || magic.compare(0, 3, "ply") != 0)) return;  // not PLY: assimp decides
  if (magic != "ply" && magic != "ply\r") throw Error(where + ": PLY header: the first line is not exactly 'ply'");
  const PlyHeader header = read_ply_header(in, where);
  if (header.format != "ascii" && header.format != "binary_little_endian" && header.format != "binary_big_endian")
    throw Error(where + ": PLY header: unknown format '" + printable(header.format) + "'");
  const std::vector<char> data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (header.format == "ascii")
    check_ascii_ply(data, header, where);
  else
    check_binary_ply(data, header, where);
}

}  // namespace bvhopt
