// The host side of the CyberGlove link, ROS-free: opens the port, asks the glove for its
// sensor count, starts streaming (or polls at a rate), parses records, notices a stale or
// unplugged glove and reconnects with a growing back-off. It never throws after
// construction: every failure becomes state, lastError() and a retry.
//
//   GloveDriver glove(config);
//   std::vector<GloveDriver::Record> records;
//   while (running) { records.clear(); glove.spinOnce(std::chrono::milliseconds(10), records); ... }
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "adroit_teleop/glove_protocol.h"
#include "adroit_teleop/serial_port.h"

namespace adroit::teleop {

struct GloveDriverConfig {
  std::string port;           // e.g. /dev/ttyUSB0, or the emulator's link /tmp/adroit_glove
  int baud = 115200;
  int sensors = 0;            // 18 or 22; 0 = ask the glove ("?S")
  bool stream = true;         // streaming records ('S'); false = poll one record ('G') per period
  double poll_rate = 100.0;   // Hz, polled mode
  double stale_after = 0.1;   // s without a valid record: the glove is stale
  double retry_min = 0.1;     // s, first reconnection delay; doubles up to retry_max
  double retry_max = 2.0;
};

// Empty when valid, else one line naming the field ("port must name a serial device").
std::string validate(const GloveDriverConfig& config);

class GloveDriver {
 public:
  using Clock = std::chrono::steady_clock;
  enum class State {
    kDisconnected,  // port closed; the next attempt is due at retryAt()
    kQuerying,      // port open, waiting for the answer to "?S"
    kRunning,       // records flow (or are polled)
  };
  struct Record {
    GloveFrame frame;
    Clock::time_point arrival;  // when the read that completed it returned
  };

  explicit GloveDriver(GloveDriverConfig config);  // std::invalid_argument on a bad config

  // One turn: opens the port when a retry is due, reads what arrives within `timeout` and
  // appends the complete records. Sleeps out the timeout while disconnected.
  void spinOnce(std::chrono::milliseconds timeout, std::vector<Record>& out);
  // Stops streaming and closes the port (also done by the destructor).
  void close();

  State state() const { return state_; }
  bool stale(Clock::time_point now = Clock::now()) const;
  int sensors() const { return parser_.sensorCount(); }
  // The newest problem, e.g. "glove port /dev/ttyUSB0: cannot open: No such file or
  // directory" or "glove reports: glove not plugged in"; empty while records flow.
  const std::string& lastError() const { return last_error_; }
  const ParserStats& parserStats() const { return parser_.stats(); }
  std::uint64_t connects() const { return connects_; }       // successful opens
  std::uint64_t disconnects() const { return disconnects_; } // hang-ups and stale links closed
  Clock::time_point retryAt() const { return retry_at_; }
  double retryDelay() const { return retry_delay_; }

 private:
  void tryOpen(Clock::time_point now);
  void drop(const std::string& why, Clock::time_point now);  // close, then retry later
  bool send(const std::vector<std::uint8_t>& bytes, Clock::time_point now);
  void handle(const GloveFrame& frame, Clock::time_point now, std::vector<Record>& out);

  GloveDriverConfig config_;
  SerialPort port_;
  GloveParser parser_;
  State state_ = State::kDisconnected;
  std::string last_error_;
  Clock::time_point retry_at_{}, last_record_{}, opened_at_{}, next_poll_{}, query_sent_{};
  double retry_delay_;
  std::uint64_t connects_ = 0, disconnects_ = 0;
  std::vector<GloveFrame> frames_;  // parser output, reused
  std::vector<std::uint8_t> buffer_ = std::vector<std::uint8_t>(4096);
};

}  // namespace adroit::teleop
