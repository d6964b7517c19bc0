// The glove_emulator program, run as a process and talked to as the driver will: through
// SerialPort on the link path. Polling, the sensor-count query, streaming at the requested
// rate and stopping, the log, garbage injection, unplugging and coming back, the glove-error
// mode, a clean exit on SIGTERM, and refusal of bad options and trajectory files.
#include <adroit_teleop/glove_protocol.h>
#include <adroit_teleop/serial_port.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <thread>

#include "temp_dir.h"

using namespace adroit::teleop;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using Bytes = std::vector<std::uint8_t>;

namespace {

using adroit::teleop::test::TempDir;

bool exists(const std::string& path) {
  struct stat st {};
  return lstat(path.c_str(), &st) == 0;
}

bool waitFor(const std::function<bool()>& condition, std::chrono::milliseconds limit) {
  const auto end = Clock::now() + limit;
  while (Clock::now() < end) {
    if (condition()) return true;
    std::this_thread::sleep_for(10ms);
  }
  return condition();
}

std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// The emulator as a child process, its stdout and stderr in a file.
class Emulator {
 public:
  Emulator(const std::string& dir, const std::vector<std::string>& args) : output_(dir + "/output.txt") {
    std::vector<std::string> argv = {GLOVE_EMULATOR_BINARY};
    argv.insert(argv.end(), args.begin(), args.end());
    pid_ = fork();
    if (pid_ == 0) {
      const int fd = open(output_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(fd, 1);
      dup2(fd, 2);
      std::vector<char*> c;
      for (auto& a : argv) c.push_back(const_cast<char*>(a.c_str()));
      c.push_back(nullptr);
      execv(c[0], c.data());
      _exit(127);
    }
  }
  ~Emulator() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  // Sends `sig` (0: none) and waits for the exit; the exit status, or -1 if killed/hung.
  int finish(int sig, std::chrono::milliseconds limit = 5000ms) {
    if (sig) kill(pid_, sig);
    int status = 0;
    const auto end = Clock::now() + limit;
    while (Clock::now() < end) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(10ms);
    }
    return -1;
  }
  std::string output() const { return readText(output_); }

 private:
  std::string output_;
  pid_t pid_ = -1;
};

// Reads for `duration` (or until a hang-up), decoding into frames. False on a hang-up.
bool collect(SerialPort& port, GloveParser& parser, std::chrono::milliseconds duration, std::vector<GloveFrame>& frames) {
  const auto end = Clock::now() + duration;
  std::uint8_t buf[512];
  while (Clock::now() < end) {
    const auto r = port.readSome(buf, sizeof buf, 20ms);
    if (r.status == SerialPort::ReadStatus::kHangup) return false;
    parser.feed(buf, r.bytes, frames);
  }
  return true;
}

// Reads until a frame satisfying `want` arrives; that frame, or nullopt after `limit`.
std::optional<GloveFrame> awaitFrame(SerialPort& port, GloveParser& parser,
                                     const std::function<bool(const GloveFrame&)>& want,
                                     std::chrono::milliseconds limit = 2000ms) {
  const auto end = Clock::now() + limit;
  std::vector<GloveFrame> frames;
  std::uint8_t buf[512];
  while (Clock::now() < end) {
    const auto r = port.readSome(buf, sizeof buf, 20ms);
    if (r.status == SerialPort::ReadStatus::kHangup) return std::nullopt;
    frames.clear();
    parser.feed(buf, r.bytes, frames);
    for (const GloveFrame& f : frames)
      if (want(f)) return f;
  }
  return std::nullopt;
}

std::vector<std::vector<long long>> logLines(const std::string& path) {
  std::vector<std::vector<long long>> lines;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    std::vector<long long> v;
    long long x;
    while (s >> x) v.push_back(x);
    lines.push_back(v);
  }
  return lines;
}

}  // namespace

