// CAN frames over a file descriptor that carries one 16-byte CanFrame per datagram: a
// PF_CAN raw socket bound to an interface (the robot), or a Unix-domain SOCK_SEQPACKET
// socket (machines without SocketCAN: the hardware emulator listens on a path, the
// driver connects; tests use socketpair()). Reading waits with ppoll(); writing never
// blocks, so the driver's control loop never waits on the bus. Error frames from the CAN
// controller are classified and counted, never returned as data.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include "adroit_driver/can_frame.h"

namespace adroit::driver::can {

// Error classes (CanFrame::id of an error frame) and controller status bits (data[1]),
// with the values of <linux/can/error.h>.
constexpr std::uint32_t kErrTxTimeout = 0x001;
constexpr std::uint32_t kErrLostArbitration = 0x002;
constexpr std::uint32_t kErrController = 0x004;
constexpr std::uint32_t kErrProtocol = 0x008;
constexpr std::uint32_t kErrTransceiver = 0x010;
constexpr std::uint32_t kErrNoAck = 0x020;
constexpr std::uint32_t kErrBusOff = 0x040;
constexpr std::uint32_t kErrBusError = 0x080;
constexpr std::uint32_t kErrRestarted = 0x100;
constexpr std::uint32_t kErrCounters = 0x200;  // data[6] tx, data[7] rx error counters
constexpr std::uint8_t kCtrlRxOverflow = 0x01;
constexpr std::uint8_t kCtrlTxOverflow = 0x02;
constexpr std::uint8_t kCtrlRxWarning = 0x04;
constexpr std::uint8_t kCtrlTxWarning = 0x08;
constexpr std::uint8_t kCtrlRxPassive = 0x10;
constexpr std::uint8_t kCtrlTxPassive = 0x20;
constexpr std::uint8_t kCtrlActive = 0x40;  // back to error active

enum class BusState : std::uint8_t { kErrorActive, kErrorWarning, kErrorPassive, kBusOff };
const char* busStateName(BusState state);

struct ErrorFrameInfo {
  std::uint32_t classes = 0;  // kErr* bits
  bool bus_off = false;
  bool error_passive = false;   // tx or rx error counter >= 128
  bool error_warning = false;   // tx or rx error counter >= 96
  bool back_to_active = false;  // the controller recovered to error active
  bool restarted = false;       // the controller was restarted after bus-off
  bool rx_overflow = false;     // frames lost in the controller or driver
  bool tx_overflow = false;
  bool has_counters = false;
  std::uint8_t tx_errors = 0, rx_errors = 0;
};
// Meaning of an error frame (isErrorFrame(frame) must hold).
ErrorFrameInfo classifyErrorFrame(const CanFrame& frame);

// What one received datagram is. A datagram of the wrong size (which a PF_CAN socket never
// delivers, but a seqpacket peer might) or a frame with dlc > 8 is dropped, never trusted.
enum class DatagramKind : std::uint8_t { kDataFrame, kErrorFrame, kWrongSize, kBadDlc };
DatagramKind parseDatagram(const void* bytes, std::size_t size, CanFrame* frame);

enum class IoStatus : std::uint8_t {
  kOk,
  kTimeout,  // read: nothing arrived in time
  kFull,     // write: the socket's buffer is full; the frame was not sent
  kHangUp,   // the peer closed, or the interface went away
  kError,    // anything else (errno in the result)
};
const char* ioStatusName(IoStatus status);

struct ReadResult {
  std::size_t count = 0;  // data frames stored
  IoStatus status = IoStatus::kOk;
  int error = 0;          // errno for kError
};

struct TransportCounters {
  std::uint64_t frames_read = 0;
  std::uint64_t frames_written = 0;
  std::uint64_t wrong_size = 0;    // datagrams that were not one 16-byte frame (dropped)
  std::uint64_t bad_dlc = 0;       // 16-byte datagrams with dlc > 8 (dropped)
  std::uint64_t write_full = 0;    // frames not sent because the buffer was full
  std::uint64_t write_errors = 0;
  std::uint64_t read_errors = 0;
  std::uint64_t error_frames = 0;  // every error frame, then by meaning:
  std::uint64_t bus_off = 0;
  std::uint64_t error_passive = 0;
  std::uint64_t error_warning = 0;
  std::uint64_t controller_problems = 0;  // kErrController frames (overflows, state changes)
  std::uint64_t overflows = 0;            // rx/tx overflow reported by the controller
  std::uint64_t protocol_errors = 0;      // kErrProtocol / kErrBusError
  std::uint64_t no_ack = 0;
  std::uint64_t lost_arbitration = 0;
  std::uint64_t tx_timeouts = 0;
  std::uint64_t transceiver_errors = 0;
  std::uint64_t restarts = 0;
};

class CanTransport {
 public:
  // Takes ownership of `fd` (closed on destruction), a socket carrying 16-byte datagrams.
  // `name` (interface or path) only appears in messages.
  explicit CanTransport(int fd, std::string name = "fd");
  ~CanTransport();
  CanTransport(CanTransport&& other) noexcept;
  CanTransport& operator=(CanTransport&& other) noexcept;
  CanTransport(const CanTransport&) = delete;
  CanTransport& operator=(const CanTransport&) = delete;

