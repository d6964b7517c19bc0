#include "adroit_teleop/serial_port.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

namespace adroit::teleop {

namespace {

struct BaudEntry {
  int baud;
  speed_t speed;
};

const std::vector<BaudEntry>& baudTable() {
  static const std::vector<BaudEntry> table = {
      {9600, B9600}, {19200, B19200}, {38400, B38400}, {57600, B57600}, {115200, B115200},
#ifdef B230400
      {230400, B230400},
#endif
#ifdef B460800
      {460800, B460800},
#endif
  };
  return table;
}

std::string errnoText(int err) { return std::strerror(err); }

std::string supportedList() {
  std::string s;
  for (const BaudEntry& e : baudTable()) s += (s.empty() ? "" : ", ") + std::to_string(e.baud);
  return s;
}

speed_t speedFor(int baud, const std::string& name) {
  for (const BaudEntry& e : baudTable())
    if (e.baud == baud) return e.speed;
  throw SerialPortError(name + ": unsupported baud rate " + std::to_string(baud) + " (supported: " +
                        supportedList() + ")");
}

using Clock = std::chrono::steady_clock;

// Milliseconds left until `deadline`, for poll(): never negative.
int msLeft(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return static_cast<int>(std::clamp<long long>(left, 0, 1 << 30));
}

bool isHangupErrno(int err) { return err == EIO || err == EPIPE || err == ECONNRESET || err == ENXIO; }

}  // namespace

std::vector<int> supportedBaudRates() {
  std::vector<int> v;
  for (const BaudEntry& e : baudTable()) v.push_back(e.baud);
  return v;
}

bool baudRateSupported(int baud) {
  for (const BaudEntry& e : baudTable())
    if (e.baud == baud) return true;
  return false;
}

void makeRaw(int fd, int baud, const std::string& name) {
  const speed_t speed = speedFor(baud, name);
  termios t{};
  if (tcgetattr(fd, &t) != 0) {
    const int err = errno;
    throw SerialPortError(name + ": not a serial port (tcgetattr): " + errnoText(err));
  }
  cfmakeraw(&t);  // no echo, no line editing, no CR/LF translation, 8 bits, no parity
  t.c_cflag &= ~(CSIZE | PARENB | CSTOPB | CRTSCTS);
  t.c_cflag |= CS8 | CLOCAL | CREAD;  // CLOCAL: ignore modem lines, a glove has none
  t.c_iflag &= ~(IXON | IXOFF | IXANY);  // no XON/XOFF: 0x11/0x13 are ordinary sensor values
  t.c_cc[VMIN] = 0;  // reads never block in the kernel: waiting is poll()'s job
  t.c_cc[VTIME] = 0;
  cfsetispeed(&t, speed);
  cfsetospeed(&t, speed);
  if (tcsetattr(fd, TCSANOW, &t) != 0) {
    const int err = errno;
    throw SerialPortError(name + ": cannot configure (tcsetattr): " + errnoText(err));
  }
}

SerialPort::SerialPort(int fd, std::string name) : fd_(fd), name_(std::move(name)) {
  if (fd_ < 0) throw SerialPortError(name_ + ": invalid file descriptor");
  const int flags = fcntl(fd_, F_GETFL);
  if (flags < 0 || fcntl(fd_, F_SETFL, flags | O_NONBLOCK) < 0) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    throw SerialPortError(name_ + ": cannot make non-blocking: " + errnoText(err));
  }
  struct stat st {};
  is_socket_ = fstat(fd_, &st) == 0 && S_ISSOCK(st.st_mode);
}

SerialPort::~SerialPort() { close(); }

SerialPort::SerialPort(SerialPort&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)), is_socket_(other.is_socket_), name_(std::move(other.name_)) {}

SerialPort& SerialPort::operator=(SerialPort&& other) noexcept {
  if (this != &other) {
    close();
    fd_ = std::exchange(other.fd_, -1);
    is_socket_ = other.is_socket_;
    name_ = std::move(other.name_);
  }
  return *this;
}

void SerialPort::open(const std::string& path, int baud) {
  close();
  name_ = "glove port " + path;
  speedFor(baud, name_);  // refuse an unsupported rate before touching the device
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) fail("cannot open", errno);
  try {
    makeRaw(fd, baud, name_);
  } catch (...) {
    ::close(fd);
    throw;
  }
  tcflush(fd, TCIOFLUSH);  // bytes from before we opened belong to nobody
  fd_ = fd;
  is_socket_ = false;
}

void SerialPort::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void SerialPort::fail(const std::string& what, int err) const {
  throw SerialPortError(name_ + ": " + what + ": " + errnoText(err));
}

SerialPort::ReadResult SerialPort::readSome(std::uint8_t* buffer, std::size_t max,
                                            std::chrono::milliseconds timeout) {
  if (fd_ < 0) throw SerialPortError(name_ + ": read: port not open");
  if (max == 0) throw SerialPortError(name_ + ": read: empty buffer");
  const Clock::time_point deadline = Clock::now() + timeout;
  for (;;) {
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, msLeft(deadline));
    if (r < 0) {
      if (errno == EINTR) continue;
      fail("poll", errno);
    }
    if (r == 0) return {ReadStatus::kTimeout, 0};
    if (p.revents & POLLNVAL) fail("poll", EBADF);
    // POLLIN, POLLHUP or POLLERR: read in every case, since bytes sent just before a hang-up
    // are still buffered and belong to the caller.
    const ssize_t k = ::read(fd_, buffer, max);
    if (k > 0) return {ReadStatus::kData, static_cast<std::size_t>(k)};
    if (k == 0) return {ReadStatus::kHangup, 0};  // end of file: a pty's master or a socket peer closed
    const int err = errno;
    if (isHangupErrno(err)) return {ReadStatus::kHangup, 0};
    if (err == EAGAIN || err == EWOULDBLOCK || err == EINTR) {
      if (p.revents & (POLLHUP | POLLERR)) return {ReadStatus::kHangup, 0};
      if (Clock::now() >= deadline) return {ReadStatus::kTimeout, 0};
      continue;  // woken without data: wait out the rest of the timeout
    }
    fail("read", err);
  }
}

bool SerialPort::writeAll(const std::uint8_t* data, std::size_t n, std::chrono::milliseconds timeout) {
  if (fd_ < 0) throw SerialPortError(name_ + ": write: port not open");
  const Clock::time_point deadline = Clock::now() + timeout;
  std::size_t done = 0;
  while (done < n) {
    const ssize_t k = is_socket_ ? ::send(fd_, data + done, n - done, MSG_NOSIGNAL)
                                 : ::write(fd_, data + done, n - done);
    if (k > 0) {
      done += static_cast<std::size_t>(k);
      continue;
    }
    const int err = k == 0 ? EAGAIN : errno;
    if (isHangupErrno(err)) return false;
    if (err == EINTR) continue;
    if (err != EAGAIN && err != EWOULDBLOCK) fail("write", err);
    // Output buffer full: wait for room.
    pollfd p{fd_, POLLOUT, 0};
    const int r = ::poll(&p, 1, msLeft(deadline));
    if (r < 0 && errno != EINTR) fail("poll", errno);
    if (r == 0) fail("write timed out after " + std::to_string(done) + " of " + std::to_string(n) + " bytes", ETIMEDOUT);
    if (r > 0 && (p.revents & POLLHUP)) return false;
    if (r > 0 && (p.revents & POLLNVAL)) fail("poll", EBADF);
  }
  return true;
}

}  // namespace adroit::teleop
