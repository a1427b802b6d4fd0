// The fuzzers' bytes as a file: the readers under test take paths, so each input is
// written to a per-process temporary file with the extension the reader dispatches on.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <unistd.h>

namespace bvhopt::fuzz {

inline std::filesystem::path write_input_file(const uint8_t* data, size_t size, const std::string& extension) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / ("bvhopt-fuzz-" + std::to_string(::getpid()) + extension);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();  // the machine, not the input: stop rather than report nothing
  if (size != 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

}  // namespace bvhopt::fuzz
