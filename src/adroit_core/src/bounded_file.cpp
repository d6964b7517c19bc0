#include "adroit_core/bounded_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

namespace adroit {

namespace {

const char* kindOf(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

// Closes the descriptor on every path out.
struct Descriptor {
  int fd;
  explicit Descriptor(int descriptor) : fd(descriptor) {}
  Descriptor(Descriptor&& other) noexcept : fd(other.fd) { other.fd = -1; }
  Descriptor(const Descriptor&) = delete;
  Descriptor& operator=(const Descriptor&) = delete;
  ~Descriptor() {
    if (fd >= 0) close(fd);
  }
};

}  // namespace

std::string describeBytes(size_t bytes) {
  const char* units[] = {"B", "kB", "MB", "GB", "TB"};
  double value = static_cast<double>(bytes);
  int unit = 0;
  while (value >= 1024.0 && unit < 4) {
    value /= 1024.0;
    ++unit;
  }
  char text[32];
  std::snprintf(text, sizeof text, unit == 0 ? "%.0f %s" : "%.3g %s", value, units[unit]);
  return text;
}

namespace {

// "2 MB, over the limit of 1 MB"; with the byte counts when the rounded sizes read the same.
std::string describeOverLimit(size_t size, size_t limit) {
  std::string have = describeBytes(size), allowed = describeBytes(limit);
  if (have == allowed) {
    have += " (" + std::to_string(size) + " bytes)";
    allowed += " (" + std::to_string(limit) + " bytes)";
  }
  return have + ", over the limit of " + allowed;
}

// Opens `path` for reading if it is a regular file of at most `max_bytes`; `size` set.
Descriptor openRegularFile(const std::string& path, size_t max_bytes, size_t& size) {
  if (path.empty()) throw FileError("no file named (empty path)");
  // O_NONBLOCK: opening a FIFO with no writer must not wait; the type is checked next.
  Descriptor file{open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY)};
  if (file.fd < 0) throw FileError(path + ": cannot open (" + std::strerror(errno) + ")");
  struct stat info {};
  if (fstat(file.fd, &info) != 0) throw FileError(path + ": cannot stat (" + std::strerror(errno) + ")");
  if (!S_ISREG(info.st_mode)) throw FileError(path + ": not a regular file (" + kindOf(info.st_mode) + ")");
  size = static_cast<size_t>(info.st_size);
  if (size > max_bytes) throw FileError(path + ": " + describeOverLimit(size, max_bytes));
  return file;
}

}  // namespace

size_t requireRegularFile(const std::string& path, size_t max_bytes) {
  size_t size = 0;
  openRegularFile(path, max_bytes, size);
  return size;
}

std::string readBoundedFile(const std::string& path, size_t max_bytes) {
  size_t size = 0;
  const Descriptor file = openRegularFile(path, max_bytes, size);
  std::string text(size, '\0');
  size_t got = 0;
  // The file may change while it is read: never more than `size` bytes (the bound), and a
  // shorter read keeps what arrived.
  while (got < size) {
    const ssize_t n = read(file.fd, &text[got], size - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw FileError(path + ": read failed (" + std::strerror(errno) + ")");
    if (n == 0) break;
    got += static_cast<size_t>(n);
  }
  text.resize(got);
  return text;
}

}  // namespace adroit
