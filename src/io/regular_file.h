// Readers look at what a path names before they open it (internal to bvhopt::io).
#pragma once

#include <filesystem>
#include <string>
#include <system_error>

#include "bvhopt/error.h"

namespace bvhopt {

// Throws Error unless `path` names a regular file (symbolic links followed): opening a FIFO
// for reading blocks until a writer comes, and a device such as /dev/zero never ends, so
// both are refused before any open.
inline void require_regular_file(const std::filesystem::path& path, const std::string& kind) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) throw Error(path.string() + ": cannot open: no such file");
  if (std::filesystem::is_directory(status)) throw Error(path.string() + ": is a directory, not a " + kind);
  if (!std::filesystem::is_regular_file(status))
    throw Error(path.string() + ": not a regular file (a device, FIFO or socket), not a " + kind);
}

}  // namespace bvhopt
