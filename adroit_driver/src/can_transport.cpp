#include "adroit_driver/can_transport.h"

#include <fcntl.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#if defined(__has_include)
#if __has_include(<linux/can.h>) && __has_include(<linux/can/raw.h>) && __has_include(<linux/can/error.h>)
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#define ADROIT_HAVE_LINUX_CAN 1
#endif
#endif

#ifndef ADROIT_HAVE_LINUX_CAN
// Only what opening a PF_CAN socket needs, with the kernel's values (linux/can.h, can/raw.h).
#ifndef AF_CAN
#define AF_CAN 29
#endif
#ifndef PF_CAN
#define PF_CAN AF_CAN
#endif
namespace {
constexpr int CAN_RAW = 1;
constexpr int SOL_CAN_RAW = 101;  // SOL_CAN_BASE + CAN_RAW
constexpr int CAN_RAW_ERR_FILTER = 2;
struct sockaddr_can {
  sa_family_t can_family;
  int can_ifindex;
  alignas(8) unsigned char can_addr[16];
};
}  // namespace
#endif

namespace adroit::driver::can {

#ifdef ADROIT_HAVE_LINUX_CAN
static_assert(CAN_ERR_TX_TIMEOUT == kErrTxTimeout && CAN_ERR_LOSTARB == kErrLostArbitration &&
              CAN_ERR_CRTL == kErrController && CAN_ERR_PROT == kErrProtocol && CAN_ERR_TRX == kErrTransceiver &&
              CAN_ERR_ACK == kErrNoAck && CAN_ERR_BUSOFF == kErrBusOff && CAN_ERR_BUSERROR == kErrBusError &&
              CAN_ERR_RESTARTED == kErrRestarted, "error classes differ from linux/can/error.h");
static_assert(CAN_ERR_CRTL_RX_OVERFLOW == kCtrlRxOverflow && CAN_ERR_CRTL_TX_OVERFLOW == kCtrlTxOverflow &&
              CAN_ERR_CRTL_RX_WARNING == kCtrlRxWarning && CAN_ERR_CRTL_TX_WARNING == kCtrlTxWarning &&
              CAN_ERR_CRTL_RX_PASSIVE == kCtrlRxPassive && CAN_ERR_CRTL_TX_PASSIVE == kCtrlTxPassive &&
              CAN_ERR_CRTL_ACTIVE == kCtrlActive, "controller status bits differ from linux/can/error.h");
#ifdef CAN_ERR_CNT
static_assert(CAN_ERR_CNT == kErrCounters, "error counter class differs from linux/can/error.h");
#endif
#endif

namespace {

// Errors after which the bus is gone for this socket: the peer closed, or the interface
// was removed or taken down.
bool isHangUpErrno(int e) {
  return e == EPIPE || e == ECONNRESET || e == ENOTCONN || e == ENETDOWN || e == ENODEV || e == ENXIO;
}

std::string errnoText(int e) { return std::strerror(e); }

bool fillUnixAddress(const std::string& path, sockaddr_un* addr, std::string* why) {
  std::memset(addr, 0, sizeof *addr);
  addr->sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof addr->sun_path) {
    *why = "a socket path must have 1 to " + std::to_string(sizeof addr->sun_path - 1) + " characters";
    return false;
  }
  std::memcpy(addr->sun_path, path.c_str(), path.size());
  return true;
}

bool fail(std::string* error, const std::string& text) {
  if (error) *error = text;
  return false;
}

// ppoll with a relative timeout (negative, or more than a year: forever); a signal does not
// lengthen the wait.
int waitFor(int fd, short events, std::chrono::nanoseconds timeout, short* revents) {
  using Clock = std::chrono::steady_clock;
  const bool forever = timeout.count() < 0 || timeout > std::chrono::hours(24 * 366);
  const Clock::time_point deadline = Clock::now() + (forever ? std::chrono::nanoseconds(0) : timeout);
  for (;;) {
    pollfd p{fd, events, 0};
    timespec ts{};
    timespec* tsp = nullptr;
    if (!forever) {
      const auto left = std::max(std::chrono::nanoseconds(0), std::chrono::nanoseconds(deadline - Clock::now()));
      ts.tv_sec = static_cast<time_t>(left.count() / 1000000000);
      ts.tv_nsec = static_cast<long>(left.count() % 1000000000);
      tsp = &ts;
    }
    const int n = ppoll(&p, 1, tsp, nullptr);
    if (n < 0 && errno == EINTR) continue;
    *revents = p.revents;
    return n;
  }
}

}  // namespace

