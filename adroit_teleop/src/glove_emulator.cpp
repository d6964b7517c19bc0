#include "adroit_teleop/glove_emulator.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <limits>

namespace adroit::teleop {

// --- SyntheticTrajectory -------------------------------------------------------------------

SyntheticTrajectory::SyntheticTrajectory(int sensors, double period) : sensors_(sensors), period_(period) {
  if (!validSensorCount(sensors))
    throw std::invalid_argument("synthetic trajectory: sensor count must be 18 or 22, got " + std::to_string(sensors));
  if (!(period > 0) || !std::isfinite(period))
    throw std::invalid_argument("synthetic trajectory: period must be > 0 s");
}

void SyntheticTrajectory::sample(double t, std::uint8_t* out) const {
  for (int i = 0; i < sensors_; ++i) {
    const double phase = 2 * M_PI * i / sensors_;
    const double v = 128 + 100 * std::sin(2 * M_PI * t / period_ + phase);
    out[i] = static_cast<std::uint8_t>(std::lround(v));
  }
}

// --- CsvTrajectory -------------------------------------------------------------------------

namespace {

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> splitCommas(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = line.find(',', start);
    fields.push_back(trim(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start)));
    if (comma == std::string::npos) return fields;
    start = comma + 1;
  }
}

bool parseNumber(const std::string& s, double* x) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *x = std::strtod(s.c_str(), &end);
  return *end == '\0' && errno == 0;
}

std::string fmt(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", x);
  return buf;
}

// The file's text: a regular file of at most kMaxTrajectoryFileBytes (a FIFO, a device or a
// directory is refused unread, so the load never blocks). Throws TrajectoryError "<path>: ...".
std::string readTrajectoryText(const std::string& path) {
  try {
    return readBoundedFile(path, kMaxTrajectoryFileBytes);
  } catch (const FileError& e) {
    throw TrajectoryError(e.what());
  }
}

}  // namespace

CsvTrajectory CsvTrajectory::load(const std::string& path, int sensors) {
  if (!validSensorCount(sensors))
    throw TrajectoryError(path + ": sensor count must be 18 or 22, got " + std::to_string(sensors));
  std::istringstream in(readTrajectoryText(path));
  CsvTrajectory traj;
  traj.sensors_ = sensors;
  const std::size_t columns = static_cast<std::size_t>(sensors) + 1;
  double first_time = 0, previous = 0;
  bool seen_row = false;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const std::string where = path + ":" + std::to_string(number) + ": ";
    const std::string text = trim(line);
    if (text.empty() || text[0] == '#') continue;
    const std::vector<std::string> fields = splitCommas(text);
    double t;
    // A header names the columns: allowed once, before any sample.
    if (!seen_row && traj.times_.empty() && !parseNumber(fields[0], &t)) {
      seen_row = true;
      continue;
    }
    seen_row = true;
    if (fields.size() != columns)
      throw TrajectoryError(where + "expected " + std::to_string(columns) + " columns (t and " +
                            std::to_string(sensors) + " sensor values), got " + std::to_string(fields.size()));
    for (std::size_t c = 0; c < columns; ++c) {
      double x;
      if (!parseNumber(fields[c], &x) || !std::isfinite(x))
        throw TrajectoryError(where + "column " + std::to_string(c + 1) + ": '" + fields[c] + "' is not a number");
      if (c == 0) {
        if (!traj.times_.empty() && !(x > previous))
          throw TrajectoryError(where + "time " + fmt(x) + " is not after the previous row's " + fmt(previous));
        if (traj.times_.empty()) first_time = x;
        previous = x;
        traj.times_.push_back(x - first_time);
        continue;
      }
      const double v = std::round(x);
      if (v < 1 || v > 255)
        throw TrajectoryError(where + "sensor " + std::to_string(c) + " value " + fmt(x) + " is outside 1..255");
      traj.values_.push_back(static_cast<std::uint8_t>(v));
    }
  }
  if (traj.times_.empty()) throw TrajectoryError(path + ": no samples");
  const std::size_t m = traj.times_.size();
  traj.loop_ = m == 1 ? 0 : traj.times_[m - 1] + (traj.times_[m - 1] - traj.times_[m - 2]);
  return traj;
}

void CsvTrajectory::sample(double t, std::uint8_t* out) const {
  std::size_t row = 0;
  if (loop_ > 0) {
    double u = std::fmod(std::max(t, 0.0), loop_);
    // The last row whose time is <= u.
    row = static_cast<std::size_t>(std::upper_bound(times_.begin(), times_.end(), u) - times_.begin()) - 1;
  }
  std::copy_n(values_.begin() + row * sensors_, sensors_, out);
}

