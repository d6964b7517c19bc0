// The emulator core, driven with bytes and simulated times (no pty): its answers to each
// command, stream pacing on absolute deadlines, fault injection, and the trajectories.
#include <adroit_teleop/glove_emulator.h>
#include <gtest/gtest.h>
#include <stdlib.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "temp_dir.h"
#include "unreadable_files.h"

using namespace adroit::teleop;
using Bytes = std::vector<std::uint8_t>;

namespace {

std::shared_ptr<const GloveTrajectory> synthetic(int sensors = 22, double period = 4) {
  return std::make_shared<SyntheticTrajectory>(sensors, period);
}

Bytes answer(GloveEmulator& glove, const Bytes& in, double t) {
  EmulatorOutput out;
  glove.receive(in.data(), in.size(), t, out);
  return out.bytes;
}

using adroit::teleop::test::scratchDir;

std::string writeTemp(const std::string& name, const std::string& text) {
  const std::string path = scratchDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

std::string csvError(const std::string& text, int sensors = 18) {
  const std::string path = writeTemp("traj.csv", text);
  try {
    CsvTrajectory::load(path, sensors);
  } catch (const TrajectoryError& e) {
    return e.what();
  }
  return "";
}

// "t, v, v, ..." with `sensors` copies of v.
std::string row(double t, double v, int sensors = 18) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", t);
  std::string s = buf;
  std::snprintf(buf, sizeof buf, ", %g", v);
  for (int i = 0; i < sensors; ++i) s += buf;
  return s + "\n";
}

}  // namespace

TEST(SyntheticTrajectory, SinusoidsWithSpreadPhases) {
  const SyntheticTrajectory traj(22, 4.0);
  std::uint8_t v[22];
  traj.sample(0.0, v);
  EXPECT_EQ(v[0], 128);   // 128 + 100 sin(0)
  EXPECT_EQ(v[11], 128);  // phase pi
  traj.sample(1.0, v);    // a quarter period
  EXPECT_EQ(v[0], 228);
  EXPECT_EQ(v[11], 28);
  for (double t = 0; t < 8; t += 0.013) {
    traj.sample(t, v);
    for (std::uint8_t x : v) {
      EXPECT_GE(x, 28);
      EXPECT_LE(x, 228);
    }
  }
  EXPECT_THROW(SyntheticTrajectory(20, 4.0), std::invalid_argument);
  EXPECT_THROW(SyntheticTrajectory(22, 0.0), std::invalid_argument);
}

TEST(DeferredTrajectory, HoldsTheFirstSampleUntilStartedThenPlaysFromThere) {
  auto motion = std::make_shared<SyntheticTrajectory>(22, 4.0);
  DeferredTrajectory deferred(motion);
  std::uint8_t held[22], expected[22];
  motion->sample(0.0, expected);
  for (double t : {0.0, 1.0, 7.3}) {  // a quarter period and more: the motion would have moved
    deferred.sample(t, held);
    EXPECT_EQ(std::vector<std::uint8_t>(held, held + 22), std::vector<std::uint8_t>(expected, expected + 22)) << t;
  }
  EXPECT_FALSE(deferred.started());
  deferred.start(5.0);
  EXPECT_TRUE(deferred.started());
  deferred.sample(6.0, held);  // one second into the motion
  motion->sample(1.0, expected);
  EXPECT_EQ(std::vector<std::uint8_t>(held, held + 22), std::vector<std::uint8_t>(expected, expected + 22));
  EXPECT_EQ(held[0], 228);
  EXPECT_THROW(DeferredTrajectory(nullptr), std::invalid_argument);
}

TEST(GloveEmulator, PollAnswersOneRecordOfTheTrajectory) {
  GloveEmulator glove(EmulatorOptions{}, synthetic());
  const Bytes out = answer(glove, {'G'}, 1.0);
  ASSERT_EQ(out.size(), 24u);  // 'G', 22 values, 0
  EXPECT_EQ(out[0], 'G');
  EXPECT_EQ(out[1], 228);  // sensor 0 a quarter period in
  EXPECT_EQ(out[12], 28);  // sensor 11
  EXPECT_EQ(out[23], 0);
  EXPECT_EQ(glove.stats().polled_records, 1u);
  EXPECT_FALSE(glove.streaming());
}