TEST(GloveEmulatorProgram, PollQueryStreamStopAndLog) {
  const TempDir tmp;
  const std::string dir = tmp.path(), link = dir + "/glove", log = dir + "/glove.log";
  Emulator emu(dir, {"--link", link, "--sensors", "18", "--rate", "200", "--log", log});
  ASSERT_TRUE(waitFor([&] { return exists(link); }, 5000ms)) << emu.output();
  SerialPort port;
  port.open(link, 115200);
  GloveParser parser(18);

  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kQuerySensorCount)));
  const auto count = awaitFrame(port, parser, [](const GloveFrame& f) { return f.type == FrameType::kSensorCount; });
  ASSERT_TRUE(count.has_value());
  EXPECT_EQ(count->count, 18);

  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kPoll)));
  const auto polled = awaitFrame(port, parser, [](const GloveFrame& f) { return f.isRecord(); });
  ASSERT_TRUE(polled.has_value());
  EXPECT_EQ(polled->type, FrameType::kPolledRecord);

  // Stream for one second. Deadlines are t0 + k / 200, so at most 200 s + 1 records can have
  // been sent in s seconds; on a busy machine a late emulator skips deadlines, so allow 20 %
  // fewer.
  const auto t0 = Clock::now();
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kStartStream)));
  std::vector<GloveFrame> frames;
  ASSERT_TRUE(collect(port, parser, 1000ms, frames));
  const double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kStopStream)));
  ASSERT_TRUE(collect(port, parser, 200ms, frames));  // what was already on its way
  const std::size_t streamed = frames.size();
  for (const GloveFrame& f : frames) EXPECT_EQ(f.type, FrameType::kStreamedRecord);
  EXPECT_LE(streamed, static_cast<std::size_t>(200 * (elapsed + 0.2)) + 1);
  EXPECT_GE(streamed, static_cast<std::size_t>(0.8 * 200 * 1.0));
  std::vector<GloveFrame> after_stop;
  ASSERT_TRUE(collect(port, parser, 300ms, after_stop));
  EXPECT_TRUE(after_stop.empty()) << after_stop.size() << " records after the stop";
  EXPECT_EQ(parser.stats().garbage_bytes, 0u);

  EXPECT_EQ(emu.finish(SIGTERM), 0) << emu.output();
  EXPECT_FALSE(exists(link)) << "link left behind";
  EXPECT_NE(emu.output().find("sent 1 polled and " + std::to_string(streamed) + " streamed records"),
            std::string::npos)
      << emu.output();

  // The log: one line per record sent, in order, with the values that went out.
  const auto lines = logLines(log);
  ASSERT_EQ(lines.size(), 1 + streamed);
  for (std::size_t k = 0; k < lines.size(); ++k) {
    ASSERT_EQ(lines[k].size(), 2u + 18u) << "line " << k;
    EXPECT_EQ(lines[k][0], static_cast<long long>(k));
    if (k > 0) {
      EXPECT_GE(lines[k][1], lines[k - 1][1]);
    }
    const GloveFrame& f = k == 0 ? *polled : frames[k - 1];
    for (int i = 0; i < 18; ++i) ASSERT_EQ(lines[k][2 + i], f.raw[i]) << "line " << k << " sensor " << i;
  }
}

TEST(GloveEmulatorProgram, GarbageCostsNoRecord) {
  const TempDir tmp;
  const std::string dir = tmp.path(), link = dir + "/glove", log = dir + "/glove.log";
  Emulator emu(dir, {"--link", link, "--rate", "500", "--garbage-every", "5", "--seed", "3", "--log", log});
  ASSERT_TRUE(waitFor([&] { return exists(link); }, 5000ms)) << emu.output();
  SerialPort port;
  port.open(link, 115200);
  GloveParser parser(22);
  std::vector<GloveFrame> frames;
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kStartStream)));
  ASSERT_TRUE(collect(port, parser, 500ms, frames));
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kStopStream)));
  ASSERT_TRUE(collect(port, parser, 300ms, frames));
  EXPECT_EQ(emu.finish(SIGTERM), 0) << emu.output();
  EXPECT_GT(parser.stats().garbage_bytes, 0u);
  const auto lines = logLines(log);
  ASSERT_GT(frames.size(), 100u);
  ASSERT_EQ(frames.size(), lines.size());
  for (std::size_t k = 0; k < frames.size(); ++k)
    for (int i = 0; i < 22; ++i) ASSERT_EQ(lines[k][2 + i], frames[k].raw[i]) << "record " << k;
}

