// GloveDriver against the emulated glove on a real pseudo-terminal (the emulator's core on a
// thread here, so the test can unplug it): it asks the sensor count, streams or polls at the
// rate, survives garbage, notices a stale glove, and reconnects with back-off when the glove
// returns; a missing port is an error naming it, and the driver keeps retrying.
#include <adroit_teleop/glove_driver.h>
#include <adroit_teleop/glove_emulator.h>
#include <adroit_teleop/pseudo_terminal.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <thread>

using namespace adroit::teleop;
using namespace std::chrono_literals;

namespace {

std::string linkPath(const char* name) {
  return "/tmp/adroit_test_glove_driver_" + std::to_string(::getpid()) + "_" + name;
}

// The glove: GloveEmulator behind a pty at `link`, served on its own thread until stopped.
class EmulatedGlove {
 public:
  EmulatedGlove(const std::string& link, EmulatorOptions options)
      : pty_(std::make_unique<PseudoTerminal>(link)),
        glove_(options, std::make_shared<SyntheticTrajectory>(options.sensors, 2.0)),
        thread_([this] { serve(); }) {}
  ~EmulatedGlove() { unplug(); }
  void unplug() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
    pty_.reset();  // closes the master: the host sees a hang-up; removes the link
  }
  std::uint64_t sent() const { return sent_.load(); }

 private:
  void serve() {
    const auto start = std::chrono::steady_clock::now();
    std::uint8_t in[256];
    EmulatorOutput out;
    while (running_) {
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      pollfd p{pty_->master(), POLLIN, 0};
      if (::poll(&p, 1, 1) > 0 && (p.revents & POLLIN)) {
        const ssize_t n = ::read(pty_->master(), in, sizeof(in));
        if (n > 0) glove_.receive(in, static_cast<std::size_t>(n), t, out);
      }
      glove_.tick(t, out);
      if (!out.bytes.empty()) {
        const ssize_t w = ::write(pty_->master(), out.bytes.data(), out.bytes.size());
        (void)w;
        sent_ += out.records.size();
        out.clear();
      }
    }
  }
  std::unique_ptr<PseudoTerminal> pty_;
  GloveEmulator glove_;
  std::atomic<bool> running_{true};
  std::atomic<std::uint64_t> sent_{0};
  std::thread thread_;
};

// Runs the driver for `seconds`, returning the records it produced.
std::vector<GloveDriver::Record> run(GloveDriver& driver, double seconds) {
  std::vector<GloveDriver::Record> records;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) driver.spinOnce(5ms, records);
  return records;
}

TEST(GloveDriver, AsksTheSensorCountAndStreamsAtTheGlovesRate) {
  const std::string link = linkPath("stream");
  EmulatorOptions options;
  options.sensors = 18;
  options.rate_hz = 150;
  EmulatedGlove glove(link, options);
  GloveDriverConfig config;
  config.port = link;  // sensors 0: ask
  GloveDriver driver(config);
  const auto records = run(driver, 1.5);
  EXPECT_EQ(driver.state(), GloveDriver::State::kRunning);
  EXPECT_EQ(driver.sensors(), 18);
  EXPECT_FALSE(driver.stale());
  // About 150 Hz from the first record on (the query takes a few ms).
  EXPECT_GT(records.size(), 200u);
  EXPECT_LT(records.size(), 230u);
  for (std::size_t i = 1; i < records.size(); ++i) {
    EXPECT_EQ(records[i].frame.count, 18);
    EXPECT_EQ(records[i].frame.sequence, records[i - 1].frame.sequence + 1) << "a record was lost";
    EXPECT_GE(records[i].arrival, records[i - 1].arrival);
  }
  EXPECT_EQ(driver.parserStats().rejectedTotal(), 0u);
}

TEST(GloveDriver, PollsAtItsOwnRate) {
  const std::string link = linkPath("poll");
  EmulatedGlove glove(link, EmulatorOptions{});
  GloveDriverConfig config;
  config.port = link;
  config.sensors = 22;
  config.stream = false;
  config.poll_rate = 50;
  GloveDriver driver(config);
  const auto records = run(driver, 1.0);
  EXPECT_GE(records.size(), 45u);
  EXPECT_LE(records.size(), 52u);
  for (const auto& r : records) EXPECT_EQ(r.frame.type, FrameType::kPolledRecord);
}