TEST(GloveEmulator, SensorCountQueryAndUnknownCommand) {
  EmulatorOptions o;
  o.sensors = 18;
  GloveEmulator glove(o, synthetic(18));
  EXPECT_EQ(answer(glove, {'?', 'S'}, 0), (Bytes{'?', 'S', 18, 0}));
  EXPECT_EQ(answer(glove, {'x'}, 0), (Bytes{'e', '?', 0}));
  EXPECT_EQ(answer(glove, {'?', 'Z'}, 0), (Bytes{'e', '?', 0}));
  // A query split across two reads is still one query.
  EXPECT_TRUE(answer(glove, {'?'}, 0).empty());
  EXPECT_EQ(answer(glove, {'S'}, 0), (Bytes{'?', 'S', 18, 0}));
  EXPECT_EQ(glove.stats().unknown_commands, 2u);
  EXPECT_EQ(glove.stats().error_replies, 2u);
}

TEST(GloveEmulator, StreamPacedOnAbsoluteDeadlines) {
  EmulatorOptions o;
  o.rate_hz = 120;
  GloveEmulator glove(o, synthetic());
  EmulatorOutput out;
  const double t0 = 10.0;
  glove.receive(Bytes{'S'}.data(), 1, t0, out);
  EXPECT_TRUE(out.bytes.empty());  // records come from tick()
  EXPECT_TRUE(glove.streaming());
  EXPECT_DOUBLE_EQ(glove.nextDeadline(), t0);
  // One simulated second, ticked every 0.1 ms: deadlines t0 + k/120 for k = 0..120.
  for (int i = 0; i <= 10000; ++i) glove.tick(t0 + i * 1e-4, out);
  ASSERT_EQ(out.records.size(), 121u);
  for (std::size_t k = 0; k < out.records.size(); ++k) {
    EXPECT_NEAR(out.records[k].t, t0 + k / 120.0, 1e-9);
    EXPECT_TRUE(out.records[k].streamed);
    EXPECT_EQ(out.records[k].sequence, k);
  }
  EXPECT_EQ(glove.stats().missed_deadlines, 0u);
  EXPECT_EQ(out.bytes.size(), 121u * 24u);
  EXPECT_EQ(out.bytes[0], 'S');

  // Stop: nothing more, however long we wait.
  out.clear();
  glove.receive(Bytes{0x03}.data(), 1, t0 + 1.0001, out);
  EXPECT_FALSE(glove.streaming());
  for (int i = 0; i < 1000; ++i) glove.tick(t0 + 1.0001 + i * 1e-3, out);
  EXPECT_TRUE(out.bytes.empty());
  EXPECT_TRUE(std::isinf(glove.nextDeadline()));
}

TEST(GloveEmulator, LateTicksSkipDeadlinesInsteadOfBursting) {
  EmulatorOptions o;
  o.rate_hz = 100;
  GloveEmulator glove(o, synthetic());
  EmulatorOutput out;
  glove.receive(Bytes{'S'}.data(), 1, 0.0, out);
  // Ticks every 35 ms for 1.0 s: each tick sends at most one record.
  int ticks = 0;
  for (double t = 0.0005; t < 1.0; t += 0.035, ++ticks) {
    const std::size_t before = out.records.size();
    glove.tick(t, out);
    EXPECT_LE(out.records.size() - before, 1u);
  }
  EXPECT_EQ(out.records.size(), static_cast<std::size_t>(ticks));
  // Every deadline up to the last tick was either sent or counted as missed.
  const double last_tick = 0.0005 + (ticks - 1) * 0.035;
  const auto deadlines_passed = static_cast<std::uint64_t>(std::floor(last_tick * 100)) + 1;
  EXPECT_EQ(out.records.size() + glove.stats().missed_deadlines, deadlines_passed);
  EXPECT_GT(glove.nextDeadline(), last_tick);
}

