#include "adroit_teleop/glove_driver.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace adroit::teleop {

namespace {

using Seconds = std::chrono::duration<double>;

GloveDriver::Clock::duration toDuration(double seconds) {
  return std::chrono::duration_cast<GloveDriver::Clock::duration>(Seconds(seconds));
}

bool positive(double v) { return std::isfinite(v) && v > 0; }

}  // namespace

std::string validate(const GloveDriverConfig& c) {
  if (c.port.empty()) return "port must name the glove's serial device (or the emulator's link)";
  if (!baudRateSupported(c.baud)) return "baud " + std::to_string(c.baud) + " is not a supported rate";
  if (c.sensors != 0 && !validSensorCount(c.sensors)) return "sensors must be 18, 22 or 0 (ask the glove)";
  if (!positive(c.poll_rate) || c.poll_rate > 1000) return "poll_rate must be in (0, 1000] Hz";
  if (!positive(c.stale_after)) return "stale_after must be > 0 s";
  if (!positive(c.retry_min) || !positive(c.retry_max) || c.retry_max < c.retry_min)
    return "retry_min and retry_max must be > 0 s with retry_min <= retry_max";
  return "";
}

GloveDriver::GloveDriver(GloveDriverConfig config)
    : config_(std::move(config)),
      parser_(config_.sensors != 0 ? config_.sensors : kSensors22),
      retry_delay_(config_.retry_min) {
  const std::string error = validate(config_);
  if (!error.empty()) throw std::invalid_argument("glove driver: " + error);
}

bool GloveDriver::stale(Clock::time_point now) const {
  return state_ != State::kRunning || now - last_record_ > toDuration(config_.stale_after);
}

void GloveDriver::close() {
  if (port_.isOpen() && config_.stream) {
    try {
      port_.writeAll(encodeCommand(GloveCommand::kStopStream), std::chrono::milliseconds(50));
    } catch (const SerialPortError&) {
    }
  }
  port_.close();
  state_ = State::kDisconnected;
}

void GloveDriver::drop(const std::string& why, Clock::time_point now) {
  last_error_ = why;
  close();
  ++disconnects_;
  retry_at_ = now + toDuration(retry_delay_);
  retry_delay_ = std::min(2.0 * retry_delay_, config_.retry_max);
}

bool GloveDriver::send(const std::vector<std::uint8_t>& bytes, Clock::time_point now) {
  try {
    if (port_.writeAll(bytes, std::chrono::milliseconds(100))) return true;
    drop(port_.name() + ": the other end hung up", now);
  } catch (const SerialPortError& e) {
    drop(e.what(), now);
  }
  return false;
}

void GloveDriver::tryOpen(Clock::time_point now) {
  try {
    port_.open(config_.port, config_.baud);
  } catch (const SerialPortError& e) {
    last_error_ = e.what();
    retry_at_ = now + toDuration(retry_delay_);
    retry_delay_ = std::min(2.0 * retry_delay_, config_.retry_max);
    return;
  }
  ++connects_;
  opened_at_ = now;
  parser_.resetWindow();
  // Whatever the glove was doing (streaming for a previous host), stop it first.
  if (!send(encodeCommand(GloveCommand::kStopStream), now)) return;
  if (config_.sensors == 0) {
    state_ = State::kQuerying;
    query_sent_ = now;
    send(encodeCommand(GloveCommand::kQuerySensorCount), now);
    return;
  }
  state_ = State::kRunning;
  last_record_ = now;  // staleness counts from the start
  next_poll_ = now;
  if (config_.stream) send(encodeCommand(GloveCommand::kStartStream), now);
}

void GloveDriver::handle(const GloveFrame& frame, Clock::time_point now, std::vector<Record>& out) {
  switch (frame.type) {
    case FrameType::kSensorCount:
      if (state_ != State::kQuerying) return;
      parser_.setSensorCount(frame.count);
      state_ = State::kRunning;
      last_record_ = now;
      next_poll_ = now;
      if (config_.stream) send(encodeCommand(GloveCommand::kStartStream), now);
      return;
    case FrameType::kError:
      last_error_ = std::string("glove reports: ") + gloveErrorText(frame.error);
      return;
    case FrameType::kPolledRecord:
    case FrameType::kStreamedRecord:
      if (state_ != State::kRunning || frame.count != parser_.sensorCount()) return;
      last_record_ = now;
      last_error_.clear();
      retry_delay_ = config_.retry_min;  // a working link resets the back-off
      out.push_back({frame, now});
      return;
  }
}

void GloveDriver::spinOnce(std::chrono::milliseconds timeout, std::vector<Record>& out) {
  Clock::time_point now = Clock::now();
  if (state_ == State::kDisconnected) {
    if (now < retry_at_) {
      std::this_thread::sleep_for(std::min<Clock::duration>(timeout, retry_at_ - now));
      return;
    }
    tryOpen(now);
    if (state_ == State::kDisconnected) return;
  }
  // A glove that stopped answering (unplugged from the interface unit, a lost "?S" reply, a
  // streaming command lost in line noise) is closed and opened again: that re-sends them.
  const double silent_for = config_.stale_after * 10;
  if ((state_ == State::kQuerying && now - query_sent_ > toDuration(silent_for)) ||
      (state_ == State::kRunning && now - last_record_ > toDuration(silent_for))) {
    drop(last_error_.empty() ? port_.name() + ": no valid record for " + std::to_string(silent_for) + " s"
                             : last_error_,
         now);
    return;
  }
  if (state_ == State::kRunning && !config_.stream && now >= next_poll_) {
    next_poll_ = std::max(next_poll_ + toDuration(1.0 / config_.poll_rate), now);
    if (!send(encodeCommand(GloveCommand::kPoll), now)) return;
  }
  auto wait = timeout;
  if (state_ == State::kRunning && !config_.stream)
    wait = std::min(wait, std::chrono::duration_cast<std::chrono::milliseconds>(next_poll_ - now));
  SerialPort::ReadResult r;
  try {
    r = port_.readSome(buffer_.data(), buffer_.size(), std::max(wait, std::chrono::milliseconds(0)));
  } catch (const SerialPortError& e) {
    drop(e.what(), Clock::now());
    return;
  }
  now = Clock::now();
  if (r.status == SerialPort::ReadStatus::kHangup) {
    drop(port_.name() + ": the glove went away (hang-up)", now);
    return;
  }
  if (r.bytes == 0) return;
  frames_.clear();
  parser_.feed(buffer_.data(), r.bytes, frames_);
  for (const GloveFrame& f : frames_) handle(f, now, out);
}

}  // namespace adroit::teleop