// ---------------------------------------------------------------- classification

const char* busStateName(BusState state) {
  switch (state) {
    case BusState::kErrorActive: return "error-active";
    case BusState::kErrorWarning: return "error-warning";
    case BusState::kErrorPassive: return "error-passive";
    case BusState::kBusOff: return "bus-off";
  }
  return "?";
}

const char* ioStatusName(IoStatus status) {
  switch (status) {
    case IoStatus::kOk: return "ok";
    case IoStatus::kTimeout: return "timeout";
    case IoStatus::kFull: return "buffer full";
    case IoStatus::kHangUp: return "hang-up";
    case IoStatus::kError: return "error";
  }
  return "?";
}

ErrorFrameInfo classifyErrorFrame(const CanFrame& frame) {
  ErrorFrameInfo info;
  info.classes = frame.id & kErrMask;
  info.bus_off = (info.classes & kErrBusOff) != 0;
  info.restarted = (info.classes & kErrRestarted) != 0;
  if (info.classes & kErrController) {
    const std::uint8_t status = frame.data[1];
    info.rx_overflow = (status & kCtrlRxOverflow) != 0;
    info.tx_overflow = (status & kCtrlTxOverflow) != 0;
    info.error_warning = (status & (kCtrlRxWarning | kCtrlTxWarning)) != 0;
    info.error_passive = (status & (kCtrlRxPassive | kCtrlTxPassive)) != 0;
    info.back_to_active = (status & kCtrlActive) != 0;
  }
  if (info.classes & kErrCounters) {
    info.has_counters = true;
    info.tx_errors = frame.data[6];
    info.rx_errors = frame.data[7];
  }
  return info;
}

DatagramKind parseDatagram(const void* bytes, std::size_t size, CanFrame* frame) {
  if (size != sizeof(CanFrame)) return DatagramKind::kWrongSize;
  CanFrame f;
  std::memcpy(&f, bytes, sizeof f);
  if (isErrorFrame(f)) {
    *frame = f;
    return DatagramKind::kErrorFrame;
  }
  if (f.dlc > kMaxDataLength) return DatagramKind::kBadDlc;
  *frame = f;
  return DatagramKind::kDataFrame;
}

// ---------------------------------------------------------------- CanTransport

CanTransport::CanTransport(int fd, std::string name) : fd_(fd), name_(std::move(name)) {}

CanTransport::~CanTransport() {
  if (fd_ >= 0) ::close(fd_);
}

CanTransport::CanTransport(CanTransport&& other) noexcept
    : fd_(other.fd_),
      name_(std::move(other.name_)),
      hung_up_(other.hung_up_),
      last_error_(other.last_error_),
      bus_state_(other.bus_state_),
      counters_(other.counters_) {
  other.fd_ = -1;
}

CanTransport& CanTransport::operator=(CanTransport&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = other.fd_;
    name_ = std::move(other.name_);
    hung_up_ = other.hung_up_;
    last_error_ = other.last_error_;
    bus_state_ = other.bus_state_;
    counters_ = other.counters_;
    other.fd_ = -1;
  }
  return *this;
}

bool CanTransport::peerGone() const {
  pollfd p{fd_, POLLRDHUP, 0};
  return ::poll(&p, 1, 0) > 0 && (p.revents & (POLLHUP | POLLRDHUP)) != 0;
}

void CanTransport::handleErrorFrame(const CanFrame& frame) {
  const ErrorFrameInfo info = classifyErrorFrame(frame);
  TransportCounters& c = counters_;
  ++c.error_frames;
  if (info.classes & kErrController) ++c.controller_problems;
  if (info.rx_overflow || info.tx_overflow) ++c.overflows;
  if (info.classes & (kErrProtocol | kErrBusError)) ++c.protocol_errors;
  if (info.classes & kErrNoAck) ++c.no_ack;
  if (info.classes & kErrLostArbitration) ++c.lost_arbitration;
  if (info.classes & kErrTxTimeout) ++c.tx_timeouts;
  if (info.classes & kErrTransceiver) ++c.transceiver_errors;
  // The state follows the most severe news of this frame; a restart or "active again"
  // ends bus-off / passive.
  if (info.bus_off) {
    ++c.bus_off;
    bus_state_ = BusState::kBusOff;
  } else if (info.error_passive) {
    ++c.error_passive;
    bus_state_ = BusState::kErrorPassive;
  } else if (info.error_warning) {
    ++c.error_warning;
    bus_state_ = BusState::kErrorWarning;
  } else if (info.restarted || info.back_to_active) {
    if (info.restarted) ++c.restarts;
    bus_state_ = BusState::kErrorActive;
  }
}