TEST(GloveDriver, GarbageOnTheLineCostsNoRecord) {
  const std::string link = linkPath("garbage");
  EmulatorOptions options;
  options.garbage_every = 3;
  EmulatedGlove glove(link, options);
  GloveDriverConfig config;
  config.port = link;
  GloveDriver driver(config);
  const auto records = run(driver, 1.0);
  ASSERT_GT(records.size(), 100u);
  EXPECT_GT(driver.parserStats().garbage_bytes, 0u);
  for (std::size_t i = 1; i < records.size(); ++i)
    EXPECT_EQ(records[i].frame.sequence, records[i - 1].frame.sequence + 1);
}

TEST(GloveDriver, UnpluggedGlovesAreStaleAndReconnectedWhenBack) {
  const std::string link = linkPath("unplug");
  GloveDriverConfig config;
  config.port = link;
  config.retry_min = 0.05;
  config.retry_max = 0.2;
  GloveDriver driver(config);
  auto glove = std::make_unique<EmulatedGlove>(link, EmulatorOptions{});
  EXPECT_GT(run(driver, 0.5).size(), 40u);
  glove->unplug();
  run(driver, 0.3);
  EXPECT_TRUE(driver.stale());
  EXPECT_EQ(driver.state(), GloveDriver::State::kDisconnected);
  EXPECT_EQ(driver.disconnects(), 1u);
  EXPECT_NE(driver.lastError().find(link), std::string::npos) << driver.lastError();
  // Back (a new pty behind the same link): records flow again without anyone's help.
  glove = std::make_unique<EmulatedGlove>(link, EmulatorOptions{});
  const auto records = run(driver, 1.0);
  EXPECT_GT(records.size(), 60u);
  EXPECT_FALSE(driver.stale());
  EXPECT_EQ(driver.connects(), 2u);
  EXPECT_TRUE(driver.lastError().empty()) << driver.lastError();
}

TEST(GloveDriver, MissingPortIsAnErrorNamingItAndRetriedWithGrowingDelays) {
  GloveDriverConfig config;
  config.port = linkPath("missing");
  config.retry_min = 0.02;
  config.retry_max = 0.16;
  GloveDriver driver(config);
  EXPECT_TRUE(run(driver, 0.5).empty());
  EXPECT_TRUE(driver.stale());
  EXPECT_NE(driver.lastError().find(config.port), std::string::npos) << driver.lastError();
  EXPECT_NE(driver.lastError().find("No such file"), std::string::npos) << driver.lastError();
  EXPECT_DOUBLE_EQ(driver.retryDelay(), 0.16);  // doubled up to the cap
  EXPECT_EQ(driver.connects(), 0u);
}

TEST(GloveDriver, AGloveUnpluggedFromItsInterfaceIsReported) {
  const std::string link = linkPath("glove_error");
  EmulatorOptions options;
  options.glove_error = true;
  EmulatedGlove glove(link, options);
  GloveDriverConfig config;
  config.port = link;
  config.sensors = 22;
  config.stream = false;
  GloveDriver driver(config);
  EXPECT_TRUE(run(driver, 0.5).empty());
  EXPECT_TRUE(driver.stale());
  EXPECT_NE(driver.lastError().find("not plugged"), std::string::npos) << driver.lastError();
}

TEST(GloveDriver, BadConfigurationIsRefused) {
  GloveDriverConfig config;
  EXPECT_THROW(GloveDriver{config}, std::invalid_argument);  // no port
  config.port = "/dev/null";
  config.sensors = 20;
  EXPECT_THROW(GloveDriver{config}, std::invalid_argument);
  config.sensors = 22;
  config.baud = 12345;
  EXPECT_THROW(GloveDriver{config}, std::invalid_argument);
}

}  // namespace
