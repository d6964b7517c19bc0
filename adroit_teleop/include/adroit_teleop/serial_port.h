// A serial port (or any byte-stream file descriptor: pty, socketpair) owned by one object:
// raw 8N1 termios set-up, reads with a timeout through poll(), complete writes, and a
// hang-up (glove unplugged, emulator gone) reported apart from errors so the caller can
// close and reopen. Errors are SerialPortError whose message names the port and the errno
// text: "glove port /dev/ttyUSB0: cannot open: No such file or directory".
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit::teleop {

class SerialPortError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Baud rates open() accepts: 9600..115200, plus 230400 and 460800 where termios has them.
std::vector<int> supportedBaudRates();
bool baudRateSupported(int baud);

// Puts an open terminal in raw mode: 8 data bits, no parity, 1 stop bit, no flow control,
// no echo or line editing, VMIN = VTIME = 0, input and output at `baud`. Throws
// SerialPortError "<name>: ..." when the descriptor is not a terminal or the baud rate is
// not supported. Used by SerialPort::open and by the emulator on its pty.
void makeRaw(int fd, int baud, const std::string& name);

class SerialPort {
 public:
  enum class ReadStatus {
    kData,     // bytes > 0 were read
    kTimeout,  // nothing arrived within the timeout (bytes == 0)
    kHangup,   // the other end is gone (POLLHUP, EIO, end of file): close and reopen
  };
  struct ReadResult {
    ReadStatus status = ReadStatus::kTimeout;
    std::size_t bytes = 0;
  };

  SerialPort() = default;  // closed
  // Takes ownership of an open descriptor (a socketpair end, a pty...), made non-blocking.
  // `name` is used in error messages, e.g. "glove port /dev/pts/3".
  SerialPort(int fd, std::string name);
  ~SerialPort();
  SerialPort(SerialPort&& other) noexcept;
  SerialPort& operator=(SerialPort&& other) noexcept;
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  // Opens `path` (O_RDWR | O_NOCTTY | O_NONBLOCK), raw 8N1 at `baud`, and discards whatever
  // the kernel buffered before. Closes a port already open first. Throws SerialPortError
  // "glove port <path>: <what>: <errno text>".
  void open(const std::string& path, int baud);
  void close();
  bool isOpen() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  const std::string& name() const { return name_; }

  // Waits up to `timeout` for input and reads what is there, at most `max` bytes.
  // Throws SerialPortError on other errors, or when the port is not open.
  ReadResult readSome(std::uint8_t* buffer, std::size_t max, std::chrono::milliseconds timeout);

  // Writes all n bytes, waiting for room up to `timeout` in total. Returns false when the
  // other end has hung up; throws SerialPortError on a timeout or any other error. Never
  // raises SIGPIPE (socketpair peers).
  bool writeAll(const std::uint8_t* data, std::size_t n,
                std::chrono::milliseconds timeout = std::chrono::milliseconds(1000));
  bool writeAll(const std::vector<std::uint8_t>& data,
                std::chrono::milliseconds timeout = std::chrono::milliseconds(1000)) {
    return writeAll(data.data(), data.size(), timeout);
  }

 private:
  [[noreturn]] void fail(const std::string& what, int err) const;

  int fd_ = -1;
  bool is_socket_ = false;  // write with send(MSG_NOSIGNAL) so a closed peer gives EPIPE, not SIGPIPE
  std::string name_;
};

}  // namespace adroit::teleop
