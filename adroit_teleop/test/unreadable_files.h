// Files a loader must refuse without reading them: a FIFO with no writer (a read, or even a
// plain open, would wait for one forever), a directory, a device, a file over the limit
// (sparse, so a limit of gigabytes costs no disk). errorWithin runs a load that must throw
// and gives its message, failing the test instead of hanging when the load blocks.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstddef>
#include <functional>
#include <future>
#include <string>
#include <thread>

namespace adroit::teleop::test {

inline std::string makeFifo(const std::string& path) {
  unlink(path.c_str());
  EXPECT_EQ(mkfifo(path.c_str(), 0600), 0) << path;
  return path;
}

// A file of `bytes` that holds no data blocks (reads as zeros).
inline std::string makeSparseFile(const std::string& path, std::size_t bytes) {
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  EXPECT_GE(fd, 0) << path;
  EXPECT_EQ(ftruncate(fd, static_cast<off_t>(bytes)), 0) << path;
  close(fd);
  return path;
}

// The message of the exception of type Error that `load` throws, or "" when it returns
// normally. When it has not finished after `timeout_s` (it blocked on `fifo`), the test fails
// and a writer opens and closes `fifo` so that the blocked reader sees end of file and returns.
template <class Error>
std::string errorWithin(const std::function<void()>& load, const std::string& fifo, double timeout_s = 5.0) {
  std::promise<std::string> result;
  std::future<std::string> message = result.get_future();
  std::thread reader([&] {
    try {
      load();
      result.set_value("");
    } catch (const Error& e) {
      result.set_value(e.what());
    } catch (const std::exception& e) {
      result.set_value(std::string("unexpected exception: ") + e.what());
    }
  });
  if (message.wait_for(std::chrono::duration<double>(timeout_s)) != std::future_status::ready) {
    ADD_FAILURE() << "the load blocked for " << timeout_s << " s on " << fifo;
    const int fd = open(fifo.c_str(), O_WRONLY | O_NONBLOCK);  // releases a reader waiting in open()
    if (fd >= 0) close(fd);
  }
  reader.join();
  return message.get();
}

}  // namespace adroit::teleop::test