TEST(GloveEmulatorProgram, UnplugHangsUpAndTheGloveComesBack) {
  const TempDir tmp;
  const std::string dir = tmp.path(), link = dir + "/glove";
  Emulator emu(dir, {"--link", link, "--rate", "100", "--unplug-after", "0.8", "--unplug-for", "0.8"});
  ASSERT_TRUE(waitFor([&] { return exists(link); }, 5000ms)) << emu.output();
  const auto started = Clock::now();
  SerialPort port;
  port.open(link, 115200);
  GloveParser parser(22);
  std::vector<GloveFrame> frames;
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kStartStream)));
  EXPECT_FALSE(collect(port, parser, 5000ms, frames)) << "no hang-up";
  const double at = std::chrono::duration<double>(Clock::now() - started).count();
  EXPECT_GT(frames.size(), 10u);
  EXPECT_LT(at, 2.0);
  port.close();

  // The glove returns on a new pty behind the same link, not streaming.
  ASSERT_TRUE(waitFor([&] { return exists(link); }, 5000ms)) << emu.output();
  port.open(link, 115200);
  GloveParser again(22);
  std::vector<GloveFrame> quiet;
  ASSERT_TRUE(collect(port, again, 200ms, quiet));
  EXPECT_TRUE(quiet.empty());
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kPoll)));
  EXPECT_TRUE(awaitFrame(port, again, [](const GloveFrame& f) { return f.isRecord(); }).has_value());
  EXPECT_EQ(emu.finish(SIGINT), 0) << emu.output();
  EXPECT_NE(emu.output().find("plugged in again"), std::string::npos) << emu.output();
}

TEST(GloveEmulatorProgram, GloveErrorMode) {
  const TempDir tmp;
  const std::string dir = tmp.path(), link = dir + "/glove";
  Emulator emu(dir, {"--link", link, "--glove-error"});
  ASSERT_TRUE(waitFor([&] { return exists(link); }, 5000ms)) << emu.output();
  SerialPort port;
  port.open(link, 115200);
  GloveParser parser(22);
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kPoll)));
  const auto f = awaitFrame(port, parser, [](const GloveFrame&) { return true; });
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->type, FrameType::kError);
  EXPECT_EQ(f->error, GloveError::kGloveUnplugged);
  EXPECT_EQ(emu.finish(SIGTERM), 0);
}

TEST(GloveEmulatorProgram, DurationEndsTheProgram) {
  const TempDir tmp;
  const std::string dir = tmp.path(), link = dir + "/glove";
  Emulator emu(dir, {"--link", link, "--duration", "0.3"});
  EXPECT_EQ(emu.finish(0, 5000ms), 0) << emu.output();
  EXPECT_FALSE(exists(link));
}

TEST(GloveEmulatorProgram, BadOptionsAndFilesExitWithStatus2) {
  const TempDir tmp;
  const std::string dir = tmp.path();
  {
    Emulator emu(dir, {"--rate", "5000"});
    EXPECT_EQ(emu.finish(0), 2);
    EXPECT_NE(emu.output().find("--rate must be in 1..1000 Hz"), std::string::npos) << emu.output();
    EXPECT_NE(emu.output().find("usage: glove_emulator"), std::string::npos) << emu.output();
  }
  {
    Emulator emu(dir, {"--sensors", "20"});
    EXPECT_EQ(emu.finish(0), 2);
  }
  {
    Emulator emu(dir, {"--realtime-priority", "120"});
    EXPECT_EQ(emu.finish(0), 2);
    EXPECT_NE(emu.output().find("--realtime-priority must be in 0..99"), std::string::npos) << emu.output();
  }
  {
    Emulator emu(dir, {"--unplug-after", "1"});
    EXPECT_EQ(emu.finish(0), 2);
  }
  {
    Emulator emu(dir, {"--frobnicate"});
    EXPECT_EQ(emu.finish(0), 2);
    EXPECT_NE(emu.output().find("unknown option '--frobnicate'"), std::string::npos) << emu.output();
  }
  {
    const std::string csv = dir + "/bad.csv";
    std::ofstream(csv) << "t,s\n0,1,2\n";
    Emulator emu(dir, {"--link", dir + "/glove", "--trajectory", csv});
    EXPECT_EQ(emu.finish(0), 2);
    EXPECT_NE(emu.output().find(csv + ":2: expected 23 columns"), std::string::npos) << emu.output();
    EXPECT_FALSE(exists(dir + "/glove"));
  }
}
