// Writing an output file so that a failed write never leaves half a file in its place.
#pragma once

#include <filesystem>
#include <functional>
#include <string>

namespace bvhopt {

// Calls `write(tmp)` to write the whole file at a temporary path beside `path`, then renames
// it over `path`. The rename is atomic on one file system, so readers see the old file or the
// new one, never half of either; if `write` throws or the rename fails, the temporary is
// removed, `path` is left as it was, and the error propagates (as bvhopt::Error). The
// temporary's name holds the process id and a per-process counter, so concurrent writers of
// one target never share it.
//
// Only a regular file or a missing path is ever replaced. What else the path names is kept:
// - a symlink (chain) is followed and its final target is written as above; the link stays;
// - a device or FIFO is written to, never replaced: the file is first written to a temporary in
//   the system's temporary folder, then streamed into the node (/dev/null swallows it, /dev/full
//   fails with "No space left on device"). A FIFO without a reader is an error at once ("no
//   reader"), not a process blocked in open();
// - a folder or any other kind of node is an error, and nothing is written.
void write_atomically(const std::filesystem::path& path,
                      const std::function<void(const std::filesystem::path& tmp)>& write);

// Writes `text` to `path` through write_atomically.
void write_text_atomically(const std::filesystem::path& path, const std::string& text);

}  // namespace bvhopt
