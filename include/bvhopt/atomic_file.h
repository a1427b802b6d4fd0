// Writing an output file so that a failed write never leaves half a file in its place.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

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

// Checks, before any work, that `path` can be written as write_atomically would write it:
// not a folder, and (for a regular file or a missing path) its folder exists and a file can
// be created there (a probe file is created and removed). Throws Error naming `what` (the
// option, e.g. "--heatmap") and the path, so a typo costs nothing instead of the run.
void check_output_path(const std::filesystem::path& path, const std::string& what);

// The same for an output folder that may not exist yet: the path, if it exists, is a
// folder, and a file can be created in it or in the nearest folder above it that exists.
void check_output_folder(const std::filesystem::path& path, const std::string& what);

// Several outputs of one run, written all or none: add() writes each to its temporary at
// once (a failure removes every temporary so far and throws), commit() then moves them all
// into place. Destroyed without commit(), it removes the temporaries and leaves every target
// as it was.
class OutputGroup {
 public:
  OutputGroup();
  ~OutputGroup();
  OutputGroup(const OutputGroup&) = delete;
  OutputGroup& operator=(const OutputGroup&) = delete;
  void add(const std::filesystem::path& path, const std::function<void(const std::filesystem::path& tmp)>& write);
  void add_text(const std::filesystem::path& path, const std::string& text);
  void commit();

 private:
  struct Staged;
  std::vector<Staged>* staged_;
};

}  // namespace bvhopt
