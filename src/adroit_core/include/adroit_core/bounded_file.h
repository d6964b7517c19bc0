// Reads a file that came from outside (a path in a parameter, a service request or on the
// command line) without trusting it: only a regular file is read (a FIFO, a device such as
// /dev/zero or a directory is refused before a byte is read, so a read never blocks or runs
// without end), and only up to a size limit that is checked before anything is allocated.
// Every error is one line that names the file and, for size, the limit.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>

namespace adroit {

class FileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Sizes for the limits callers pass, so the numbers read alike everywhere.
constexpr size_t kKiB = 1024, kMiB = 1024 * kKiB, kGiB = 1024 * kMiB;

// The whole text of `path`, which must be a regular file of at most `max_bytes`. Throws
// FileError: "<path>: not a regular file (a FIFO)", "<path>: 3.1 GB, over the limit of 64 MB".
std::string readBoundedFile(const std::string& path, size_t max_bytes);

// For a reader that opens the file itself (a rosbag): throws FileError unless `path` is a
// regular file of at most `max_bytes`; returns its size. Never blocks on a FIFO.
size_t requireRegularFile(const std::string& path, size_t max_bytes);

// "12 B", "3.5 kB", "64 MB": a size as a person reads it in an error message.
std::string describeBytes(size_t bytes);

}  // namespace adroit
