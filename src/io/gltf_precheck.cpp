// The glTF pre-check: every accessor, buffer view and buffer range of a glTF file checked
// against what it points into, before assimp reads it.
#include "io/gltf_precheck.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "bvhopt/error.h"

namespace bvhopt {
namespace {

using Json = nlohmann::json;
using Wide = unsigned __int128;  // sums of 64-bit counts and offsets cannot overflow it

// The file's JSON and, for a .glb, its binary chunk's length.
struct GltfContent {
  Json json;
  std::optional<uint64_t> binary_chunk;  // bytes of the GLB's BIN chunk (its buffer 0)
};

uint32_t le32(const unsigned char* p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24; }

// A GLB: "glTF", version, length, then the JSON's length at byte 12 and the JSON from byte
// 20 (version 2: a chunk header; version 1: contentLength and contentFormat), then the binary
// data (version 2: a second chunk, with its own 8-byte header; version 1: the rest).
GltfContent parse_glb(const std::vector<unsigned char>& bytes, const std::string& where) {
  if (bytes.size() < 20) throw Error(where + ": GLB: " + std::to_string(bytes.size()) + " bytes, shorter than its header");
  const uint64_t json_at = 20, json_len = le32(&bytes[12]);
  if (json_at + json_len > bytes.size())
    throw Error(where + ": GLB: JSON chunk of " + std::to_string(json_len) + " bytes runs past the end of the file (" +
                std::to_string(bytes.size()) + " bytes)");
  GltfContent out;
  const uint64_t rest = bytes.size() - json_at - json_len;
  if (le32(&bytes[4]) == 1)
    out.binary_chunk = rest;
  else
    out.binary_chunk = rest < 8 ? 0 : std::min<uint64_t>(le32(&bytes[json_at + json_len]), rest - 8);
  out.json = Json::parse(bytes.begin() + long(json_at), bytes.begin() + long(json_at + json_len), nullptr, false);
  if (out.json.is_discarded()) throw Error(where + ": GLB: the JSON chunk is not valid JSON");
  return out;
}

// An item of a glTF collection: glTF 2 refers by index into an array, glTF 1 by name into
// an object. Null when the reference is absent or does not resolve.
const Json* lookup(const Json& root, const char* collection, const Json& ref) {
  const auto c = root.find(collection);
  if (c == root.end()) return nullptr;
  if (c->is_array() && ref.is_number_unsigned() && ref.get<uint64_t>() < c->size()) return &(*c)[ref.get<size_t>()];
  if (c->is_object() && ref.is_string()) {
    const auto it = c->find(ref.get<std::string>());
    return it == c->end() ? nullptr : &*it;
  }
  return nullptr;
}

// Appended piece by piece: GCC 12 warns falsely (-Wrestrict) on "'" + str + "'" here.
std::string ref_text(const Json& ref) {
  if (!ref.is_string()) return ref.dump();
  std::string quoted = "'";
  quoted += ref.get<std::string>();
  quoted += '\'';
  return quoted;
}

// A non-negative integer field (absent: `fallback`); anything else is an error.
uint64_t count_field(const Json& item, const char* field, uint64_t fallback, const std::string& what) {
  const auto it = item.find(field);
  if (it == item.end()) return fallback;
  if (!it->is_number_unsigned()) throw Error(what + ": " + field + " " + it->dump() + " is not a non-negative integer");
  return it->get<uint64_t>();
}

// Bytes of base64 data behind "data:...;base64," (nullopt for any other URI).
std::optional<uint64_t> data_uri_bytes(const std::string& uri) {
  if (uri.rfind("data:", 0) != 0) return std::nullopt;
  const size_t comma = uri.find(',');
  if (comma == std::string::npos || uri.substr(0, comma).find(";base64") == std::string::npos) return std::nullopt;
  uint64_t chars = uri.size() - comma - 1;
  while (chars > 0 && uri[comma + chars] == '=') --chars;  // padding
  return chars * 6 / 8;
}

// How many bytes buffer `ref` really holds (its declared byteLength, checked against what
// stands behind it when that can be told).
uint64_t buffer_bytes(const Json& root, const Json& ref, const GltfContent& content, const std::filesystem::path& path,
                      const std::string& where) {
  const Json* buffer = lookup(root, "buffers", ref);
  const std::string what = where + ": buffer " + ref_text(ref);
  if (!buffer || !buffer->is_object()) throw Error(what + " does not exist");
  const auto uri = buffer->find("uri");
  std::optional<uint64_t> available;
  if (uri == buffer->end() || (ref.is_string() && ref.get<std::string>() == "binary_glTF")) {
    available = content.binary_chunk.value_or(0);
  } else if (uri->is_string()) {
    available = data_uri_bytes(uri->get<std::string>());
    if (!available) {
      std::error_code ec;
      const auto size = std::filesystem::file_size(path.parent_path() / uri->get<std::string>(), ec);
      if (!ec) available = size;
    }
  }
  const uint64_t declared = count_field(*buffer, "byteLength", available.value_or(0), what);
  if (available && declared > *available)
    throw Error(what + ": byteLength " + std::to_string(declared) + " but only " + std::to_string(*available) +
                " bytes of data");
  return declared;
}

// The bytes buffer view `ref` spans (checked to lie inside its buffer), and its stride.
struct ViewExtent {
  uint64_t length = 0;
  uint64_t stride = 0;
};
ViewExtent view_extent(const Json& root, const Json& ref, const GltfContent& content, const std::filesystem::path& path,
                       const std::string& where) {
  const Json* view = lookup(root, "bufferViews", ref);
  const std::string what = where + ": bufferView " + ref_text(ref);
  if (!view || !view->is_object()) throw Error(what + " does not exist");
  const auto buffer_ref = view->find("buffer");
  if (buffer_ref == view->end()) throw Error(what + ": no buffer");
  const uint64_t buffer_length = buffer_bytes(root, *buffer_ref, content, path, where);
  const uint64_t offset = count_field(*view, "byteOffset", 0, what);
  const uint64_t length = count_field(*view, "byteLength", 0, what);
  if (Wide(offset) + length > buffer_length)
    throw Error(what + ": " + std::to_string(length) + " bytes from offset " + std::to_string(offset) +
                " run past its buffer's " + std::to_string(buffer_length) + " bytes");
  return {length, count_field(*view, "byteStride", 0, what)};
}

uint64_t component_bytes(const Json& accessor, const std::string& what) {
  switch (count_field(accessor, "componentType", 0, what)) {
    case 5120: case 5121: return 1;
    case 5122: case 5123: return 2;
    case 5125: case 5126: return 4;
    default: throw Error(what + ": unknown componentType " + accessor.value("componentType", Json()).dump());
  }
}

uint64_t component_count(const Json& accessor, const std::string& what) {
  // value("type", std::string()) would throw nlohmann's type error on a non-string type
  // (found by fuzz/scene_file_fuzzer: "type":[...] ended the program).
  const auto it = accessor.find("type");
  const std::string type = it != accessor.end() && it->is_string() ? it->get<std::string>() : std::string();
  static const std::pair<const char*, uint64_t> kTypes[] = {{"SCALAR", 1}, {"VEC2", 2}, {"VEC3", 3}, {"VEC4", 4},
                                                             {"MAT2", 4},   {"MAT3", 9}, {"MAT4", 16}};
  for (const auto& [name, n] : kTypes)
    if (type == name) return n;
  throw Error(what + ": unknown type " + accessor.value("type", Json()).dump());
}

// `count` elements of `element` bytes from `offset` in view `view_ref` stay inside it.
void check_range(const Json& root, const Json& view_ref, uint64_t offset, uint64_t count, uint64_t element,
                 uint64_t accessor_stride, const GltfContent& content, const std::filesystem::path& path,
                 const std::string& where, const std::string& what) {
  const ViewExtent view = view_extent(root, view_ref, content, path, where);
  if (count == 0) return;
  const uint64_t stride = view.stride ? view.stride : accessor_stride ? accessor_stride : element;
  const Wide end = Wide(offset) + Wide(stride) * (count - 1) + element;
  if (end > view.length)
    throw Error(what + ": " + std::to_string(count) + " elements of " + std::to_string(element) + " bytes from offset " +
                std::to_string(offset) + " run past bufferView " + ref_text(view_ref) + " (" +
                std::to_string(view.length) + " bytes)");
}

void check_accessor(const Json& root, const std::string& key, const Json& accessor, const GltfContent& content,
                    const std::filesystem::path& path, const std::string& where) {
  const std::string what = where + ": accessor " + key;
  if (!accessor.is_object()) throw Error(what + " is not an object");
  const uint64_t element = component_bytes(accessor, what) * component_count(accessor, what);
  const uint64_t count = count_field(accessor, "count", 0, what);
  const uint64_t stride = count_field(accessor, "byteStride", 0, what);  // glTF 1 keeps it here
  if (const auto view = accessor.find("bufferView"); view != accessor.end())
    check_range(root, *view, count_field(accessor, "byteOffset", 0, what), count, element, stride, content, path, where,
                what);
  const auto sparse = accessor.find("sparse");
  if (sparse == accessor.end()) return;
  if (!sparse->is_object()) throw Error(what + ": sparse is not an object");
  const uint64_t sparse_count = count_field(*sparse, "count", 0, what + ", sparse");
  const Json& indices = sparse->value("indices", Json::object());
  const Json& values = sparse->value("values", Json::object());
  if (!indices.is_object() || !values.is_object()) throw Error(what + ": sparse indices or values are not objects");
  const uint64_t index_bytes = component_bytes(indices, what + ", sparse indices");
  check_range(root, indices.value("bufferView", Json()), count_field(indices, "byteOffset", 0, what), sparse_count,
              index_bytes, 0, content, path, where, what + ", sparse indices");
  check_range(root, values.value("bufferView", Json()), count_field(values, "byteOffset", 0, what), sparse_count, element,
              0, content, path, where, what + ", sparse values");
}

void check_json(const GltfContent& content, const std::filesystem::path& path, const std::string& where) {
  const Json& root = content.json;
  if (!root.is_object()) throw Error(where + ": glTF: the top level is not a JSON object");
  const auto accessors = root.find("accessors");
  if (accessors != root.end()) {
    if (accessors->is_array()) {
      for (size_t i = 0; i < accessors->size(); ++i) check_accessor(root, std::to_string(i), (*accessors)[i], content, path, where);
    } else if (accessors->is_object()) {
      for (const auto& [key, accessor] : accessors->items()) check_accessor(root, "'" + key + "'", accessor, content, path, where);
    } else {
      throw Error(where + ": glTF: accessors is neither an array nor an object");
    }
  }
  // Views that images and the like read directly.
  if (const auto views = root.find("bufferViews"); views != root.end() && views->is_array())
    for (size_t i = 0; i < views->size(); ++i) view_extent(root, Json(i), content, path, where);
}

}  // namespace

void check_gltf(const std::filesystem::path& path, const std::string& where) {
  std::string extension = path.extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  std::ifstream in(path, std::ios::binary);
  char first[4] = {};
  in.read(first, 4);
  const bool glb_magic = in.gcount() == 4 && std::memcmp(first, "glTF", 4) == 0;
  const bool named = extension == ".gltf" || extension == ".glb";
  // Assimp tries its glTF readers on a file of another name too, by these signatures.
  if (!named && !glb_magic && !(in.gcount() > 0 && first[0] == '{')) return;
  in.seekg(0);
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  GltfContent content;
  if (glb_magic) {
    content = parse_glb(bytes, where);
  } else {
    content.json = Json::parse(bytes.begin(), bytes.end(), nullptr, false);
    if (content.json.is_discarded()) {
      if (!named) return;  // not glTF after all: assimp decides
      throw Error(where + ": glTF: not valid JSON");
    }
  }
  if (!named && !(content.json.is_object() && content.json.contains("asset"))) return;
  // Every field is read after checking its JSON type; a read that missed the check still
  // becomes this file's error, not an exception the caller cannot place.
  try {
    check_json(content, path, where);
  } catch (const Json::exception& e) {
    throw Error(where + ": glTF: a value of the wrong JSON type (" + std::string(e.what()) + ")");
  }
}

}  // namespace bvhopt