ReadResult CanTransport::read(CanFrame* frames, std::size_t max, std::chrono::nanoseconds timeout) {
  ReadResult result;
  short revents = 0;
  const int ready = waitFor(fd_, POLLIN, timeout, &revents);
  if (ready < 0) {
    last_error_ = errno;
    ++counters_.read_errors;
    result.status = IoStatus::kError;
    result.error = last_error_;
    return result;
  }
  if (ready == 0) {
    result.status = hung_up_ ? IoStatus::kHangUp : IoStatus::kTimeout;
    return result;
  }
  // Bounded, so that a peer flooding bad datagrams or error frames cannot hold us here.
  std::size_t budget = max + 64;
  while (result.count < max && budget-- > 0) {
    // Larger than a frame, and MSG_TRUNC reports a longer datagram's real size.
    alignas(8) unsigned char buffer[2 * sizeof(CanFrame)];
    const ssize_t got = ::recv(fd_, buffer, sizeof buffer, MSG_DONTWAIT | MSG_TRUNC);
    if (got < 0) {
      const int e = errno;
      if (e == EINTR) continue;
      if (e == EAGAIN || e == EWOULDBLOCK) break;
      last_error_ = e;
      if (isHangUpErrno(e)) {
        hung_up_ = true;
        break;
      }
      ++counters_.read_errors;
      result.status = IoStatus::kError;
      result.error = e;
      return result;
    }
    if (got == 0) {
      // End of stream or an empty datagram: only the peer's hang-up tells them apart.
      if (peerGone()) {
        hung_up_ = true;
        break;
      }
      ++counters_.wrong_size;
      continue;
    }
    CanFrame frame;
    switch (parseDatagram(buffer, static_cast<std::size_t>(got), &frame)) {
      case DatagramKind::kDataFrame:
        frames[result.count++] = frame;
        ++counters_.frames_read;
        break;
      case DatagramKind::kErrorFrame: handleErrorFrame(frame); break;
      case DatagramKind::kWrongSize: ++counters_.wrong_size; break;
      case DatagramKind::kBadDlc: ++counters_.bad_dlc; break;
    }
  }
  if (hung_up_) result.status = IoStatus::kHangUp;
  return result;
}

IoStatus CanTransport::write(const CanFrame& frame) {
  if (frame.dlc > kMaxDataLength) {  // a frame no bus can carry
    last_error_ = EINVAL;
    ++counters_.write_errors;
    return IoStatus::kError;
  }
  for (;;) {
    const ssize_t n = ::send(fd_, &frame, sizeof frame, MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(sizeof frame)) {
      ++counters_.frames_written;
      return IoStatus::kOk;
    }
    const int e = n < 0 ? errno : EMSGSIZE;
    if (e == EINTR) continue;
    last_error_ = e;
    // ENOBUFS: a PF_CAN interface's transmit queue is full.
    if (e == EAGAIN || e == EWOULDBLOCK || e == ENOBUFS) {
      ++counters_.write_full;
      return IoStatus::kFull;
    }
    if (isHangUpErrno(e)) {
      hung_up_ = true;
      return IoStatus::kHangUp;
    }
    ++counters_.write_errors;
    return IoStatus::kError;
  }
}

// ---------------------------------------------------------------- opening

std::optional<CanTransport> openSocketCan(const std::string& interface, std::string* error) {
  const std::string what = "cannot open CAN interface '" + interface + "': ";
  if (interface.empty() || interface.size() >= IFNAMSIZ) {
    fail(error, what + "not an interface name (1 to " + std::to_string(IFNAMSIZ - 1) + " characters)");
    return std::nullopt;
  }
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    const int e = errno;
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT) {
      fail(error, what + "this kernel does not support SocketCAN raw sockets (" + errnoText(e) +
                      "); load the can and can_raw modules, or use an emulator bus \"unix:<path>\"");
    } else {
      fail(error, what + "socket(PF_CAN): " + errnoText(e));
    }
    return std::nullopt;
  }
  const unsigned index = ::if_nametoindex(interface.c_str());
  if (index == 0) {
    const int e = errno;
    ::close(fd);
    fail(error, what + "no such network interface (" + errnoText(e) + ")");
    return std::nullopt;
  }
  // Error frames: every class. Without this option (old kernels) the bus state stays unknown.
  const std::uint32_t error_mask = kErrMask;
  (void)::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &error_mask, sizeof error_mask);
  sockaddr_can address{};
  address.can_family = AF_CAN;
  address.can_ifindex = static_cast<int>(index);
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) < 0) {
    const int e = errno;
    ::close(fd);
    fail(error, what + "bind: " + errnoText(e));
    return std::nullopt;
  }
  return CanTransport(fd, interface);
}

