// The hardware emulator driven step by step (realtime = false, tick()), with the test as the
// host on every bus: what the boards send (heartbeats, streams, calibration, rates), the valve
// boards' state machine of docs/can_protocol.md section 8 (release, first command, watchdog,
// host heartbeat timeout, e-stop, supply valve), every fault injection, and garbage from the
// host. One real-time run checks the thread and the clean stop.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <map>
#include <random>
#include <set>
#include <thread>

#include "adroit_driver/can_transport.h"
#include "adroit_driver/hardware_emulator.h"

namespace adroit::driver::can {
namespace {

constexpr double kDt = 0.002;
constexpr int kCylinder = 2;  // A_ARJ2_flex (M24x5): valve board 0, channel 2 (group 0), bus act0

SimConfig simConfig(const std::string& scene = "arm_hand") {
  SimConfig c;
  c.model_path = std::string(ADROIT_MJCF_DIR) + "/" + scene + ".xml";
  c.sensors.enabled = true;
  return c;
}

struct Rx {
  int bus = 0;
  int step = 0;  // the tick after which the host read it
  CanFrame frame;
};

class Emulator : public ::testing::Test {
 protected:
  void SetUp() override {
    char dir[] = "/tmp/adroit_emu_XXXXXX";  // short: socket paths have at most 107 characters
    ASSERT_NE(mkdtemp(dir), nullptr);
    dir_ = dir;
  }
  void TearDown() override {
    host_.clear();
    emulator_.reset();
    for (const auto& p : paths_) ::unlink(p.c_str());
    ::rmdir(dir_.c_str());
  }

  EmulatorConfig config() {
    EmulatorConfig c;
    c.sim = simConfig();
    c.realtime = false;
    c.seed = 7;
    paths_.clear();
    for (const char* bus : {"palm", "act0", "act1", "act2"}) paths_.push_back(dir_ + "/" + bus);
    c.bus_paths = paths_;
    return c;
  }
  void make(EmulatorConfig c) {
    emulator_ = std::make_unique<HardwareEmulator>(c);
    emulator_->start();
    mapping_ = emulator_->mapping();
    host_.clear();
    host_.resize(mapping_.buses.size());
    hung_up_.assign(mapping_.buses.size(), false);
  }
  void make() { make(config()); }

  // ---- the host's side
  void connect(int bus) {
    std::string error;
    host_[bus] = openSeqpacket(paths_[bus], &error);
    ASSERT_TRUE(host_[bus].has_value()) << error;
    hung_up_[bus] = false;
  }
  void connectAll() {
    for (std::size_t b = 0; b < host_.size(); ++b) connect(static_cast<int>(b));
  }
  void write(int bus, const CanFrame& frame) {
    ASSERT_TRUE(host_[bus]);
    ASSERT_EQ(host_[bus]->write(frame), IoStatus::kOk);
  }
  template <class T>
  void send(int bus, const T& message) {
    CanFrame f;
    ASSERT_TRUE(encode(message, &f).ok());
    write(bus, f);
  }
  void sendRaw(int bus, const void* bytes, std::size_t size) {
    ASSERT_EQ(::send(host_[bus]->fd(), bytes, size, MSG_DONTWAIT), static_cast<ssize_t>(size));
  }
  void heartbeat() {
    for (std::size_t b = 0; b < host_.size(); ++b)
      if (host_[b]) send(static_cast<int>(b), HeartbeatFrame{kHostNode, kProtocolVersion, NodeState::kOperational, 0});
  }
  void release(int only_bus = -1) {
    for (std::size_t b = 1; b < host_.size(); ++b)
      if (host_[b] && (only_bus < 0 || only_bus == static_cast<int>(b)))
        send(static_cast<int>(b), EstopFrame{kHostNode, EstopAction::kRelease, EstopCause::kNone});
  }
  // The host's cycle: these groups (board, group) every 2 steps with these volts.
  void command(int board, int group, std::array<double, 3> volts) { commands_[{board, group}] = volts; }
  void commandCylinder(int cylinder, double volts) {
    const auto& ch = mapping_.cylinder[cylinder];
    auto& v = commands_.emplace(std::make_pair(int(ch.board), ch.channel / 3), std::array<double, 3>{-5, -5, -5})
                  .first->second;
    v[ch.channel % 3] = volts;
  }
  int busOfBoard(int board) const {
    for (std::size_t b = 0; b < mapping_.valve_boards.size(); ++b)
      for (auto vb : mapping_.valve_boards[b])
        if (vb == board) return static_cast<int>(b);
    return -1;
  }
  void hostCycle() {
    if (heartbeats_ && host_step_ % 50 == 0) {
      heartbeat();
      last_heartbeat_clock_ = emulator_->snapshot().clock;
    }
    if (host_step_ % 2 == 0) {
      for (const auto& [key, volts] : commands_) {
        ValveCommandFrame f;
        f.board = static_cast<std::uint8_t>(key.first);
        f.first_channel = static_cast<std::uint8_t>(3 * key.second);
        f.count = key.second == 2 ? 2 : 3;  // 8-channel boards: 3 + 3 + 2
        f.volts = volts;
        f.seq = static_cast<std::uint8_t>(host_step_ / 2);
        const int bus = busOfBoard(key.first);
        if (host_[bus]) send(bus, f);
      }
      if (!commands_.empty()) last_command_clock_ = emulator_->snapshot().clock;
    }
    ++host_step_;
  }
  void drain() {
    CanFrame in[256];
    for (std::size_t b = 0; b < host_.size(); ++b) {
      if (!host_[b] || hung_up_[b]) continue;
      for (;;) {
        const ReadResult r = host_[b]->read(in, 256, std::chrono::nanoseconds(0));
        for (std::size_t k = 0; k < r.count; ++k) rx_.push_back({static_cast<int>(b), step_, in[k]});
        if (r.status == IoStatus::kHangUp) hung_up_[b] = true;
        if (r.status != IoStatus::kOk || r.count < 256) break;
      }
    }
  }
  void tick(int n = 1) {
    for (int k = 0; k < n; ++k) {
      hostCycle();
      emulator_->tick();
      ++step_;
      drain();
    }
  }
  // Host heartbeats and the release, then until every valve board is operational.
  void releaseAndRun() {
    tick(2);
    release();
    tick(2);
    for (const auto& vb : emulator_->snapshot().valve_boards)
      ASSERT_EQ(vb.state, NodeState::kOperational) << int(vb.node);
  }

