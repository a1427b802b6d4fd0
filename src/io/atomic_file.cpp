#include "bvhopt/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <vector>

#include "bvhopt/error.h"

namespace bvhopt {
namespace {

namespace fs = std::filesystem;

// Follows a chain of symlinks to the path it ends in (which need not exist), so that the link
// itself is kept and its target is what gets written. A bound on the chain turns a loop into an
// error instead of a hang.
fs::path resolve_symlinks(const fs::path& path) {
  fs::path p = path;
  for (int hops = 0; hops < 40; ++hops) {
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(p, ec))) return p;
    fs::path next = fs::read_symlink(p, ec);
    if (ec) throw Error(path.string() + ": cannot read the symlink " + p.string() + ": " + ec.message());
    p = next.is_absolute() ? next : p.parent_path() / next;
  }
  throw Error(path.string() + ": too many levels of symlinks");
}

fs::path temporary_name(const fs::path& beside) {
  static std::atomic<uint64_t> counter{0};
  fs::path tmp = beside;
  tmp += ".tmp-" + std::to_string(static_cast<long>(::getpid())) + "-" + std::to_string(counter++);
  return tmp;
}

// Runs `write` on a temporary and removes the temporary if it throws.
void write_temporary(const fs::path& tmp, const std::function<void(const fs::path&)>& write) {
  try {
    write(tmp);
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

// Copies the finished temporary into a device or FIFO. O_NONBLOCK on open makes a FIFO without a
// reader an immediate error (ENXIO) rather than a process blocked forever; it is cleared before
// writing so a slow reader is waited for, not dropped.
void copy_into_special_file(const fs::path& shown, const fs::path& target, const fs::path& tmp) {
  std::ifstream in(tmp, std::ios::binary);
  if (!in) throw Error(shown.string() + ": cannot read back the temporary " + tmp.string());
  int fd = ::open(target.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    if (err == ENXIO) throw Error(shown.string() + ": is a FIFO with no reader; start the reader first");
    throw Error(shown.string() + ": cannot open for writing: " + std::strerror(err));
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  std::vector<char> buffer(1 << 16);
  while (in) {
    in.read(buffer.data(), std::streamsize(buffer.size()));
    const char* p = buffer.data();
    size_t left = size_t(in.gcount());
    while (left > 0) {
      ssize_t n = ::write(fd, p, left);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        const int err = errno;
        ::close(fd);
        throw Error(shown.string() + ": write failed: " + std::strerror(err));
      }
      p += n;
      left -= size_t(n);
    }
  }
  if (::close(fd) != 0) throw Error(shown.string() + ": write failed: " + std::strerror(errno));
}

// One output written to its temporary and not yet in place.
struct StagedOutput {
  fs::path shown, target, tmp;
  bool special = false;  // a device or FIFO: copied into, not renamed over
};

// Writes the temporary for `path` (see write_atomically for what each kind of node gets).
StagedOutput stage(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  StagedOutput out{path, resolve_symlinks(path), {}, false};
  std::error_code ec;
  const fs::file_status st = fs::status(out.target, ec);
  switch (st.type()) {
    case fs::file_type::not_found:
    case fs::file_type::regular:
      out.tmp = temporary_name(out.target);
      break;
    case fs::file_type::character:
    case fs::file_type::block:
    case fs::file_type::fifo:
      // Never beside the node (e.g. in /dev): in the system's temporary folder.
      out.tmp = temporary_name(fs::temp_directory_path() / ("bvhopt-" + out.target.filename().string()));
      out.special = true;
      break;
    case fs::file_type::directory:
      throw Error(path.string() + ": is a folder, not a file");
    default:
      if (ec && ec != std::errc::no_such_file_or_directory)
        throw Error(path.string() + ": cannot inspect the output path: " + ec.message());
      throw Error(path.string() + ": is neither a regular file nor a device or FIFO; not written");
  }
  write_temporary(out.tmp, write);
  return out;
}

void discard(const StagedOutput& s) {
  std::error_code ignored;
  fs::remove(s.tmp, ignored);
}

// Moves a staged output into place; the temporary is gone afterwards either way.
void move_into_place(const StagedOutput& s) {
  try {
    if (s.special) {
      copy_into_special_file(s.shown, s.target, s.tmp);
    } else {
      std::error_code ec;
      fs::rename(s.tmp, s.target, ec);
      if (ec) throw Error(s.shown.string() + ": cannot move the written file into place: " + ec.message());
    }
  } catch (...) {
    discard(s);
    throw;
  }
  discard(s);
}

}  // namespace

void write_atomically(const std::filesystem::path& path,
                      const std::function<void(const std::filesystem::path& tmp)>& write) {
  move_into_place(stage(path, write));
}

void check_output_path(const std::filesystem::path& path, const std::string& what) {
  const std::string shown = what + " " + path.string();
  if (path.empty()) throw Error(what + ": empty path");
  const fs::path target = resolve_symlinks(path);
  std::error_code ec;
  const fs::file_status st = fs::status(target, ec);
  switch (st.type()) {
    case fs::file_type::character:
    case fs::file_type::block:
    case fs::file_type::fifo:
      return;  // written into when the work is done
    case fs::file_type::directory:
      throw Error(shown + ": is a folder, not a file");
    case fs::file_type::not_found:
    case fs::file_type::regular:
      break;
    default:
      throw Error(shown + ": is neither a regular file nor a device or FIFO");
  }
  const fs::path folder = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  if (!fs::is_directory(folder, ec)) throw Error(shown + ": the folder " + folder.string() + " does not exist");
  // The one sure test of permissions, read-only mounts and quotas: create a file there.
  const fs::path probe = temporary_name(target);
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) throw Error(shown + ": cannot create a file in " + folder.string() + ": " + std::strerror(errno));
  ::close(fd);
  fs::remove(probe, ec);
}

