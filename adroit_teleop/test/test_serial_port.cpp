// The serial port over a pseudo-terminal (opened by path, as the driver opens a glove) and
// over a socketpair: frames written on one end arrive on the other, a closed far end is
// reported as a hang-up, and every error names the port and the system's reason.
#include <adroit_teleop/glove_protocol.h>
#include <adroit_teleop/pseudo_terminal.h>
#include <adroit_teleop/serial_port.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <thread>

#include "temp_dir.h"

using namespace adroit::teleop;
using namespace std::chrono_literals;
using Bytes = std::vector<std::uint8_t>;

namespace {

using adroit::teleop::test::TempDir;

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const SerialPortError& e) {
    return e.what();
  }
  return "";
}

// Reads until `n` bytes arrived or `limit` passed.
Bytes readBytes(SerialPort& port, std::size_t n, std::chrono::milliseconds limit) {
  Bytes got;
  const auto end = std::chrono::steady_clock::now() + limit;
  std::uint8_t buf[256];
  while (got.size() < n && std::chrono::steady_clock::now() < end) {
    const auto r = port.readSome(buf, sizeof buf, 20ms);
    if (r.status == SerialPort::ReadStatus::kHangup) break;
    got.insert(got.end(), buf, buf + r.bytes);
  }
  return got;
}

Bytes readMaster(int fd, std::size_t n) {
  Bytes got;
  std::uint8_t buf[256];
  for (int i = 0; i < 200 && got.size() < n; ++i) {
    const ssize_t k = ::read(fd, buf, sizeof buf);
    if (k > 0) got.insert(got.end(), buf, buf + k);
    else std::this_thread::sleep_for(5ms);
  }
  return got;
}

Bytes record(bool streamed, int n, int first) {
  Bytes v(n);
  for (int i = 0; i < n; ++i) v[i] = static_cast<std::uint8_t>(first + i);
  return encodeRecord(streamed, v);
}

}  // namespace

TEST(SerialPort, MissingPathErrorNamesPortAndReason) {
  SerialPort port;
  const std::string e = errorOf([&] { port.open("/nonexistent/ttyGLOVE", 115200); });
  EXPECT_EQ(e, "glove port /nonexistent/ttyGLOVE: cannot open: No such file or directory");
  EXPECT_FALSE(port.isOpen());
}

TEST(SerialPort, NotATerminalIsRefused) {
  SerialPort port;
  const std::string e = errorOf([&] { port.open("/dev/null", 115200); });
  EXPECT_EQ(e.rfind("glove port /dev/null: not a serial port", 0), 0u) << e;
  EXPECT_FALSE(port.isOpen());
}

TEST(SerialPort, BaudRates) {
  for (int b : {9600, 19200, 38400, 57600, 115200}) EXPECT_TRUE(baudRateSupported(b)) << b;
  EXPECT_FALSE(baudRateSupported(12345));
  EXPECT_FALSE(baudRateSupported(0));
  PseudoTerminal pty;
  SerialPort port;
  const std::string e = errorOf([&] { port.open(pty.slaveName(), 12345); });
  EXPECT_NE(e.find("glove port " + pty.slaveName() + ": unsupported baud rate 12345 (supported: 9600"),
            std::string::npos)
      << e;
  EXPECT_FALSE(port.isOpen());
  EXPECT_NO_THROW(port.open(pty.slaveName(), 9600));
}

TEST(SerialPort, FramesThroughAPseudoTerminalLink) {
  const TempDir tmp;
  const std::string dir = tmp.path();
  PseudoTerminal pty(dir + "/glove");
  SerialPort port;
  port.open(dir + "/glove", 115200);
  ASSERT_TRUE(port.isOpen());
  EXPECT_EQ(port.name(), "glove port " + dir + "/glove");

  // Glove -> host: records written on the master arrive whole and decode.
  Bytes frames;
  for (int r = 0; r < 20; ++r) {
    const Bytes rec = record(true, 22, 10 + r);
    frames.insert(frames.end(), rec.begin(), rec.end());
  }
  ASSERT_EQ(::write(pty.master(), frames.data(), frames.size()), static_cast<ssize_t>(frames.size()));
  const Bytes got = readBytes(port, frames.size(), 2000ms);
  EXPECT_EQ(got, frames);  // raw mode: no byte translated (0x0d, 0x11, 0x13 among the values)
  GloveParser parser(22);
  const auto decoded = parser.feed(got.data(), got.size());
  ASSERT_EQ(decoded.size(), 20u);
  EXPECT_EQ(decoded[19].raw[0], 29);

  // Host -> glove: a command written on the port arrives on the master, not echoed back.
  ASSERT_TRUE(port.writeAll(encodeCommand(GloveCommand::kQuerySensorCount)));
  EXPECT_EQ(readMaster(pty.master(), 2), (Bytes{'?', 'S'}));
  std::uint8_t buf[16];
  EXPECT_EQ(port.readSome(buf, sizeof buf, 50ms).status, SerialPort::ReadStatus::kTimeout);
}

