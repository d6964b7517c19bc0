// The glove side of the protocol, without a device: what a CyberGlove answers to the host's
// bytes, and what it sends while streaming. The emulator program (tools/glove_emulator.cpp)
// puts this behind a pseudo-terminal; tests drive it directly with bytes and times.
//
//   GloveEmulator glove(options, std::make_shared<SyntheticTrajectory>(22, 4.0));
//   EmulatorOutput out;
//   glove.receive(bytes, n, t, out);   // answers to commands (polled records, errors...)
//   glove.tick(t, out);                // streamed records whose deadline has come
//   write(out.bytes); out.clear();
#pragma once

#include <adroit_core/bounded_file.h>
#include <adroit_teleop/glove_protocol.h>

#include <array>
#include <cstdint>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit::teleop {

// Sensor bytes (1..255) of the simulated hand at time t (seconds since the emulator started).
class GloveTrajectory {
 public:
  virtual ~GloveTrajectory() = default;
  virtual int sensors() const = 0;
  virtual void sample(double t, std::uint8_t* out) const = 0;  // writes sensors() bytes
};

// Smooth periodic motion of every sensor: 128 + 100 sin(2 pi t / period + phase_i), phases
// spread evenly over the sensors, so all values stay in 28..228 and no two sensors coincide.
class SyntheticTrajectory : public GloveTrajectory {
 public:
  // sensors 18 or 22, period > 0 (std::invalid_argument otherwise).
  SyntheticTrajectory(int sensors, double period);
  int sensors() const override { return sensors_; }
  void sample(double t, std::uint8_t* out) const override;

 private:
  int sensors_;
  double period_;
};

// A trajectory that holds its first sample until started: the scripted expert's glove
// (adroit_teleop pickup_expert) stays in the start pose while the scene is set up and the
// dead-man pressed, and plays its motion from the moment start() is called, so the motion
// begins where the demonstration's recording begins.
class DeferredTrajectory : public GloveTrajectory {
 public:
  explicit DeferredTrajectory(std::shared_ptr<const GloveTrajectory> motion);  // throws std::invalid_argument for none
  int sensors() const override { return motion_->sensors(); }
  // motion(0) before start(); motion(t - start time) from then on.
  void sample(double t, std::uint8_t* out) const override;
  void start(double t) { start_ = t; }
  bool started() const { return start_ < kNotStarted; }

 private:
  static constexpr double kNotStarted = 1e300;
  std::shared_ptr<const GloveTrajectory> motion_;
  double start_ = kNotStarted;
};

// Thrown by CsvTrajectory::load: "<file>:<line>: <what is wrong>" (or "<file>: ..." for the
// whole file).
class TrajectoryError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The largest trajectory file read: a glove recorded at 150 Hz with 22 values of up to 3
// digits is about 15 kB a second, so 64 MiB holds over an hour; a wrong path (a bag, a
// device) is refused before a byte is read.
constexpr std::size_t kMaxTrajectoryFileBytes = 64 * kMiB;

// A recorded trajectory played back in time and looped. File: one row per sample,
// "t, s1, ..., sN" (comma separated, t in seconds strictly increasing, values 1..255, rounded
// to the nearest integer); an optional header row first; blank lines and '#' lines ignored.
// Playback holds each row until the next row's time (a recorded glove is sampled, not
// interpolated). The loop lasts from the first row's time to the last row's plus the last
// interval, so the last row is held as long as the one before it.
class CsvTrajectory : public GloveTrajectory {
 public:
  // Reads a regular file of at most kMaxTrajectoryFileBytes (a FIFO, a device or a directory is
  // refused without blocking). Throws TrajectoryError naming the file (and line).
  static CsvTrajectory load(const std::string& path, int sensors);
  int sensors() const override { return sensors_; }
  void sample(double t, std::uint8_t* out) const override;
  std::size_t rows() const { return times_.size(); }
  double loopDuration() const { return loop_; }

 private:
  int sensors_ = 0;
  std::vector<double> times_;                 // relative to the first row
  std::vector<std::uint8_t> values_;          // rows() x sensors_, row-major
  double loop_ = 0;
};

struct EmulatorOptions {
  int sensors = kSensors22;   // 18 or 22
  double rate_hz = 120;       // streaming rate, 1..1000
  int garbage_every = 0;      // > 0: 1..8 random non-zero garbage bytes after every K-th record
  bool glove_error = false;   // answer every request with 'e' 'g' 0 (glove unplugged from its unit)
  std::uint32_t seed = 1;     // garbage bytes
};

// A record the emulator sent (for the emulator's --log).
struct SentRecord {
  std::uint64_t sequence = 0;  // 0, 1, 2... over polled and streamed records
  bool streamed = false;
  double t = 0;                // the trajectory time the values were sampled at
  int count = 0;
  std::array<std::uint8_t, kMaxSensors> values{};
};

// Bytes to send, in order, and the records among them.
struct EmulatorOutput {
  std::vector<std::uint8_t> bytes;
  std::vector<SentRecord> records;
  void clear() {
    bytes.clear();
    records.clear();
  }
};

struct EmulatorStats {
  std::uint64_t polled_records = 0, streamed_records = 0;
  std::uint64_t error_replies = 0;     // 'e' frames sent
  std::uint64_t unknown_commands = 0;
  std::uint64_t garbage_bytes = 0;     // injected by garbage_every
  std::uint64_t missed_deadlines = 0;  // stream deadlines skipped because tick() came too late
};

class GloveEmulator {
 public:
  // Throws std::invalid_argument for options out of range, a missing trajectory, or a
  // trajectory whose sensor count differs from options.sensors.
  GloveEmulator(const EmulatorOptions& options, std::shared_ptr<const GloveTrajectory> trajectory);

  // Bytes from the host at time t (seconds, monotonic). Appends the answers to out:
  //   'G'  -> a polled record sampled at t ('e' 'g' 0 with glove_error)
  //   'S'  -> starts streaming: the first record is due at t, then every 1/rate
  //   0x03 -> stops streaming (no answer)
  //   "?S" -> '?' 'S' sensors 0 ('e' 'g' 0 with glove_error)
  //   else -> 'e' '?' 0
  void receive(const std::uint8_t* bytes, std::size_t n, double t, EmulatorOutput& out);

  // Appends the streamed record due at or before t, if any. Deadlines are t_start + k / rate
  // (absolute, so pacing errors never accumulate). A glove samples when it sends, so when t
  // is already past several deadlines one record goes out and the skipped deadlines are
  // counted in missed_deadlines, instead of a burst of stale records.
  void tick(double t, EmulatorOutput& out);

  bool streaming() const { return streaming_; }
  // Time of the next streamed record; +infinity when not streaming.
  double nextDeadline() const;
  // A glove that comes back after being unplugged: not streaming, no half-received command.
  void reset();

  const EmulatorOptions& options() const { return options_; }
  const EmulatorStats& stats() const { return stats_; }

 private:
  void sendRecord(bool streamed, double t, EmulatorOutput& out);
  void sendError(GloveError code, EmulatorOutput& out);

  EmulatorOptions options_;
  std::shared_ptr<const GloveTrajectory> trajectory_;
  CommandParser commands_;
  std::vector<GloveCommand> pending_;  // reused by receive()
  bool streaming_ = false;
  double stream_start_ = 0;
  std::uint64_t stream_index_ = 0;     // index k of the next deadline
  std::uint64_t sequence_ = 0;
  std::mt19937 rng_;
  EmulatorStats stats_;
};

}  // namespace adroit::teleop