TEST(GloveEmulator, PollWhileStreamingAndRestartIgnored) {
  GloveEmulator glove(EmulatorOptions{}, synthetic());
  EmulatorOutput out;
  glove.receive(Bytes{'S'}.data(), 1, 0.0, out);
  glove.receive(Bytes{'S'}.data(), 1, 0.5, out);  // already streaming: the schedule stands
  EXPECT_DOUBLE_EQ(glove.nextDeadline(), 0.0);
  glove.receive(Bytes{'G'}.data(), 1, 0.5, out);
  ASSERT_EQ(out.records.size(), 1u);
  EXPECT_FALSE(out.records[0].streamed);
  EXPECT_EQ(out.bytes[0], 'G');
  glove.reset();  // the glove was unplugged and came back
  EXPECT_FALSE(glove.streaming());
}

TEST(GloveEmulator, GloveErrorAnswersEveryRequest) {
  EmulatorOptions o;
  o.glove_error = true;
  GloveEmulator glove(o, synthetic());
  const Bytes eg = {'e', 'g', 0};
  EXPECT_EQ(answer(glove, {'G'}, 0), eg);
  EXPECT_EQ(answer(glove, {'S'}, 0), eg);
  EXPECT_FALSE(glove.streaming());
  EXPECT_EQ(answer(glove, {'?', 'S'}, 0), eg);
  EXPECT_EQ(answer(glove, {'q'}, 0), (Bytes{'e', '?', 0}));
  EXPECT_TRUE(answer(glove, {0x03}, 0).empty());
  EXPECT_EQ(glove.stats().polled_records + glove.stats().streamed_records, 0u);
}

TEST(GloveEmulator, GarbageIsInjectedAndCostsTheParserNoRecord) {
  EmulatorOptions o;
  o.garbage_every = 3;
  o.rate_hz = 1000;
  o.seed = 11;
  GloveEmulator glove(o, synthetic());
  EmulatorOutput out;
  glove.receive(Bytes{'S'}.data(), 1, 0.0, out);
  for (int i = 0; i < 3000; ++i) glove.tick(i * 1e-4, out);  // 0.3 s: 300 records
  ASSERT_EQ(out.records.size(), 300u);
  EXPECT_GE(glove.stats().garbage_bytes, 100u);       // 100 bursts of 1..8 bytes
  EXPECT_LE(glove.stats().garbage_bytes, 800u);
  EXPECT_EQ(out.bytes.size(), 300u * 24u + glove.stats().garbage_bytes);

  GloveParser parser(22);
  const auto frames = parser.feed(out.bytes.data(), out.bytes.size());
  ASSERT_EQ(frames.size(), 300u);
  for (std::size_t k = 0; k < frames.size(); ++k)
    ASSERT_TRUE(std::equal(frames[k].raw.begin(), frames[k].raw.end(), out.records[k].values.begin())) << k;
  EXPECT_EQ(parser.stats().garbage_bytes, glove.stats().garbage_bytes);
}

TEST(GloveEmulator, OptionsAreChecked) {
  EmulatorOptions o;
  o.rate_hz = 0.5;
  EXPECT_THROW(GloveEmulator(o, synthetic()), std::invalid_argument);
  o.rate_hz = 1001;
  EXPECT_THROW(GloveEmulator(o, synthetic()), std::invalid_argument);
  o = EmulatorOptions{};
  EXPECT_THROW(GloveEmulator(o, synthetic(18)), std::invalid_argument);  // 22-sensor glove, 18-sensor data
  EXPECT_THROW(GloveEmulator(o, nullptr), std::invalid_argument);
  o.sensors = 20;
  EXPECT_THROW(GloveEmulator(o, synthetic()), std::invalid_argument);
}