TEST(SerialPort, TimeoutReturnsNothingAfterTheTimeout) {
  PseudoTerminal pty;
  SerialPort port;
  port.open(pty.slaveName(), 115200);
  std::uint8_t buf[16];
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = port.readSome(buf, sizeof buf, 100ms);
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_EQ(r.status, SerialPort::ReadStatus::kTimeout);
  EXPECT_EQ(r.bytes, 0u);
  EXPECT_GE(waited, 95ms);
  EXPECT_LT(waited, 1000ms);
}

TEST(SerialPort, HangupWhenThePseudoTerminalGoes) {
  const TempDir tmp;
  const std::string dir = tmp.path();
  auto pty = std::make_unique<PseudoTerminal>(dir + "/glove");
  SerialPort port;
  port.open(dir + "/glove", 115200);
  pty.reset();  // the emulator unplugs the glove
  struct stat st {};
  EXPECT_NE(lstat((dir + "/glove").c_str(), &st), 0) << "link left behind";
  std::uint8_t buf[16];
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = port.readSome(buf, sizeof buf, 2000ms);
  EXPECT_EQ(r.status, SerialPort::ReadStatus::kHangup);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 1000ms) << "hang-up reported only at the timeout";
  EXPECT_FALSE(port.writeAll(Bytes{'G'}));
  // Reopening the path fails until the glove is back, with the path in the message.
  const std::string e = errorOf([&] { port.open(dir + "/glove", 115200); });
  EXPECT_EQ(e, "glove port " + dir + "/glove: cannot open: No such file or directory");
}

TEST(SerialPort, SocketpairDataThenHangup) {
  int sv[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  SerialPort host(sv[0], "glove port socketpair");
  SerialPort glove(sv[1], "glove socketpair");
  const Bytes rec = record(false, 18, 100);
  ASSERT_TRUE(glove.writeAll(rec));
  EXPECT_EQ(readBytes(host, rec.size(), 1000ms), rec);

  // Bytes sent just before the far end closes are still delivered, then the hang-up.
  ASSERT_TRUE(glove.writeAll(Bytes{'e', 'g', 0}));
  glove.close();
  std::uint8_t buf[16];
  auto r = host.readSome(buf, sizeof buf, 1000ms);
  ASSERT_EQ(r.status, SerialPort::ReadStatus::kData);
  EXPECT_EQ(Bytes(buf, buf + r.bytes), (Bytes{'e', 'g', 0}));
  r = host.readSome(buf, sizeof buf, 1000ms);
  EXPECT_EQ(r.status, SerialPort::ReadStatus::kHangup);
  // Writing to the closed peer reports the hang-up (and raises no SIGPIPE, or we'd be dead).
  EXPECT_FALSE(host.writeAll(Bytes{'G'}));
}

TEST(SerialPort, WriteTimesOutWhenNobodyReads) {
  int sv[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  SerialPort a(sv[0], "glove port stuck");
  SerialPort b(sv[1], "other end");
  const Bytes big(8 << 20, 'x');  // more than any socket buffer
  const std::string e = errorOf([&] { a.writeAll(big, 100ms); });
  EXPECT_EQ(e.rfind("glove port stuck: write timed out after ", 0), 0u) << e;
}

TEST(SerialPort, MoveTransfersTheDescriptor) {
  int sv[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
  SerialPort a(sv[0], "a");
  SerialPort peer(sv[1], "peer");
  SerialPort b(std::move(a));
  EXPECT_FALSE(a.isOpen());
  EXPECT_EQ(b.fd(), sv[0]);
  EXPECT_EQ(b.name(), "a");
  ASSERT_TRUE(peer.writeAll(Bytes{'G'}));
  EXPECT_EQ(readBytes(b, 1, 1000ms), Bytes{'G'});
  std::uint8_t buf[4];
  EXPECT_THROW(a.readSome(buf, sizeof buf, 1ms), SerialPortError);
}

TEST(PseudoTerminal, LinkHandling) {
  const TempDir tmp;
  const std::string dir = tmp.path();
  const std::string link = dir + "/glove";
  // A stale link from a crashed run is replaced.
  ASSERT_EQ(symlink("/dev/pts/does-not-exist", link.c_str()), 0);
  {
    PseudoTerminal pty(link);
    char target[256] = {};
    ASSERT_GT(readlink(link.c_str(), target, sizeof target - 1), 0);
    EXPECT_EQ(std::string(target), pty.slaveName());
    EXPECT_EQ(pty.link(), link);
  }
  struct stat st {};
  EXPECT_NE(lstat(link.c_str(), &st), 0) << "link not removed";

  // A link someone else re-pointed in the meantime is not ours to remove.
  {
    PseudoTerminal pty(link);
    ASSERT_EQ(unlink(link.c_str()), 0);
    ASSERT_EQ(symlink("/dev/null", link.c_str()), 0);
  }
  EXPECT_EQ(lstat(link.c_str(), &st), 0);
  unlink(link.c_str());

  // A regular file at the link path is never clobbered.
  std::ofstream(link) << "precious";
  try {
    PseudoTerminal pty(link);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(link + " exists and is not a symbolic link"), std::string::npos) << e.what();
  }
  std::ifstream in(link);
  std::string text;
  in >> text;
  EXPECT_EQ(text, "precious");
}