void check_output_folder(const std::filesystem::path& path, const std::string& what) {
  const std::string shown = what + " " + path.string();
  if (path.empty()) throw Error(what + ": empty path");
  std::error_code ec;
  fs::path existing = fs::absolute(path, ec);
  while (!fs::exists(existing, ec) && existing.has_relative_path()) existing = existing.parent_path();
  if (!fs::is_directory(existing, ec))
    throw Error(shown + ": " + existing.string() + " is not a folder");
  const fs::path probe = temporary_name(existing / ".bvhopt-probe");
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) throw Error(shown + ": cannot create files in " + existing.string() + ": " + std::strerror(errno));
  ::close(fd);
  fs::remove(probe, ec);
}

struct OutputGroup::Staged : StagedOutput {};

OutputGroup::OutputGroup() : staged_(new std::vector<Staged>) {}

OutputGroup::~OutputGroup() {
  for (const Staged& s : *staged_) discard(s);
  delete staged_;
}

void OutputGroup::add(const std::filesystem::path& path,
                      const std::function<void(const std::filesystem::path& tmp)>& write) {
  try {
    staged_->push_back(Staged{stage(path, write)});
  } catch (...) {
    for (const Staged& s : *staged_) discard(s);
    staged_->clear();
    throw;
  }
}

void OutputGroup::add_text(const std::filesystem::path& path, const std::string& text) {
  add(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path.string() + ": cannot create " + tmp.string() + ": " + std::strerror(errno));
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.close();
    if (!out) throw Error(path.string() + ": write failed (disk full or no permission?)");
  });
}

void OutputGroup::commit() {
  // Every output is written by now; what is left are renames (and copies into devices).
  std::vector<Staged> staged = std::move(*staged_);
  staged_->clear();
  for (size_t i = 0; i < staged.size(); ++i) {
    try {
      move_into_place(staged[i]);
    } catch (...) {
      for (size_t j = i + 1; j < staged.size(); ++j) discard(staged[j]);
      throw;
    }
  }
}

void write_text_atomically(const std::filesystem::path& path, const std::string& text) {
  OutputGroup one;
  one.add_text(path, text);
  one.commit();
}

}  // namespace bvhopt
