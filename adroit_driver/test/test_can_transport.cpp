// CanTransport over socketpair(AF_UNIX, SOCK_SEQPACKET) (the same frame semantics as a
// PF_CAN socket: one frame per datagram), the seqpacket listener/connector through a path,
// and the PF_CAN opening error on machines without SocketCAN.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>

#include "adroit_driver/can_protocol.h"
#include "adroit_driver/can_transport.h"

namespace adroit::driver::can {
namespace {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

CanFrame numbered(std::uint32_t id, std::uint8_t n) {
  const std::uint8_t bytes[4] = {n, static_cast<std::uint8_t>(n + 1), 0xAB, 0xCD};
  return makeFrame(id, bytes, 4);
}

class Pair : public ::testing::Test {
 protected:
  void SetUp() override {
    int fds[2];
    ASSERT_EQ(socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds), 0);
    raw_a_ = fds[0];
    a_.emplace(fds[0], "a");
    b_.emplace(fds[1], "b");
  }
  // A datagram of any size, bypassing CanTransport (a misbehaving peer).
  void sendRaw(const void* bytes, std::size_t size) {
    ASSERT_EQ(::send(raw_a_, bytes, size, 0), static_cast<ssize_t>(size));
  }
  int raw_a_ = -1;
  std::optional<CanTransport> a_, b_;
  CanFrame in_[32];
};

TEST_F(Pair, FramesGoBothWays) {
  for (std::uint8_t n = 0; n < 5; ++n) ASSERT_EQ(a_->write(numbered(0x100 + n, n)), IoStatus::kOk);
  ReadResult r = b_->read(in_, 32, milliseconds(100));
  ASSERT_EQ(r.status, IoStatus::kOk);
  ASSERT_EQ(r.count, 5u);
  for (std::uint8_t n = 0; n < 5; ++n) EXPECT_TRUE(sameFrame(in_[n], numbered(0x100 + n, n))) << toString(in_[n]);
  ASSERT_EQ(b_->write(numbered(0x7FF, 9)), IoStatus::kOk);
  r = a_->read(in_, 32, milliseconds(100));
  ASSERT_EQ(r.count, 1u);
  EXPECT_TRUE(sameFrame(in_[0], numbered(0x7FF, 9)));
  EXPECT_EQ(a_->counters().frames_written, 5u);
  EXPECT_EQ(b_->counters().frames_read, 5u);
}

TEST_F(Pair, ProtocolFramesSurviveTheTrip) {
  CanFrame f;
  ASSERT_TRUE(encode(ValveCommandFrame{1, 3, 3, {-5, 0.5, 5}, 77}, &f).ok());
  ASSERT_EQ(a_->write(f), IoStatus::kOk);
  ASSERT_EQ(b_->read(in_, 1, milliseconds(100)).count, 1u);
  ValveCommandFrame v;
  ASSERT_EQ(decode(in_[0], &v), DecodeError::kNone);
  EXPECT_EQ(v.seq, 77);
  EXPECT_EQ(v.volts[0], -5.0);
}

TEST_F(Pair, ReadTimesOutAndReadsAtMostMax) {
  const auto start = Clock::now();
  ReadResult r = b_->read(in_, 32, milliseconds(30));
  EXPECT_EQ(r.status, IoStatus::kTimeout);
  EXPECT_EQ(r.count, 0u);
  EXPECT_GE(Clock::now() - start, milliseconds(25));
  EXPECT_EQ(b_->read(in_, 32, milliseconds(0)).status, IoStatus::kTimeout);  // zero: a look only
  for (std::uint8_t n = 0; n < 10; ++n) ASSERT_EQ(a_->write(numbered(0x10, n)), IoStatus::kOk);
  EXPECT_EQ(b_->read(in_, 4, milliseconds(0)).count, 4u);
  EXPECT_EQ(in_[0].data[0], 0);
  EXPECT_EQ(b_->read(in_, 4, milliseconds(0)).count, 4u);
  EXPECT_EQ(in_[0].data[0], 4);
  EXPECT_EQ(b_->read(in_, 4, milliseconds(0)).count, 2u);
}

TEST_F(Pair, ReadWaitsForAFrameThatArrivesLater) {
  std::thread writer([this] {
    std::this_thread::sleep_for(milliseconds(20));
    CanFrame f = numbered(0x55, 1);
    ::send(raw_a_, &f, sizeof f, 0);
  });
  const ReadResult r = b_->read(in_, 32, milliseconds(-1));  // forever
  writer.join();
  EXPECT_EQ(r.status, IoStatus::kOk);
  EXPECT_EQ(r.count, 1u);
}

TEST_F(Pair, WrongSizeDatagramsAreDroppedAndCounted) {
  const CanFrame good = numbered(0x123, 1);
  unsigned char big[100] = {};
  std::memcpy(big, &good, sizeof good);
  sendRaw(&good, sizeof good);
  sendRaw(big, 15);   // one byte short
  sendRaw(big, 17);   // one byte long
  sendRaw(big, 100);  // longer than the read buffer: its real size is still known
  sendRaw(big, 0);    // empty
  sendRaw(&good, sizeof good);
  const ReadResult r = b_->read(in_, 32, milliseconds(100));
  EXPECT_EQ(r.status, IoStatus::kOk);
  ASSERT_EQ(r.count, 2u);
  EXPECT_TRUE(sameFrame(in_[0], good));
  EXPECT_TRUE(sameFrame(in_[1], good));
  EXPECT_EQ(b_->counters().wrong_size, 4u);
  EXPECT_EQ(b_->counters().frames_read, 2u);
  EXPECT_FALSE(b_->hungUp());
}

TEST_F(Pair, FramesWithAnImpossibleLengthAreDropped) {
  CanFrame bad = numbered(0x123, 1);
  bad.dlc = 9;
  sendRaw(&bad, sizeof bad);
  EXPECT_EQ(b_->read(in_, 32, milliseconds(100)).count, 0u);
  EXPECT_EQ(b_->counters().bad_dlc, 1u);
  EXPECT_EQ(a_->write(bad), IoStatus::kError);  // and never sent
  EXPECT_EQ(a_->counters().write_errors, 1u);
  EXPECT_EQ(a_->lastError(), EINVAL);
}

TEST_F(Pair, AFullBufferIsReportedWithoutBlocking) {
  const int small = 4096;  // the kernel doubles it and keeps a minimum; a few frames fit
  ASSERT_EQ(setsockopt(raw_a_, SOL_SOCKET, SO_SNDBUF, &small, sizeof small), 0);
  const auto start = Clock::now();
  int sent = 0;
  IoStatus status = IoStatus::kOk;
  for (int k = 0; k < 100000 && status == IoStatus::kOk; ++k) {
    status = a_->write(numbered(0x10, static_cast<std::uint8_t>(k)));
    if (status == IoStatus::kOk) ++sent;
  }
  EXPECT_EQ(status, IoStatus::kFull);
  EXPECT_LT(Clock::now() - start, milliseconds(500));  // never waited for the reader
  EXPECT_GT(sent, 0);
  EXPECT_EQ(a_->write(numbered(0x10, 0)), IoStatus::kFull);
  EXPECT_EQ(a_->counters().write_full, 2u);
  EXPECT_EQ(a_->counters().frames_written, static_cast<std::uint64_t>(sent));
  // Once the reader drains, writing works again, and nothing was reordered or torn.
  std::size_t got = 0;
  while (got < static_cast<std::size_t>(sent)) {
    const ReadResult r = b_->read(in_, 32, milliseconds(100));
    ASSERT_GT(r.count, 0u);
    for (std::size_t k = 0; k < r.count; ++k) ASSERT_EQ(in_[k].data[0], static_cast<std::uint8_t>(got + k));
    got += r.count;
  }
  EXPECT_EQ(a_->write(numbered(0x10, 1)), IoStatus::kOk);
}

TEST_F(Pair, HangUpAfterTheFramesSentBeforeIt) {
  for (std::uint8_t n = 0; n < 3; ++n) ASSERT_EQ(a_->write(numbered(0x20, n)), IoStatus::kOk);
  a_.reset();  // the peer closes
  ReadResult r = b_->read(in_, 32, milliseconds(100));
  EXPECT_EQ(r.count, 3u);  // delivered, then the hang-up
  EXPECT_EQ(r.status, IoStatus::kHangUp);
  EXPECT_TRUE(b_->hungUp());
  r = b_->read(in_, 32, milliseconds(100));
  EXPECT_EQ(r.status, IoStatus::kHangUp);
  EXPECT_EQ(r.count, 0u);
  EXPECT_EQ(b_->write(numbered(0x20, 0)), IoStatus::kHangUp);  // EPIPE, and no SIGPIPE
}

TEST_F(Pair, HangUpWhileWaiting) {
  std::thread closer([this] {
    std::this_thread::sleep_for(milliseconds(20));
    a_.reset();
  });
  const auto start = Clock::now();
  const ReadResult r = b_->read(in_, 32, std::chrono::seconds(5));
  closer.join();
  EXPECT_EQ(r.status, IoStatus::kHangUp);
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(2));
}