  // Waits up to `timeout` (zero: do not wait; negative: forever) for the socket to be
  // readable, then reads without waiting until `max` data frames are stored or nothing is
  // left. Error frames and bad datagrams are counted, not stored. Frames that arrived before
  // a hang-up are returned with status kHangUp. Allocates nothing.
  ReadResult read(CanFrame* frames, std::size_t max, std::chrono::nanoseconds timeout);

  // Sends one frame without ever blocking: kFull (counted) when the buffer is full.
  IoStatus write(const CanFrame& frame);

  int lastError() const { return last_error_; }  // errno of the last failed read or write

  int fd() const { return fd_; }
  const std::string& name() const { return name_; }
  bool hungUp() const { return hung_up_; }
  BusState busState() const { return bus_state_; }  // from the error frames seen
  const TransportCounters& counters() const { return counters_; }

 private:
  void handleErrorFrame(const CanFrame& frame);
  bool peerGone() const;

  int fd_ = -1;
  std::string name_;
  bool hung_up_ = false;
  int last_error_ = 0;
  BusState bus_state_ = BusState::kErrorActive;
  TransportCounters counters_;
};

// PF_CAN raw socket bound to `interface` (e.g. "can0"), with every error class enabled
// where the kernel supports CAN_RAW_ERR_FILTER. On failure nullopt and one line in *error
// naming the interface and the reason (no PF_CAN support, no such interface, ...).
std::optional<CanTransport> openSocketCan(const std::string& interface, std::string* error);

// Connects to the emulator's seqpacket socket at `path`.
std::optional<CanTransport> openSeqpacket(const std::string& path, std::string* error);

// The emulator's side: a listening seqpacket socket at a path, one CanTransport per
// connection. The socket file is removed on destruction.
class SeqpacketListener {
 public:
  SeqpacketListener(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~SeqpacketListener();
  SeqpacketListener(SeqpacketListener&& other) noexcept;
  SeqpacketListener& operator=(SeqpacketListener&& other) noexcept;
  SeqpacketListener(const SeqpacketListener&) = delete;
  SeqpacketListener& operator=(const SeqpacketListener&) = delete;

  // Waits up to `timeout` (negative: forever) for a connection. nullopt with *error empty
  // on timeout, with the reason on failure.
  std::optional<CanTransport> accept(std::chrono::nanoseconds timeout, std::string* error);
  int fd() const { return fd_; }
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  std::string path_;
};

// Listens at `path`. A stale socket file left by a dead emulator is replaced; a path where
// someone still listens, or that is not a socket, is refused.
std::optional<SeqpacketListener> listenSeqpacket(const std::string& path, std::string* error);

// One bus given as text, as a driver parameter holds it: "unix:<path>" connects to an
// emulator, anything else is a SocketCAN interface name.
std::optional<CanTransport> openBus(const std::string& spec, std::string* error);

}  // namespace adroit::driver::can