TEST(CsvTrajectory, PlaysRowsInTimeAndLoops) {
  const std::string path =
      writeTemp("ok.csv", "t,s1,s2,s3,s4,s5,s6,s7,s8,s9,s10,s11,s12,s13,s14,s15,s16,s17,s18\n" + row(5.0, 10) +
                              "\n# a comment\n" + row(5.1, 20) + row(5.2, 30.4));
  const CsvTrajectory traj = CsvTrajectory::load(path, 18);
  EXPECT_EQ(traj.rows(), 3u);
  EXPECT_NEAR(traj.loopDuration(), 0.3, 1e-12);  // 0.2 s of rows + the last row held 0.1 s
  std::uint8_t v[18];
  auto at = [&](double t) {
    traj.sample(t, v);
    return static_cast<int>(v[0]);
  };
  EXPECT_EQ(at(0.0), 10);
  EXPECT_EQ(at(0.05), 10);
  EXPECT_EQ(at(0.15), 20);
  EXPECT_EQ(at(0.25), 30);  // 30.4 rounds to 30
  EXPECT_EQ(at(0.31), 10);  // looped
  EXPECT_EQ(at(0.45), 20);
  EXPECT_EQ(v[17], 20);
}

TEST(CsvTrajectory, BadFilesNameFileAndLine) {
  std::string e = csvError(row(0, 10) + "0.1, 1, 2\n");
  EXPECT_NE(e.find("traj.csv:2: expected 19 columns (t and 18 sensor values), got 3"), std::string::npos) << e;
  e = csvError(row(0, 10) + row(0.1, 0));
  EXPECT_NE(e.find("traj.csv:2: sensor 1 value 0 is outside 1..255"), std::string::npos) << e;
  e = csvError(row(0, 10) + row(0.1, 256));
  EXPECT_NE(e.find("traj.csv:2: sensor 1 value 256 is outside 1..255"), std::string::npos) << e;
  e = csvError(row(0.5, 10) + row(0.5, 10));
  EXPECT_NE(e.find("traj.csv:2: time 0.5 is not after the previous row's 0.5"), std::string::npos) << e;
  std::string r = row(0.2, 10);
  r.replace(r.find(", 10"), 4, ", x1");
  e = csvError(row(0, 10) + r);
  EXPECT_NE(e.find("traj.csv:2: column 2: 'x1' is not a number"), std::string::npos) << e;
  e = csvError("t,a,b\n" + row(0, 10) + "t,a,b\n");  // a header only at the top
  EXPECT_NE(e.find("traj.csv:3: "), std::string::npos) << e;
  e = csvError("# nothing\n\n");
  EXPECT_NE(e.find("traj.csv: no samples"), std::string::npos) << e;
  e = csvError(row(0, 10, 22), 18);
  EXPECT_NE(e.find("traj.csv:1: expected 19 columns"), std::string::npos) << e;
  try {
    CsvTrajectory::load("/nonexistent/traj.csv", 18);
    FAIL() << "no error";
  } catch (const TrajectoryError& err) {
    EXPECT_EQ(std::string(err.what()), "/nonexistent/traj.csv: cannot open (No such file or directory)");
  }
}

// --trajectory names a file from outside: only a regular file of bounded size is read, and
// anything else is one error naming the file, without blocking.
TEST(CsvTrajectory, OnlyRegularFilesOfBoundedSizeAreRead) {
  using test::errorWithin;
  const std::string fifo = test::makeFifo(scratchDir() + "/traj_fifo.csv");
  const auto load = [](const std::string& path) { return [path] { CsvTrajectory::load(path, 18); }; };
  EXPECT_EQ(errorWithin<TrajectoryError>(load(fifo), fifo), fifo + ": not a regular file (a FIFO)");
  EXPECT_EQ(errorWithin<TrajectoryError>(load(scratchDir()), fifo), scratchDir() + ": not a regular file (a directory)");
  EXPECT_EQ(errorWithin<TrajectoryError>(load("/dev/zero"), fifo), "/dev/zero: not a regular file (a character device)");
  const std::string big = test::makeSparseFile(scratchDir() + "/big_traj.csv", kMaxTrajectoryFileBytes + 1);
  const std::string e = errorWithin<TrajectoryError>(load(big), fifo);
  EXPECT_EQ(e.rfind(big + ": ", 0), 0u) << e;
  EXPECT_NE(e.find("over the limit of 64 MB"), std::string::npos) << e;
}
