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

void replace_regular_file(const fs::path& shown, const fs::path& target,
                          const std::function<void(const fs::path&)>& write) {
  const fs::path tmp = temporary_name(target);
  write_temporary(tmp, write);
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw Error(shown.string() + ": cannot move the written file into place: " + ec.message());
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

// A device or FIFO is not ours to replace: the file is written to a temporary in the system's
// temporary folder (never beside the node, e.g. in /dev) and then streamed into the node, so the
// node gets the whole file or, on a failed writer, nothing.
void write_through_special_file(const fs::path& shown, const fs::path& target,
                                const std::function<void(const fs::path&)>& write) {
  const fs::path tmp = temporary_name(fs::temp_directory_path() / ("bvhopt-" + target.filename().string()));
  write_temporary(tmp, write);
  try {
    copy_into_special_file(shown, target, tmp);
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
  std::error_code ignored;
  fs::remove(tmp, ignored);
}

}  // namespace

void write_atomically(const std::filesystem::path& path,
                      const std::function<void(const std::filesystem::path& tmp)>& write) {
  const fs::path target = resolve_symlinks(path);
  std::error_code ec;
  const fs::file_status st = fs::status(target, ec);
  switch (st.type()) {
    case fs::file_type::not_found:
    case fs::file_type::regular:
      return replace_regular_file(path, target, write);
    case fs::file_type::character:
    case fs::file_type::block:
    case fs::file_type::fifo:
      return write_through_special_file(path, target, write);
    case fs::file_type::directory:
      throw Error(path.string() + ": is a folder, not a file");
    default:
      if (ec && ec != std::errc::no_such_file_or_directory)
        throw Error(path.string() + ": cannot inspect the output path: " + ec.message());
      throw Error(path.string() + ": is neither a regular file nor a device or FIFO; not written");
  }
}

void write_text_atomically(const std::filesystem::path& path, const std::string& text) {
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path.string() + ": cannot create " + tmp.string() + ": " + std::strerror(errno));
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.close();
    if (!out) throw Error(path.string() + ": write failed (disk full or no permission?)");
  });
}

}  // namespace bvhopt