TEST_F(Pair, ErrorFramesAreClassifiedCountedAndNotReturned) {
  auto errorFrame = [](std::uint32_t classes, std::uint8_t controller = 0) {
    CanFrame f;
    f.id = kErrFlag | classes;
    f.dlc = 8;
    f.data[1] = controller;
    return f;
  };
  const CanFrame frames[] = {
      errorFrame(kErrController, kCtrlTxWarning),
      errorFrame(kErrController, kCtrlRxPassive),
      errorFrame(kErrBusOff),
      errorFrame(kErrRestarted),
      errorFrame(kErrController, kCtrlRxOverflow),
      errorFrame(kErrNoAck | kErrProtocol),
      numbered(0x100, 1),
  };
  BusState states[6];
  for (int k = 0; k < 6; ++k) {
    sendRaw(&frames[k], sizeof(CanFrame));
    ASSERT_EQ(b_->read(in_, 32, milliseconds(100)).count, 0u);
    states[k] = b_->busState();
  }
  EXPECT_EQ(states[0], BusState::kErrorWarning);
  EXPECT_EQ(states[1], BusState::kErrorPassive);
  EXPECT_EQ(states[2], BusState::kBusOff);
  EXPECT_EQ(states[3], BusState::kErrorActive);
  EXPECT_EQ(states[4], BusState::kErrorActive);
  sendRaw(&frames[6], sizeof(CanFrame));
  EXPECT_EQ(b_->read(in_, 32, milliseconds(100)).count, 1u);
  const TransportCounters& c = b_->counters();
  EXPECT_EQ(c.error_frames, 6u);
  EXPECT_EQ(c.error_warning, 1u);
  EXPECT_EQ(c.error_passive, 1u);
  EXPECT_EQ(c.bus_off, 1u);
  EXPECT_EQ(c.restarts, 1u);
  EXPECT_EQ(c.controller_problems, 3u);
  EXPECT_EQ(c.overflows, 1u);
  EXPECT_EQ(c.no_ack, 1u);
  EXPECT_EQ(c.protocol_errors, 1u);
  EXPECT_EQ(c.frames_read, 1u);
}