  std::vector<Rx> frames(std::uint32_t id, int since_step = 0) const {
    std::vector<Rx> out;
    for (const auto& r : rx_)
      if (r.step >= since_step && isStandardData(r.frame) && standardId(r.frame) == id) out.push_back(r);
    return out;
  }
  std::vector<HeartbeatFrame> heartbeats(std::uint8_t node, int since_step = 0) const {
    std::vector<HeartbeatFrame> out;
    for (const auto& r : frames(kHeartbeatIdBase + node, since_step)) {
      HeartbeatFrame h;
      EXPECT_EQ(decode(r.frame, &h), DecodeError::kNone);
      out.push_back(h);
    }
    return out;
  }
  std::size_t countOnBus(int bus, int since_step = 0) const {
    std::size_t n = 0;
    for (const auto& r : rx_) n += r.bus == bus && r.step >= since_step;
    return n;
  }
  NodeState valveState(int board) const {
    for (const auto& vb : emulator_->snapshot().valve_boards)
      if (vb.node == valveBoardNode(static_cast<std::uint8_t>(board))) return vb.state;
    ADD_FAILURE() << "no valve board " << board;
    return NodeState::kBoot;
  }

  std::string dir_;
  std::vector<std::string> paths_;
  std::unique_ptr<HardwareEmulator> emulator_;
  Mapping mapping_;
  std::vector<std::optional<CanTransport>> host_;
  std::vector<bool> hung_up_;
  std::vector<Rx> rx_;
  std::map<std::pair<int, int>, std::array<double, 3>> commands_;
  bool heartbeats_ = true;
  int step_ = 0, host_step_ = 0;
  double last_heartbeat_clock_ = 0, last_command_clock_ = 0;
};

// Expected count k out of n at probability p: within 5 standard deviations.
void expectBinomial(std::uint64_t k, std::uint64_t n, double p) {
  const double mean = n * p, sd = std::sqrt(n * p * (1 - p));
  EXPECT_NEAR(static_cast<double>(k), mean, 5 * sd + 1) << k << " of " << n << " at p = " << p;
}

// ---------------------------------------------------------------------------- streams

TEST_F(Emulator, EveryNodeSendsHeartbeatsWithVersion1OnItsBus) {
  make();
  connectAll();
  heartbeats_ = false;
  tick(110);  // 220 ms: heartbeats at 2, 102 and 202 ms
  std::vector<std::pair<std::uint8_t, int>> nodes{{kPalmNode, kPalmBus}};
  for (std::size_t b = 1; b < mapping_.buses.size(); ++b) {
    for (auto board : mapping_.valve_boards[b]) nodes.push_back({valveBoardNode(board), int(b)});
    for (auto board : mapping_.sensor_boards[b]) nodes.push_back({sensorBoardNode(board), int(b)});
  }
  ASSERT_EQ(nodes.size(), 13u);  // palm, 6 valve boards, 6 sensor boards
  for (const auto& [node, bus] : nodes) {
    const auto rx = frames(kHeartbeatIdBase + node);
    ASSERT_EQ(rx.size(), 3u) << "node " << int(node);
    for (std::size_t k = 0; k < rx.size(); ++k) {
      EXPECT_EQ(rx[k].bus, bus);
      HeartbeatFrame h;
      ASSERT_EQ(decode(rx[k].frame, &h), DecodeError::kNone);
      EXPECT_EQ(h.version, 1);
      EXPECT_EQ(h.seq, k);
      EXPECT_EQ(h.flags, 0);
      const bool valve = node >= kValveBoardNodeBase && node < kSensorBoardNodeBase;
      // A valve board's first heartbeat is sent while it boots, then it is safe.
      EXPECT_EQ(h.state, !valve ? NodeState::kOperational : k == 0 ? NodeState::kBoot : NodeState::kSafe);
    }
  }
}

TEST_F(Emulator, StreamsCarryTheSnapshotValuesThroughTheCalibrationAtTheirRates) {
  EmulatorConfig c = config();
  Calibration cal = identityCalibration(28, 48);
  for (std::size_t j = 0; j < cal.joint.size(); ++j) cal.joint[j] = {1.02, (j % 2 ? -0.01 : 0.01) * (1 + j % 5)};
  for (auto& a : cal.pressure) a = {0.98, 5000};
  for (auto& a : cal.length) a = {1.01, -0.002};
  cal.supply = {1.03, -2000};
  c.calibration = cal;
  make(c);
  connectAll();
  heartbeats_ = false;
  const int steps = 100;
  std::uint8_t first_seq = 0;
  for (int s = 1; s <= steps; ++s) {
    tick();
    const EmulatorSnapshot snap = emulator_->snapshot();
    // Joints: 7 frames per step (groups 0..5 the hand, group 6 the arm), one sequence number.
    std::set<int> joints_seen;
    for (int g = 0; g < 7; ++g) {
      const auto rx = frames(kJointAnglesIdBase + g, s);
      ASSERT_EQ(rx.size(), 1u) << "group " << g << " step " << s;
      JointAnglesFrame f;
      ASSERT_EQ(decode(rx[0].frame, &f), DecodeError::kNone);
      if (s == 1 && g == 0) first_seq = f.seq;
      EXPECT_EQ(f.seq, static_cast<std::uint8_t>(first_seq + s - 1));
      for (int k = 0; k < 4; ++k) {
        const int index = 4 * g + k;
        const auto it = std::find(mapping_.joint.begin(), mapping_.joint.end(), index);
        if (it == mapping_.joint.end()) {
          EXPECT_TRUE(std::isnan(f.angles[k])) << index;
          continue;
        }
        const auto j = static_cast<std::size_t>(it - mapping_.joint.begin());
        joints_seen.insert(static_cast<int>(j));
        EXPECT_NEAR(cal.joint[j].apply(f.angles[k]), snap.joint[j], 0.49e-3) << "joint " << j;
        EXPECT_GT(std::abs(f.angles[k] - snap.joint[j]), 0.005) << "calibration not inverted, joint " << j;
        EXPECT_NEAR(snap.joint[j], snap.truth_joint[j], 0.05) << "joint " << j;
      }
    }
    EXPECT_EQ(joints_seen.size(), 28u);
    // 250 Hz streams every other step.
    const bool sample = !frames(kPressureIdBase, s).empty();
    if (!sample) continue;
    for (std::size_t cyl = 0; cyl < 48; ++cyl) {
      const auto& ch = mapping_.cylinder[cyl];
      const std::uint32_t offset = 8 * ch.board + ch.channel / 4;
      for (bool pressure : {true, false}) {
        const auto rx = frames((pressure ? kPressureIdBase : kLengthIdBase) + offset, s);
        ASSERT_EQ(rx.size(), 1u);
        EXPECT_EQ(rx[0].bus, ch.bus);
        SensorFrame f;
        ASSERT_EQ(decode(rx[0].frame, &f), DecodeError::kNone);
        const double v = f.values[ch.channel % 4];
        if (pressure) {
          EXPECT_NEAR(cal.pressure[cyl].apply(v), snap.pressure[cyl], 0.5 * kPressureLsb * 0.98 + 1e-6);
          EXPECT_GT(std::abs(v - snap.pressure[cyl]), 1000);
        } else {
          EXPECT_NEAR(cal.length[cyl].apply(v), snap.length[cyl], 0.5 / kLengthPerLsb * 1.01 + 1e-12);
        }
      }
    }
    const auto supply = frames(kSupplyIdBase + 0, s);
    ASSERT_EQ(supply.size(), 1u);
    EXPECT_EQ(supply[0].bus, mapping_.supply_bus);
    SupplyFrame sf;
    ASSERT_EQ(decode(supply[0].frame, &sf), DecodeError::kNone);
    EXPECT_NEAR(cal.supply.apply(sf.pressure), snap.supply_pressure, 0.5 * kPressureLsb * 1.03 + 1e-6);
    const auto touch = frames(kTouchIdBase + 1, s);  // sensors 4..7: TH and three unused fields
    ASSERT_EQ(touch.size(), 1u);
    TouchFrame tf;
    ASSERT_EQ(decode(touch[0].frame, &tf), DecodeError::kNone);
    EXPECT_NEAR(tf.forces[0], snap.touch[4], 0.5e-3 + 1e-9);
    EXPECT_TRUE(std::isnan(tf.forces[1]));
  }
  // Rates: 500 Hz joints, 250 Hz touch / pressure / length / supply, 10 Hz heartbeats.
  EXPECT_EQ(frames(kJointAnglesIdBase + 6).size(), 100u);
  EXPECT_EQ(frames(kTouchIdBase).size(), 50u);
  EXPECT_EQ(frames(kPressureIdBase + 8 * 5 + 1).size(), 50u);
  EXPECT_EQ(frames(kLengthIdBase + 8 * 3).size(), 50u);
  EXPECT_EQ(frames(kSupplyIdBase).size(), 50u);
  EXPECT_EQ(frames(kHeartbeatIdBase + kPalmNode).size(), 2u);
  // A sensor board's frames of one sample carry its sample counter.
  const auto p = frames(kPressureIdBase + 8 * 2), l = frames(kLengthIdBase + 8 * 2 + 1);
  ASSERT_EQ(p.size(), l.size());
  for (std::size_t k = 0; k < p.size(); ++k) EXPECT_EQ(p[k].frame.data[0], l[k].frame.data[0]);
  const auto snap = emulator_->snapshot();
  EXPECT_EQ(snap.buses[kPalmBus].bad_frames + snap.buses[1].bad_frames, 0u);
  EXPECT_EQ(snap.buses[kPalmBus].frames_sent, countOnBus(kPalmBus));
}

// ---------------------------------------------------------------------------- valve boards

TEST_F(Emulator, ValveBoardsStaySafeWithoutAHostHeartbeatOrARelease) {
  make();
  connectAll();
  heartbeats_ = false;
  commandCylinder(kCylinder, 2.0);
  tick(5);
  release();  // no host heartbeat seen: refused
  tick(20);
  auto snap = emulator_->snapshot();
  for (const auto& vb : snap.valve_boards) EXPECT_EQ(vb.state, NodeState::kSafe);
  EXPECT_FALSE(snap.supply_open);
  EXPECT_EQ(snap.volts[kCylinder], -5.0);
  heartbeats_ = true;
  tick(100);  // heartbeats and commands, but no release
  snap = emulator_->snapshot();
  for (const auto& vb : snap.valve_boards) EXPECT_EQ(vb.state, NodeState::kSafe);
  for (double v : snap.volts) EXPECT_EQ(v, -5.0);
  EXPECT_FALSE(snap.supply_open);
  for (const auto& h : heartbeats(valveBoardNode(0), 2)) EXPECT_EQ(h.flags & kFlagSupplyOpen, 0);
}

TEST_F(Emulator, ReleaseMakesBoardsOperationalAndACommandRaisesThePressure) {
  make();
  connectAll();
  releaseAndRun();
  auto snap = emulator_->snapshot();
  EXPECT_TRUE(snap.supply_open);
  for (double v : snap.volts) EXPECT_EQ(v, -5.0);  // no group commanded yet
  tick(50);
  const auto hb = heartbeats(valveBoardNode(0), 5);
  ASSERT_FALSE(hb.empty());
  EXPECT_EQ(hb.back().state, NodeState::kOperational);
  EXPECT_EQ(hb.back().flags, kFlagSupplyOpen);
  EXPECT_EQ(heartbeats(valveBoardNode(1), 5).back().flags, 0);

  const double p0 = emulator_->snapshot().truth_pressure[kCylinder];
  commandCylinder(kCylinder, 2.0);
  tick(2);
  snap = emulator_->snapshot();
  EXPECT_NEAR(snap.volts[kCylinder], 2.0, 1e-4);  // 0.153 mV steps
  EXPECT_EQ(snap.volts[kCylinder - 1], -5.0);
  tick(150);  // 300 ms
  snap = emulator_->snapshot();
  EXPECT_GT(snap.truth_pressure[kCylinder], p0 + 50e3) << "from " << p0;
  EXPECT_NEAR(snap.pressure[kCylinder], snap.truth_pressure[kCylinder], 20e3);
  for (const auto& vb : snap.valve_boards) EXPECT_EQ(vb.state, NodeState::kOperational);
  EXPECT_EQ(snap.valve_boards[0].watchdog_trips, 0u);
}

TEST_F(Emulator, GroupWatchdogTripsAfter50msAndTheNextReleaseWaitsForAFirstCommand) {
  make();
  connectAll();
  releaseAndRun();
  const int board = 2, group = 1;  // channels 3..5 of valve board 2 (act1): cylinders 19..21
  command(board, group, {1.0, 1.5, 2.0});
  tick(20);
  auto snap = emulator_->snapshot();
  EXPECT_NEAR(snap.volts[8 * board + 4], 1.5, 1e-4);
  commands_.clear();
  const int stop_step = step_;
  const double last_command = last_command_clock_;
  while (valveState(board) == NodeState::kOperational && step_ < stop_step + 100) tick();
  snap = emulator_->snapshot();
  const double tripped_at = snap.clock - kDt;  // boards run at the start of a step
  EXPECT_GE(tripped_at - last_command, 0.050 - 1e-9);
  EXPECT_LE(tripped_at - last_command, 0.052 + 1e-9);
  EXPECT_EQ(valveState(board), NodeState::kSafe);
  EXPECT_EQ(snap.valve_boards[board].watchdog_trips, 1u);
  EXPECT_EQ(snap.volts[8 * board + 4], -5.0);
  EXPECT_EQ(valveState(3), NodeState::kOperational);  // never commanded: not watched
  const auto faults = frames(kFaultIdBase + valveBoardNode(board), stop_step);
  ASSERT_EQ(faults.size(), 1u);
  EXPECT_EQ(faults[0].bus, 2);
  FaultFrame f;
  ASSERT_EQ(decode(faults[0].frame, &f), DecodeError::kNone);
  EXPECT_EQ(f.code, FaultCode::kCommandTimeout);
  EXPECT_EQ(f.channel, 3 * group);
  EXPECT_GE(f.detail, 50);
  EXPECT_LE(f.detail, 52);
  const int after = step_;
  tick(55);
  auto hb = heartbeats(valveBoardNode(board), after);
  ASSERT_FALSE(hb.empty());
  EXPECT_EQ(hb.back().state, NodeState::kSafe);
  EXPECT_EQ(hb.back().flags & kFlagWatchdog, kFlagWatchdog);

  // Released again: the flag clears, the group stays at -5 V until commanded again.
  release(2);
  tick(2);
  EXPECT_EQ(valveState(board), NodeState::kOperational);
  EXPECT_EQ(emulator_->snapshot().volts[8 * board + 4], -5.0);
  const int released = step_;
  tick(55);
  hb = heartbeats(valveBoardNode(board), released);
  ASSERT_FALSE(hb.empty());
  EXPECT_EQ(hb.back().flags & kFlagWatchdog, 0);
  command(board, group, {1.0, 1.5, 2.0});
  tick(2);
  EXPECT_NEAR(emulator_->snapshot().volts[8 * board + 4], 1.5, 1e-4);
}

TEST_F(Emulator, HostHeartbeatMissingFor300msMakesTheBoardsSafe) {
  make();
  connectAll();
  releaseAndRun();
  commandCylinder(kCylinder, 1.0);
  commandCylinder(8 * 4, 1.0);  // act2
  tick(60);
  heartbeats_ = false;
  const double last = last_heartbeat_clock_;
  const int start = step_;
  while (valveState(0) == NodeState::kOperational && step_ < start + 400) tick();
  const auto snap = emulator_->snapshot();
  const double safe_at = snap.clock - kDt;
  EXPECT_GE(safe_at - last, 0.300 - 1e-9);
  EXPECT_LE(safe_at - last, 0.302 + 1e-9);
  for (const auto& vb : snap.valve_boards) EXPECT_EQ(vb.state, NodeState::kSafe);
  for (const auto& vb : snap.valve_boards) EXPECT_EQ(vb.watchdog_trips, 0u);  // commands kept coming
  EXPECT_FALSE(snap.supply_open);
  EXPECT_EQ(snap.volts[kCylinder], -5.0);
}

TEST_F(Emulator, EstopEngageFromAnyNodeMakesTheBoardsOfItsBusSafeAtOnce) {
  make();
  connectAll();
  releaseAndRun();
  commandCylinder(kCylinder, 1.0);
  tick(10);
  send(2, EstopFrame{kHostNode, EstopAction::kEngage, EstopCause::kOperator});
  tick();
  EXPECT_EQ(valveState(2), NodeState::kSafe);
  EXPECT_EQ(valveState(3), NodeState::kSafe);
  EXPECT_EQ(valveState(0), NodeState::kOperational);
  EXPECT_TRUE(emulator_->snapshot().supply_open);
  send(1, EstopFrame{kPalmNode, EstopAction::kEngage, EstopCause::kButton});  // relayed from another node
  tick();
  EXPECT_EQ(valveState(0), NodeState::kSafe);
  EXPECT_EQ(valveState(1), NodeState::kSafe);
  auto snap = emulator_->snapshot();
  EXPECT_FALSE(snap.supply_open);
  EXPECT_EQ(snap.volts[kCylinder], -5.0);
  // Only the host's release is obeyed.
  send(1, EstopFrame{kPalmNode, EstopAction::kRelease, EstopCause::kNone});
  tick(2);
  EXPECT_EQ(valveState(0), NodeState::kSafe);
  EXPECT_EQ(emulator_->snapshot().buses[1].bad_frames, 1u);
  release();
  tick(2);
  EXPECT_EQ(valveState(0), NodeState::kOperational);
  EXPECT_TRUE(emulator_->snapshot().supply_open);
}

TEST_F(Emulator, AHostOfAnotherProtocolVersionIsRefusedWithFault6) {
  make();
  connectAll();
  heartbeats_ = false;
  CanFrame hb;
  encode(HeartbeatFrame{kHostNode, kProtocolVersion, NodeState::kOperational, 0}, &hb);
  hb.data[1] = 2;
  write(1, hb);
  tick(2);
  release(1);
  tick(2);
  EXPECT_EQ(valveState(0), NodeState::kSafe);
  for (std::uint8_t board : {0, 1}) {
    const auto faults = frames(kFaultIdBase + valveBoardNode(board));
    ASSERT_EQ(faults.size(), 1u);
    FaultFrame f;
    ASSERT_EQ(decode(faults[0].frame, &f), DecodeError::kNone);
    EXPECT_EQ(f.code, FaultCode::kVersionMismatch);
    EXPECT_EQ(f.detail, 2);
  }
  EXPECT_EQ(emulator_->snapshot().buses[1].bad_frames, 1u);
}

// ---------------------------------------------------------------------------- fault injection

TEST_F(Emulator, DropLosesOutgoingFramesWithTheInjectedProbability) {
  make();
  connectAll();
  heartbeats_ = false;
  emulator_->setDropProbability(0.3, kPalmBus);
  const int steps = 400;
  tick(steps);
  const auto snap = emulator_->snapshot();
  const auto& palm = snap.buses[kPalmBus];
  const std::uint64_t generated = 7 * steps + 2 * (steps / 2) + steps / 50;  // joints, touch, heartbeats
  EXPECT_EQ(palm.frames_sent + palm.dropped, generated);
  EXPECT_EQ(countOnBus(kPalmBus), palm.frames_sent);
  expectBinomial(palm.dropped, generated, 0.3);
  std::size_t joints = 0;
  for (int g = 0; g < 7; ++g) joints += frames(kJointAnglesIdBase + g).size();
  expectBinomial(7 * steps - joints, 7 * steps, 0.3);
  for (std::size_t b = 1; b < snap.buses.size(); ++b) EXPECT_EQ(snap.buses[b].dropped, 0u);
  // Off again: everything arrives.
  emulator_->setDropProbability(0, kAllBuses);
  const int from = step_ + 1;
  tick(10);
  EXPECT_EQ(frames(kJointAnglesIdBase + 3, from).size(), 10u);
}

TEST_F(Emulator, CorruptedFramesAreRejectedByTheHostsStrictDecoder) {
  make();
  connectAll();
  heartbeats_ = false;
  std::string message;
  ASSERT_TRUE(emulator_->inject("corrupt", "act0", 0.4, &message)) << message;
  tick(200);
  const auto snap = emulator_->snapshot();
  std::uint64_t rejected = 0, total = 0;
  std::set<DecodeError> kinds;
  for (const auto& r : rx_) {
    Message m;
    const DecodeError e = decode(r.frame, &m);
    if (r.bus != 1) {
      EXPECT_EQ(e, DecodeError::kNone) << toString(r.frame);
      continue;
    }
    ++total;
    if (e != DecodeError::kNone) ++rejected, kinds.insert(e);
  }
  EXPECT_EQ(rejected, snap.buses[1].corrupted);
  EXPECT_EQ(total, snap.buses[1].frames_sent);
  expectBinomial(rejected, total, 0.4);
  EXPECT_TRUE(kinds.count(DecodeError::kBadDlc));
  EXPECT_TRUE(kinds.count(DecodeError::kRawOutOfRange));
  EXPECT_TRUE(kinds.count(DecodeError::kReservedBits));  // supply frames
}

TEST_F(Emulator, DelayHoldsOutgoingFramesBackInOrder) {
  make();
  connectAll();
  heartbeats_ = false;
  tick(5);
  emulator_->setDelay(0.020, kPalmBus);
  const int from = step_ + 1;
  tick(30);
  const auto rx = frames(kJointAnglesIdBase + 2, from);
  ASSERT_EQ(rx.size(), 20u);  // the first 10 steps' frames are still held back when the delay begins
  EXPECT_EQ(rx.front().step, from + 10);
  std::uint8_t seq = rx.front().frame.data[0];
  for (const auto& r : rx) EXPECT_EQ(r.frame.data[0], seq++);  // in order, none lost
  // The act buses are not delayed.
  EXPECT_LE(frames(kPressureIdBase, from).front().step, from + 1);
  EXPECT_GT(emulator_->snapshot().buses[kPalmBus].delayed, 0u);
  emulator_->setDelay(0, kPalmBus);
  const int undelayed = step_ + 1;
  tick(15);
  const auto later = frames(kJointAnglesIdBase + 2, undelayed);
  EXPECT_EQ(later.size(), 25u);  // the 10 held back, then one per step
}

TEST_F(Emulator, AStuckSensorKeepsItsValuesWhileTheTruthMoves) {
  make();
  connectAll();
  releaseAndRun();
  tick(10);
  std::string message;
  ASSERT_TRUE(emulator_->inject("stuck_sensor", emulator_->cylinderNames()[kCylinder], 1, &message)) << message;
  const double p0 = emulator_->snapshot().truth_pressure[kCylinder];
  commandCylinder(kCylinder, 3.0);
  const int from = step_ + 1;
  tick(150);
  auto snap = emulator_->snapshot();
  EXPECT_GT(snap.truth_pressure[kCylinder], p0 + 50e3);
  const auto& ch = mapping_.cylinder[kCylinder];
  const auto rx = frames(kPressureIdBase + 8 * ch.board + ch.channel / 4, from);
  const auto lx = frames(kLengthIdBase + 8 * ch.board + ch.channel / 4, from);
  ASSERT_GE(rx.size(), 70u);
  ASSERT_EQ(rx.size(), lx.size());
  SensorFrame first, firstl;
  ASSERT_EQ(decode(rx.front().frame, &first), DecodeError::kNone);
  ASSERT_EQ(decode(lx.front().frame, &firstl), DecodeError::kNone);
  bool neighbour_moves = false;
  for (std::size_t k = 0; k < rx.size(); ++k) {
    SensorFrame f, l;
    ASSERT_EQ(decode(rx[k].frame, &f), DecodeError::kNone);
    ASSERT_EQ(decode(lx[k].frame, &l), DecodeError::kNone);
    EXPECT_EQ(f.values[ch.channel % 4], first.values[ch.channel % 4]);
    EXPECT_EQ(l.values[ch.channel % 4], firstl.values[ch.channel % 4]);
    neighbour_moves |= f.values[(ch.channel + 1) % 4] != first.values[(ch.channel + 1) % 4];  // sensor noise
  }
  EXPECT_TRUE(neighbour_moves);
  EXPECT_LT(snap.pressure[kCylinder], p0 + 10e3);
  ASSERT_TRUE(emulator_->inject("stuck_sensor", emulator_->cylinderNames()[kCylinder], -1, &message)) << message;
  tick(4);
  snap = emulator_->snapshot();
  EXPECT_NEAR(snap.pressure[kCylinder], snap.truth_pressure[kCylinder], 20e3);
}

TEST_F(Emulator, SilenceStopsAStreamOrAWholeNode) {
  make();
  connectAll();
  heartbeats_ = false;
  std::string message;
  ASSERT_TRUE(emulator_->inject("silence", "pressure board 2", 1, &message)) << message;
  ASSERT_TRUE(emulator_->inject("silence", "0x21", 1, &message)) << message;  // sensor board 1
  ASSERT_TRUE(emulator_->inject("silence", "palm", 1, &message)) << message;
  int from = step_ + 1;
  tick(60);
  EXPECT_TRUE(frames(kPressureIdBase + 16, from).empty());
  EXPECT_TRUE(frames(kPressureIdBase + 17, from).empty());
  EXPECT_EQ(frames(kLengthIdBase + 16, from).size(), 30u);  // the board's other stream goes on
  EXPECT_FALSE(frames(kHeartbeatIdBase + sensorBoardNode(2), from).empty());
  EXPECT_TRUE(frames(kPressureIdBase + 8, from).empty());
  EXPECT_TRUE(frames(kLengthIdBase + 8, from).empty());
  EXPECT_TRUE(frames(kHeartbeatIdBase + sensorBoardNode(1), from).empty());
  EXPECT_EQ(countOnBus(kPalmBus, from), 0u);
  EXPECT_EQ(frames(kPressureIdBase, from).size(), 30u);
  EXPECT_EQ(emulator_->snapshot().injections.size(), 3u);
  ASSERT_TRUE(emulator_->inject("silence", "palm", -1, &message)) << message;
  ASSERT_TRUE(emulator_->inject("silence", "joints", 1, &message)) << message;
  from = step_ + 1;
  tick(60);
  EXPECT_TRUE(frames(kJointAnglesIdBase, from).empty());
  EXPECT_EQ(frames(kTouchIdBase, from).size(), 30u);
  EXPECT_FALSE(frames(kHeartbeatIdBase + kPalmNode, from).empty());
  ASSERT_TRUE(emulator_->inject("clear", "", 0, &message)) << message;
  from = step_ + 1;
  tick(10);
  EXPECT_EQ(frames(kJointAnglesIdBase, from).size(), 10u);
  EXPECT_EQ(frames(kPressureIdBase + 17, from).size(), 5u);
  EXPECT_EQ(frames(kLengthIdBase + 8, from).size(), 5u);
  EXPECT_TRUE(emulator_->snapshot().injections.empty());
}

TEST_F(Emulator, BusOffSendsAnErrorFrameThenNothingUntilTheHostReconnects) {
  make();
  connectAll();
  releaseAndRun();
  tick(5);
  emulator_->busOff(1);
  tick();
  EXPECT_EQ(host_[1]->counters().bus_off, 1u);
  EXPECT_EQ(host_[1]->busState(), BusState::kBusOff);
  EXPECT_EQ(valveState(0), NodeState::kSafe);  // the boards of that bus are off it too
  EXPECT_EQ(valveState(1), NodeState::kSafe);
  EXPECT_EQ(valveState(2), NodeState::kOperational);
  const int from = step_ + 1;
  tick(60);  // host heartbeats and a release on act0 are not heard
  release(1);
  tick(5);
  EXPECT_EQ(countOnBus(1, from), 0u);
  EXPECT_GT(countOnBus(2, from), 0u);
  auto snap = emulator_->snapshot();
  EXPECT_TRUE(snap.buses[1].bus_off);
  EXPECT_GE(snap.buses[1].ignored, 2u);  // host heartbeat(s) and the release
  EXPECT_EQ(valveState(0), NodeState::kSafe);
  // The host recovers the bus by reconnecting.
  connect(1);
  const int reconnected = step_ + 1;
  tick(60);
  EXPECT_EQ(frames(kPressureIdBase, reconnected).size(), 30u);
  EXPECT_EQ(host_[1]->counters().bus_off, 0u);
  snap = emulator_->snapshot();
  EXPECT_FALSE(snap.buses[1].bus_off);
  EXPECT_EQ(snap.buses[1].connections, 2u);
  release(1);
  tick(2);
  EXPECT_EQ(valveState(0), NodeState::kOperational);
}

TEST_F(Emulator, DisconnectHangsUpAndANewConnectionReplacesTheOld) {
  make();
  connectAll();
  heartbeats_ = false;
  tick(3);
  std::string message;
  ASSERT_TRUE(emulator_->inject("disconnect", "act2", 0, &message)) << message;
  tick();
  EXPECT_TRUE(hung_up_[3]);
  EXPECT_FALSE(emulator_->snapshot().buses[3].connected);
  connect(3);
  int from = step_ + 1;
  tick(4);
  EXPECT_EQ(frames(kPressureIdBase + 8 * 4, from).size(), 2u);
  // A second connection on a bus replaces the first (how the host recovers a bus).
  auto first = std::move(host_[kPalmBus]);
  connect(kPalmBus);
  from = step_ + 1;
  tick(2);
  CanFrame in[256];
  ReadResult r;
  do r = first->read(in, 256, std::chrono::nanoseconds(0));
  while (r.status == IoStatus::kOk && r.count == 256);
  EXPECT_EQ(r.status, IoStatus::kHangUp);
  EXPECT_EQ(frames(kJointAnglesIdBase, from).size(), 2u);
  auto snap = emulator_->snapshot();
  EXPECT_EQ(snap.buses[kPalmBus].connections, 2u);
  EXPECT_EQ(snap.buses[3].connections, 2u);
  // The host hangs up: the emulator lets the connection go and keeps listening.
  host_[2].reset();
  tick();
  snap = emulator_->snapshot();
  EXPECT_FALSE(snap.buses[2].connected);
  EXPECT_TRUE(snap.buses[3].connected);
  connect(2);
  tick();
  EXPECT_TRUE(emulator_->snapshot().buses[2].connected);
}

TEST_F(Emulator, BoardFaultSendsAFaultFrameAndHoldsTheValveBoardInFault) {
  make();
  connectAll();
  releaseAndRun();
  std::string message;
  ASSERT_TRUE(emulator_->inject("board_fault", "valve board 2", 3, &message)) << message;
  ASSERT_TRUE(emulator_->inject("board_fault", "palm", 7, &message)) << message;
  const int from = step_ + 1;
  tick();
  auto faults = frames(kFaultIdBase + valveBoardNode(2), from);
  ASSERT_EQ(faults.size(), 1u);
  FaultFrame f;
  ASSERT_EQ(decode(faults[0].frame, &f), DecodeError::kNone);
  EXPECT_EQ(f.code, FaultCode::kValveDriver);
  EXPECT_EQ(f.channel, kNoChannel);
  faults = frames(kFaultIdBase + kPalmNode, from);
  ASSERT_EQ(faults.size(), 1u);
  ASSERT_EQ(decode(faults[0].frame, &f), DecodeError::kNone);
  EXPECT_EQ(f.code, FaultCode::kOverTemperature);
  EXPECT_EQ(valveState(2), NodeState::kFault);
  EXPECT_EQ(valveState(3), NodeState::kOperational);
  EXPECT_EQ(emulator_->snapshot().palm.state, NodeState::kOperational);
  tick(50);
  EXPECT_EQ(heartbeats(valveBoardNode(2), from).back().state, NodeState::kFault);
  release();
  tick(2);
  EXPECT_EQ(valveState(2), NodeState::kFault);  // until reset
  ASSERT_TRUE(emulator_->inject("clear", "", 0, &message)) << message;
  tick();
  EXPECT_EQ(valveState(2), NodeState::kSafe);  // power-cycled
  release();
  tick(2);
  EXPECT_EQ(valveState(2), NodeState::kOperational);
}

TEST_F(Emulator, AButtonSendsEngageWithCauseButtonAndHoldsItsFlag) {
  make();
  connectAll();
  releaseAndRun();
  emulator_->setButton(valveBoardNode(1), true);
  const int from = step_ + 1;
  tick();
  const auto engage = frames(kEstopIdBase + valveBoardNode(1), from);
  ASSERT_EQ(engage.size(), 1u);
  EXPECT_EQ(engage[0].bus, 1);
  EstopFrame e;
  ASSERT_EQ(decode(engage[0].frame, &e), DecodeError::kNone);
  EXPECT_EQ(e.action, EstopAction::kEngage);
  EXPECT_EQ(e.cause, EstopCause::kButton);
  EXPECT_EQ(valveState(1), NodeState::kSafe);
  EXPECT_EQ(valveState(0), NodeState::kSafe);  // heard the engage frame on act0
  EXPECT_EQ(valveState(2), NodeState::kOperational);
  tick(50);
  EXPECT_EQ(heartbeats(valveBoardNode(1), from).back().flags & kFlagEstopInput, kFlagEstopInput);
  EXPECT_EQ(heartbeats(valveBoardNode(0), from).back().flags & kFlagEstopInput, 0);
  release(1);
  tick(2);
  EXPECT_EQ(valveState(1), NodeState::kSafe);  // its own input is held
  EXPECT_EQ(valveState(0), NodeState::kOperational);
  emulator_->setButton(valveBoardNode(1), false);
  tick();
  release(1);
  tick(50);
  EXPECT_EQ(valveState(1), NodeState::kOperational);
  EXPECT_EQ(heartbeats(valveBoardNode(1), step_ - 49).back().flags & kFlagEstopInput, 0);
  // The palm's button: engage on the palm bus, flag in its heartbeat.
  emulator_->setButton(kPalmNode, true);
  const int palm_from = step_ + 1;
  tick(50);
  ASSERT_EQ(frames(kEstopIdBase + kPalmNode, palm_from).size(), 1u);
  EXPECT_EQ(frames(kEstopIdBase + kPalmNode, palm_from)[0].bus, kPalmBus);
  EXPECT_EQ(heartbeats(kPalmNode, palm_from).back().flags, kFlagEstopInput);
}

TEST_F(Emulator, GarbageFromTheHostIsCountedAndNeverActedOn) {
  make();
  connectAll();
  heartbeats_ = false;
  tick(2);
  // Datagrams that are not one frame (empty, short, long) and frames the transport drops.
  const std::uint8_t junk[40] = {1, 2, 3, 4, 5, 6, 7, 8, 9};
  sendRaw(1, junk, 5);
  sendRaw(1, junk, 17);
  sendRaw(1, junk, 40);
  CanFrame bad_dlc = makeFrame(0x080, junk, 3);
  bad_dlc.dlc = 12;
  sendRaw(1, &bad_dlc, sizeof bad_dlc);
  CanFrame error;
  error.id = kErrFlag | kErrBusOff;
  error.dlc = 8;
  sendRaw(1, &error, sizeof error);
  tick();
  auto snap = emulator_->snapshot();
  EXPECT_EQ(snap.buses[1].bad_datagrams, 5u);
  EXPECT_EQ(snap.buses[1].frames_received, 0u);
  // Frames the strict decoder rejects or a host never sends.
  const std::uint8_t release_bad_cause[3] = {0, 2, 1};
  std::vector<CanFrame> bad = {
      makeFrame(0x7FF, junk, 4),                       // unassigned identifier
      makeFrame(kEstopIdBase, release_bad_cause, 3),   // release with a cause
      makeFrame(kHeartbeatIdBase, junk, 2),            // version 2
      makeFrame(kValveCommandIdBase + 8 * 0, junk, 6),  // wrong length
      makeFrame(kJointAnglesIdBase, junk, 8),          // a palm frame
      makeFrame(kHeartbeatIdBase + valveBoardNode(0), release_bad_cause, 3),  // wrong length
  };
  CanFrame extended = makeFrame(0x080, junk, 3);
  extended.id |= kEffFlag;
  bad.push_back(extended);
  CanFrame remote = makeFrame(0x080, junk, 0);
  remote.id |= kRtrFlag;
  bad.push_back(remote);
  ValveCommandFrame other_bus;  // valve board 2 is on act1
  other_bus.board = 2;
  CanFrame f;
  ASSERT_TRUE(encode(other_bus, &f).ok());
  bad.push_back(f);
  ValveCommandFrame beyond;  // channels 9..11: an 8-channel board has none
  beyond.board = 0;
  beyond.first_channel = 9;
  ASSERT_TRUE(encode(beyond, &f).ok());
  bad.push_back(f);
  HeartbeatFrame not_host{valveBoardNode(1), kProtocolVersion, NodeState::kOperational, 0};
  ASSERT_TRUE(encode(not_host, &f).ok());
  bad.push_back(f);
  for (const auto& frame : bad) write(1, frame);
  tick();
  snap = emulator_->snapshot();
  EXPECT_EQ(snap.buses[1].bad_frames, bad.size());
  EXPECT_EQ(snap.buses[1].frames_received, bad.size());
  for (const auto& vb : snap.valve_boards) EXPECT_EQ(vb.state, NodeState::kSafe);

  // Random datagrams of random sizes on every bus: each is accounted for exactly once.
  std::mt19937 rng(3);
  std::uint64_t sent = 0;
  for (int round = 0; round < 20; ++round) {
    for (int k = 0; k < 50; ++k) {
      std::uint8_t bytes[32];
      for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
      const std::size_t size = rng() % 3 == 0 ? rng() % 33 : 16;
      const int bus = static_cast<int>(rng() % 4);
      if (size == 0) continue;  // an empty datagram reads as a hang-up check; skip it
      sendRaw(bus, bytes, size);
      ++sent;
    }
    tick();
  }
  snap = emulator_->snapshot();
  std::uint64_t accounted = 0;
  for (const auto& b : snap.buses) accounted += b.frames_received + b.bad_datagrams;
  EXPECT_EQ(accounted, sent + bad.size() + 5);
  const int from = step_ + 1;
  tick(4);
  EXPECT_EQ(frames(kJointAnglesIdBase, from).size(), 4u);  // still streaming
}

TEST_F(Emulator, InjectByTextRefusesUnknownFaultsTargetsAndValues) {
  make();
  std::string m;
  EXPECT_FALSE(emulator_->inject("explode", "", 0, &m));
  EXPECT_NE(m.find("unknown fault 'explode'"), std::string::npos) << m;
  EXPECT_FALSE(emulator_->inject("drop", "act7", 0.1, &m));
  EXPECT_NE(m.find("unknown bus 'act7'"), std::string::npos) << m;
  EXPECT_FALSE(emulator_->inject("drop", "act0", 1.5, &m));
  EXPECT_NE(m.find("[0, 1]"), std::string::npos) << m;
  EXPECT_FALSE(emulator_->inject("delay", "", 5, &m));
  EXPECT_FALSE(emulator_->inject("delay", "", std::nan(""), &m));
  EXPECT_FALSE(emulator_->inject("stuck_sensor", "A_nope", 1, &m));
  EXPECT_NE(m.find("unknown cylinder 'A_nope'"), std::string::npos) << m;
  EXPECT_FALSE(emulator_->inject("board_fault", "valve board 7", 1, &m));  // 6 boards
  EXPECT_NE(m.find("not a board of this robot"), std::string::npos) << m;
  EXPECT_FALSE(emulator_->inject("board_fault", "valve board 1", 9, &m));
  EXPECT_FALSE(emulator_->inject("button", "0x00", 1, &m));  // the host
  EXPECT_FALSE(emulator_->inject("button", "left hand", 1, &m));
  EXPECT_NE(m.find("unknown node 'left hand'"), std::string::npos) << m;
  EXPECT_FALSE(emulator_->inject("silence", "pressure board 6", 1, &m));
  EXPECT_FALSE(emulator_->inject("silence", "heartbeats", 1, &m));
  EXPECT_THROW(emulator_->setDropProbability(0.5, 4), std::invalid_argument);
  EXPECT_THROW(emulator_->boardFault(0x3F, FaultCode::kInternal), std::invalid_argument);
  EXPECT_TRUE(emulator_->snapshot().injections.empty());

  EXPECT_TRUE(emulator_->inject("drop", "", 0.1, &m)) << m;
  EXPECT_TRUE(emulator_->inject("corrupt", "act1", 0.2, &m)) << m;
  EXPECT_TRUE(emulator_->inject("delay", "palm", 0.01, &m)) << m;
  EXPECT_TRUE(emulator_->inject("stuck_sensor", emulator_->cylinderNames()[5], 1, &m)) << m;
  EXPECT_TRUE(emulator_->inject("silence", "length board 5", 1, &m)) << m;
  EXPECT_TRUE(emulator_->inject("button", "sensor board 3", 1, &m)) << m;
  EXPECT_TRUE(emulator_->inject("board_fault", "0x15", 0, &m)) << m;
  const auto injections = emulator_->snapshot().injections;
  EXPECT_EQ(injections.size(), 4u + 1 + 1 + 1 + 1 + 1) << ::testing::PrintToString(injections);
  EXPECT_TRUE(emulator_->inject("clear", "", 0, &m)) << m;
  EXPECT_TRUE(emulator_->snapshot().injections.empty());
}

// ---------------------------------------------------------------------------- configuration, real time

TEST_F(Emulator, BadConfigurationsAreRefusedWithOneLine) {
  EmulatorConfig c = config();
  c.sim.mode = ActuationMode::kForce;
  EXPECT_THROW(HardwareEmulator e(c), std::invalid_argument);
  c = config();
  c.bus_paths.pop_back();
  EXPECT_THROW(HardwareEmulator e(c), std::invalid_argument);
  c = config();
  c.joint_rate = 0;
  EXPECT_THROW(HardwareEmulator e(c), std::invalid_argument);
  c = config();
  c.faults.drop_probability = -0.1;
  EXPECT_THROW(HardwareEmulator e(c), std::invalid_argument);
  c = config();
  c.calibration = identityCalibration(27, 48);
  EXPECT_THROW(HardwareEmulator e(c), std::invalid_argument);
  c = config();
  Mapping m = defaultMapping({}, {}, {});
  c.mapping = m;
  EXPECT_THROW(HardwareEmulator e(c), std::invalid_argument);

  make();
  EXPECT_THROW(emulator_->start(), std::logic_error);
  Calibration zero = identityCalibration(28, 48);
  zero.joint[3].gain = 0;
  EXPECT_THROW(emulator_->setCalibration(zero), std::invalid_argument);
  HardwareEmulator second(config());  // the same paths: someone listens there
  try {
    second.start();
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("another process is listening"), std::string::npos) << e.what();
  }
}

TEST_F(Emulator, RealTimeThreadStreamsAndStopRemovesTheSockets) {
  EmulatorConfig c = config();
  c.realtime = true;
  make(c);
  EXPECT_THROW(emulator_->tick(), std::logic_error);
  connect(kPalmBus);
  const auto start = std::chrono::steady_clock::now();
  std::size_t joints = 0, heartbeats = 0;
  CanFrame in[256];
  while (std::chrono::steady_clock::now() - start < std::chrono::milliseconds(300)) {
    const ReadResult r = host_[kPalmBus]->read(in, 256, std::chrono::milliseconds(10));
    for (std::size_t k = 0; k < r.count; ++k) {
      joints += standardId(in[k]) == kJointAnglesIdBase;
      heartbeats += standardId(in[k]) == kHeartbeatIdBase + kPalmNode;
    }
  }
  const auto snap = emulator_->snapshot();
  EXPECT_GE(snap.steps, 100u);
  EXPECT_GE(joints, 100u);  // 500 Hz for 0.3 s, minus the start
  EXPECT_GE(heartbeats, 2u);
  EXPECT_EQ(snap.buses[kPalmBus].connections, 1u);
  emulator_->stop();
  struct stat info;
  for (const auto& p : paths_) EXPECT_NE(::lstat(p.c_str(), &info), 0) << p;
  const ReadResult r = host_[kPalmBus]->read(in, 256, std::chrono::milliseconds(100));
  EXPECT_EQ(r.status, IoStatus::kHangUp);
}

TEST_F(Emulator, TheHandSceneHasItsOwnLayout) {
  EmulatorConfig c;
  c.sim = simConfig("hand");
  c.realtime = false;
  HardwareEmulator e(c);
  const Mapping& m = e.mapping();
  EXPECT_EQ(m.joint.size(), e.jointNames().size());
  EXPECT_EQ(e.busPaths().size(), m.buses.size());
  EXPECT_EQ(e.busPaths()[0], "/tmp/adroit_can_palm");
  const auto snap = e.snapshot();
  EXPECT_EQ(snap.buses.size(), m.buses.size());
  EXPECT_EQ(snap.valve_boards.size(), (e.cylinderNames().size() + 7) / 8);
}

// The lab's hand placing the object: the boards' world moves it (the motion-capture stand-in
// then reports it there), with the simulation's checks.
std::array<double, 3> placedObjectPosition(const HardwareEmulator& e) {
  const auto s = e.snapshot();
  return {s.object[0], s.object[1], s.object[2]};
}

TEST_F(Emulator, PlaceObjectMovesTheObjectAtTheNextStepWithTheSimulationsChecks) {
  EmulatorConfig c = config();
  c.sim = simConfig("bottle");
  make(c);
  ASSERT_TRUE(emulator_->hasObject());
  const std::array<double, 3> target{0.3, -0.4, 1.0}, still{0, 0, 0};
  const auto before = placedObjectPosition(*emulator_);
  ASSERT_GT(std::hypot(before[0] - target[0], before[1] - target[1]), 0.2);  // a move worth checking
  std::string error;
  ASSERT_TRUE(emulator_->placeObject(target, {2, 0, 0, 0}, still, still, &error)) << error;  // normalised
  for (int k = 0; k < 10; ++k) emulator_->tick();  // the motion capture's 5 ms delay
  const auto after = placedObjectPosition(*emulator_);
  EXPECT_NEAR(after[0], target[0], 0.005);
  EXPECT_NEAR(after[1], target[1], 0.005);
  EXPECT_NEAR(after[2], target[2], 0.005);  // 20 ms of fall: 2 mm
  EXPECT_NEAR(emulator_->snapshot().object[3], 1.0, 1e-3);

  EXPECT_FALSE(emulator_->placeObject(target, {0, 0, 0, 0}, still, still, &error));
  EXPECT_NE(error.find("quaternion"), std::string::npos) << error;
  EXPECT_FALSE(emulator_->placeObject({std::nan(""), 0, 1}, {1, 0, 0, 0}, still, still, &error));
  EXPECT_FALSE(emulator_->placeObject(target, {1, 0, 0, 0}, {1e3, 0, 0}, still, &error));
  EXPECT_NE(error.find("max_reset_velocity"), std::string::npos) << error;
  for (int k = 0; k < 3; ++k) emulator_->tick();
  EXPECT_NEAR(placedObjectPosition(*emulator_)[0], target[0], 0.005);  // a refusal moves nothing

  EmulatorConfig arm = config();  // no object in this scene
  arm.bus_paths.clear();
  for (const char* bus : {"p2", "a0", "a1", "a2"}) arm.bus_paths.push_back(dir_ + "/" + bus);
  HardwareEmulator no_object(arm);
  EXPECT_FALSE(no_object.placeObject(target, {1, 0, 0, 0}, still, still, &error));
  EXPECT_NE(error.find("no free body"), std::string::npos) << error;
}

TEST_F(Emulator, PlaceObjectInRealTimeWaitsForTheSteppingThreadsVerdict) {
  EmulatorConfig c = config();
  c.sim = simConfig("bottle");
  c.realtime = true;
  make(c);
  const std::array<double, 3> target{-0.3, 0.4, 1.2}, up{0, 0, 0.3}, still{0, 0, 0};
  std::string error;
  ASSERT_TRUE(emulator_->placeObject(target, {1, 0, 0, 0}, up, still, &error)) << error;
  std::this_thread::sleep_for(std::chrono::milliseconds(40));
  const auto p = placedObjectPosition(*emulator_);
  EXPECT_NEAR(p[0], target[0], 0.01);
  EXPECT_NEAR(p[1], target[1], 0.01);
  EXPECT_NEAR(p[2], target[2], 0.03);  // thrown up at 0.3 m/s: within 1 cm over 40 ms, plus scheduling
  EXPECT_FALSE(emulator_->placeObject(target, {1, 0, 0, 0}, still, {0, 1e3, 0}, &error));  // the thread's verdict
  EXPECT_NE(error.find("angular velocity"), std::string::npos) << error;
}

}  // namespace
}  // namespace adroit::driver::can