// --- GloveEmulator -------------------------------------------------------------------------

GloveEmulator::GloveEmulator(const EmulatorOptions& options, std::shared_ptr<const GloveTrajectory> trajectory)
    : options_(options), trajectory_(std::move(trajectory)), rng_(options.seed) {
  if (!validSensorCount(options_.sensors))
    throw std::invalid_argument("glove emulator: sensors must be 18 or 22, got " + std::to_string(options_.sensors));
  if (!(options_.rate_hz >= 1 && options_.rate_hz <= 1000))
    throw std::invalid_argument("glove emulator: rate must be in 1..1000 Hz, got " + fmt(options_.rate_hz));
  if (options_.garbage_every < 0) throw std::invalid_argument("glove emulator: garbage_every must be >= 0");
  if (!trajectory_) throw std::invalid_argument("glove emulator: no trajectory");
  if (trajectory_->sensors() != options_.sensors)
    throw std::invalid_argument("glove emulator: trajectory has " + std::to_string(trajectory_->sensors()) +
                                " sensors, the glove " + std::to_string(options_.sensors));
}

void GloveEmulator::reset() {
  streaming_ = false;
  commands_.reset();
}

double GloveEmulator::nextDeadline() const {
  if (!streaming_) return std::numeric_limits<double>::infinity();
  return stream_start_ + static_cast<double>(stream_index_) / options_.rate_hz;
}

void GloveEmulator::sendError(GloveError code, EmulatorOutput& out) {
  appendError(out.bytes, code);
  ++stats_.error_replies;
}

void GloveEmulator::sendRecord(bool streamed, double t, EmulatorOutput& out) {
  SentRecord r;
  r.sequence = sequence_++;
  r.streamed = streamed;
  r.t = t;
  r.count = options_.sensors;
  trajectory_->sample(t, r.values.data());
  appendRecord(out.bytes, streamed, r.values.data(), r.count);
  out.records.push_back(r);
  ++(streamed ? stats_.streamed_records : stats_.polled_records);
  if (options_.garbage_every > 0 && sequence_ % static_cast<std::uint64_t>(options_.garbage_every) == 0) {
    // Garbage bytes are never 0, so they cannot complete a frame together with the real
    // bytes around them: a parser skips exactly these bytes and loses no record.
    std::uniform_int_distribution<int> length(1, 8), byte(1, 255);
    const int n = length(rng_);
    for (int i = 0; i < n; ++i) out.bytes.push_back(static_cast<std::uint8_t>(byte(rng_)));
    stats_.garbage_bytes += n;
  }
}

void GloveEmulator::receive(const std::uint8_t* bytes, std::size_t n, double t, EmulatorOutput& out) {
  pending_.clear();
  commands_.feed(bytes, n, pending_);
  for (GloveCommand c : pending_) {
    switch (c) {
      case GloveCommand::kPoll:
        if (options_.glove_error) sendError(GloveError::kGloveUnplugged, out);
        else sendRecord(false, t, out);
        break;
      case GloveCommand::kStartStream:
        if (options_.glove_error) {
          sendError(GloveError::kGloveUnplugged, out);
        } else if (!streaming_) {  // 'S' while streaming changes nothing
          streaming_ = true;
          stream_start_ = t;
          stream_index_ = 0;
        }
        break;
      case GloveCommand::kStopStream:
        streaming_ = false;
        break;
      case GloveCommand::kQuerySensorCount:
        if (options_.glove_error) sendError(GloveError::kGloveUnplugged, out);
        else appendCountReply(out.bytes, options_.sensors);
        break;
      case GloveCommand::kUnknown:
        ++stats_.unknown_commands;
        sendError(GloveError::kUnknownCommand, out);
        break;
    }
  }
}

void GloveEmulator::tick(double t, EmulatorOutput& out) {
  if (!streaming_ || t < nextDeadline()) return;
  sendRecord(true, nextDeadline(), out);
  ++stream_index_;
  while (nextDeadline() <= t) {
    ++stream_index_;
    ++stats_.missed_deadlines;
  }
}

DeferredTrajectory::DeferredTrajectory(std::shared_ptr<const GloveTrajectory> motion) : motion_(std::move(motion)) {
  if (!motion_) throw std::invalid_argument("DeferredTrajectory: no motion");
}

void DeferredTrajectory::sample(double t, std::uint8_t* out) const {
  motion_->sample(t < start_ ? 0.0 : t - start_, out);
}

}  // namespace adroit::teleop