TEST(CanErrorFrames, ClassifiesTheLinuxBits) {
  CanFrame f;
  f.id = kErrFlag | kErrController | kErrCounters;
  f.dlc = 8;
  f.data[1] = kCtrlTxPassive | kCtrlTxOverflow;
  f.data[6] = 130;
  f.data[7] = 5;
  ErrorFrameInfo info = classifyErrorFrame(f);
  EXPECT_TRUE(info.error_passive);
  EXPECT_TRUE(info.tx_overflow);
  EXPECT_FALSE(info.rx_overflow);
  EXPECT_FALSE(info.bus_off);
  EXPECT_TRUE(info.has_counters);
  EXPECT_EQ(info.tx_errors, 130);
  EXPECT_EQ(info.rx_errors, 5);
  f.id = kErrFlag | kErrBusOff;
  f.data[1] = 0;
  info = classifyErrorFrame(f);
  EXPECT_TRUE(info.bus_off);
  EXPECT_FALSE(info.has_counters);
  f.id = kErrFlag | kErrController;
  f.data[1] = kCtrlActive;
  EXPECT_TRUE(classifyErrorFrame(f).back_to_active);
  EXPECT_STREQ(busStateName(BusState::kBusOff), "bus-off");
}

TEST(CanDatagrams, ParseBySizeAndKind) {
  CanFrame f = numbered(0x100, 1), out;
  EXPECT_EQ(parseDatagram(&f, sizeof f, &out), DatagramKind::kDataFrame);
  EXPECT_TRUE(sameFrame(f, out));
  EXPECT_EQ(parseDatagram(&f, 15, &out), DatagramKind::kWrongSize);
  EXPECT_EQ(parseDatagram(&f, 0, &out), DatagramKind::kWrongSize);
  f.dlc = 200;
  EXPECT_EQ(parseDatagram(&f, sizeof f, &out), DatagramKind::kBadDlc);
  f.id = kErrFlag | kErrBusOff;
  f.dlc = 8;
  EXPECT_EQ(parseDatagram(&f, sizeof f, &out), DatagramKind::kErrorFrame);
}