std::optional<CanTransport> openSeqpacket(const std::string& path, std::string* error) {
  const std::string what = "cannot connect to CAN emulator socket '" + path + "': ";
  sockaddr_un address;
  std::string why;
  if (!fillUnixAddress(path, &address, &why)) {
    fail(error, what + why);
    return std::nullopt;
  }
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    fail(error, what + "socket: " + errnoText(errno));
    return std::nullopt;
  }
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) < 0) {
    const int e = errno;
    ::close(fd);
    const bool absent = e == ENOENT || e == ECONNREFUSED;
    fail(error, what + errnoText(e) + (absent ? " (is the emulator running?)" : ""));
    return std::nullopt;
  }
  return CanTransport(fd, path);
}

std::optional<SeqpacketListener> listenSeqpacket(const std::string& path, std::string* error) {
  const std::string what = "cannot listen on CAN emulator socket '" + path + "': ";
  sockaddr_un address;
  std::string why;
  if (!fillUnixAddress(path, &address, &why)) {
    fail(error, what + why);
    return std::nullopt;
  }
  struct stat info;
  if (::lstat(path.c_str(), &info) == 0) {
    if (!S_ISSOCK(info.st_mode)) {
      fail(error, what + "the path exists and is not a socket");
      return std::nullopt;
    }
    // A socket file: in use if something accepts connections there, else stale.
    const int probe = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
    const bool live = probe >= 0 && ::connect(probe, reinterpret_cast<const sockaddr*>(&address), sizeof address) == 0;
    if (probe >= 0) ::close(probe);
    if (live) {
      fail(error, what + "another process is listening there");
      return std::nullopt;
    }
    ::unlink(path.c_str());
  }
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    fail(error, what + "socket: " + errnoText(errno));
    return std::nullopt;
  }
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address) < 0 || ::listen(fd, 4) < 0) {
    const int e = errno;
    ::close(fd);
    fail(error, what + errnoText(e));
    return std::nullopt;
  }
  return SeqpacketListener(fd, path);
}

std::optional<CanTransport> openBus(const std::string& spec, std::string* error) {
  const std::string unix_prefix = "unix:";
  if (spec.compare(0, unix_prefix.size(), unix_prefix) == 0) return openSeqpacket(spec.substr(unix_prefix.size()), error);
  return openSocketCan(spec, error);
}

// ---------------------------------------------------------------- SeqpacketListener

SeqpacketListener::~SeqpacketListener() {
  if (fd_ >= 0) {
    ::close(fd_);
    ::unlink(path_.c_str());
  }
}

SeqpacketListener::SeqpacketListener(SeqpacketListener&& other) noexcept
    : fd_(other.fd_), path_(std::move(other.path_)) {
  other.fd_ = -1;
}

SeqpacketListener& SeqpacketListener::operator=(SeqpacketListener&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) {
      ::close(fd_);
      ::unlink(path_.c_str());
    }
    fd_ = other.fd_;
    path_ = std::move(other.path_);
    other.fd_ = -1;
  }
  return *this;
}

std::optional<CanTransport> SeqpacketListener::accept(std::chrono::nanoseconds timeout, std::string* error) {
  if (error) error->clear();
  short revents = 0;
  const int ready = waitFor(fd_, POLLIN, timeout, &revents);
  if (ready < 0) {
    fail(error, "accept on '" + path_ + "': " + errnoText(errno));
    return std::nullopt;
  }
  if (ready == 0) return std::nullopt;  // timeout: *error stays empty
  const int fd = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
  if (fd < 0) {
    fail(error, "accept on '" + path_ + "': " + errnoText(errno));
    return std::nullopt;
  }
  return CanTransport(fd, path_);
}

}  // namespace adroit::driver::can