TEST_F(Pair, MovedTransportKeepsWorking) {
  CanTransport moved = std::move(*b_);
  EXPECT_EQ(b_->fd(), -1);
  ASSERT_EQ(a_->write(numbered(0x1, 1)), IoStatus::kOk);
  EXPECT_EQ(moved.read(in_, 32, milliseconds(100)).count, 1u);
}

// ---------------------------------------------------------------- PF_CAN

bool kernelHasPfCan() {
  const int fd = ::socket(PF_CAN, SOCK_RAW, 1 /* CAN_RAW */);
  if (fd < 0) return false;
  ::close(fd);
  return true;
}

TEST(SocketCan, OpeningGivesOneClearErrorNamingTheInterface) {
  std::string error;
  EXPECT_FALSE(openSocketCan("adroit_nocan0", &error).has_value());
  EXPECT_NE(error.find("'adroit_nocan0'"), std::string::npos) << error;
  if (kernelHasPfCan()) {
    EXPECT_NE(error.find("no such network interface"), std::string::npos) << error;
  } else {  // this development machine (DESIGN.md §5)
    EXPECT_NE(error.find("does not support SocketCAN"), std::string::npos) << error;
    EXPECT_NE(error.find("unix:"), std::string::npos) << error;  // points to the emulator
    error.clear();
    EXPECT_FALSE(openSocketCan("can0", &error).has_value());
    EXPECT_NE(error.find("'can0'"), std::string::npos) << error;
  }
  EXPECT_EQ(error.find('\n'), std::string::npos);  // one line
  std::cout << "      (message here: " << error << ")\n";
}

TEST(SocketCan, RefusesNamesThatCannotBeInterfaces) {
  std::string error;
  EXPECT_FALSE(openSocketCan("", &error).has_value());
  EXPECT_NE(error.find("not an interface name"), std::string::npos) << error;
  EXPECT_FALSE(openSocketCan("a_name_much_too_long_for_linux", &error).has_value());
  EXPECT_NE(error.find("a_name_much_too_long_for_linux"), std::string::npos) << error;
  EXPECT_FALSE(openBus("adroit_nocan1", &error).has_value());
  EXPECT_NE(error.find("'adroit_nocan1'"), std::string::npos) << error;
}

// ---------------------------------------------------------------- seqpacket through a path

class Seqpacket : public ::testing::Test {
 protected:
  void SetUp() override {
    char dir[] = "/tmp/adroit_can_test_XXXXXX";
    ASSERT_NE(mkdtemp(dir), nullptr);
    dir_ = dir;
    path_ = dir_ + "/act0.sock";
  }
  void TearDown() override {
    ::unlink(path_.c_str());
    ::unlink((dir_ + "/file").c_str());
    ::rmdir(dir_.c_str());
  }
  std::string dir_, path_;
  CanFrame in_[8];
};

TEST_F(Seqpacket, EmulatorListensDriverConnects) {
  std::string error;
  auto listener = listenSeqpacket(path_, &error);
  ASSERT_TRUE(listener) << error;
  auto driver = openSeqpacket(path_, &error);
  ASSERT_TRUE(driver) << error;
  auto emulator = listener->accept(milliseconds(1000), &error);
  ASSERT_TRUE(emulator) << error;
  CanFrame joints;
  ASSERT_TRUE(encode(JointAnglesFrame{0, {0.1, 0.2, 0.3, 0.4}, 1}, &joints).ok());
  ASSERT_EQ(emulator->write(joints), IoStatus::kOk);
  ASSERT_EQ(driver->read(in_, 8, milliseconds(100)).count, 1u);
  EXPECT_TRUE(sameFrame(in_[0], joints));
  CanFrame valve;
  ASSERT_TRUE(encode(ValveCommandFrame{0, 0, 3, {1, 2, 3}, 1}, &valve).ok());
  ASSERT_EQ(driver->write(valve), IoStatus::kOk);
  ASSERT_EQ(emulator->read(in_, 8, milliseconds(100)).count, 1u);
  EXPECT_TRUE(sameFrame(in_[0], valve));
  // The emulator goes away: the driver sees the hang-up.
  emulator.reset();
  EXPECT_EQ(driver->read(in_, 8, milliseconds(100)).status, IoStatus::kHangUp);
}

TEST_F(Seqpacket, OpenBusTakesUnixPaths) {
  std::string error;
  auto listener = listenSeqpacket(path_, &error);
  ASSERT_TRUE(listener) << error;
  auto driver = openBus("unix:" + path_, &error);
  ASSERT_TRUE(driver) << error;
  EXPECT_EQ(driver->name(), path_);
}

TEST_F(Seqpacket, AcceptTimesOutWithoutAnError) {
  std::string error = "stale";
  auto listener = listenSeqpacket(path_, &error);
  ASSERT_TRUE(listener);
  EXPECT_FALSE(listener->accept(milliseconds(20), &error).has_value());
  EXPECT_TRUE(error.empty());
}

TEST_F(Seqpacket, ConnectingWithoutAnEmulatorSaysSo) {
  std::string error;
  EXPECT_FALSE(openSeqpacket(path_, &error).has_value());
  EXPECT_NE(error.find(path_), std::string::npos) << error;
  EXPECT_NE(error.find("emulator"), std::string::npos) << error;
  EXPECT_FALSE(openSeqpacket(std::string(200, 'x'), &error).has_value());
  EXPECT_NE(error.find("characters"), std::string::npos) << error;
}

TEST_F(Seqpacket, ListeningTwiceIsRefusedAndAStaleSocketReplaced) {
  std::string error;
  {
    auto first = listenSeqpacket(path_, &error);
    ASSERT_TRUE(first) << error;
    EXPECT_FALSE(listenSeqpacket(path_, &error).has_value());
    EXPECT_NE(error.find("another process is listening"), std::string::npos) << error;
  }
  struct stat info;
  EXPECT_NE(::lstat(path_.c_str(), &info), 0);  // removed with its listener
  // A stale socket file (its process died without removing it) is replaced.
  const int dead = ::socket(AF_UNIX, SOCK_SEQPACKET, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::strncpy(address.sun_path, path_.c_str(), sizeof address.sun_path - 1);
  ASSERT_EQ(::bind(dead, reinterpret_cast<const sockaddr*>(&address), sizeof address), 0);
  ::close(dead);
  ASSERT_EQ(::lstat(path_.c_str(), &info), 0);
  auto fresh = listenSeqpacket(path_, &error);
  ASSERT_TRUE(fresh) << error;
  EXPECT_TRUE(openSeqpacket(path_, &error).has_value()) << error;
}

TEST_F(Seqpacket, APathThatIsNotASocketIsLeftAlone) {
  const std::string file = dir_ + "/file";
  std::ofstream(file) << "keep me";
  std::string error;
  EXPECT_FALSE(listenSeqpacket(file, &error).has_value());
  EXPECT_NE(error.find("not a socket"), std::string::npos) << error;
  std::ifstream in(file);
  std::string content;
  std::getline(in, content);
  EXPECT_EQ(content, "keep me");
}

}  // namespace
}  // namespace adroit::driver::can
