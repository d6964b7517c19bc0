// CanRobot against fake boards, ROS-free and single-threaded: each of the four buses is a
// socketpair(AF_UNIX, SOCK_SEQPACKET); the test plays the palm MCU, the valve boards and the
// sensor boards on its ends (FakeBoards), drives the robot's clock, and reads what the robot
// sends. Start-up, sensing with calibration, the valve cycle, and every safety case.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>
#include <set>
#include <string>
#include <vector>

#include "adroit_driver/can_robot.h"

#include "allocation_window.h"  // the robot's step and accepted commands must allocate nothing

namespace adroit::driver {
namespace {

using can::CanFrame;
using can::CanTransport;
using can::FrameType;

constexpr double kAtm = description::kAtmosphericPressure;
constexpr int kBuses = 4;
constexpr double kVoltLsb = 5.0 / 32767;

struct Received {
  int bus = 0;
  double time = 0;  // the test clock when it was read
  CanFrame frame;
  std::uint32_t id() const { return can::standardId(frame); }
};

// The robot's boards on the test's ends of the buses: the palm MCU (bus 0), valve and sensor
// boards b = 0..5 on bus 1 + b / 2 (the default mapping of arm_hand). Values are what the
// boards put on the bus (before the driver's calibration).
class FakeBoards {
 public:
  FakeBoards() {
    for (int b = 0; b < kBuses; ++b) connect(b);
    joint.fill(0.1);
    touch.fill(0.0);
    for (auto& board : pressure) board.fill(kAtm);
    for (auto& board : length) board.fill(0.02);
    state.fill(can::NodeState::kOperational);
    flags.fill(0);
    version.fill(can::kProtocolVersion);
  }

  // A new socketpair for bus b: the robot's end goes to the next open_bus of that bus.
  void connect(int b) {
    int fds[2];
    EXPECT_EQ(::socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds), 0);
    robot_end[b].emplace(fds[0], "test:" + kNames[b]);
    peer[b].emplace(fds[1], "peer " + kNames[b]);
  }

  CanRobotConfig config() {
    CanRobotConfig c;
    c.model_path = std::string(ADROIT_MJCF_DIR) + "/arm_hand.xml";
    for (int b = 0; b < kBuses; ++b) c.buses.push_back("test:" + kNames[b]);
    c.open_bus = [this](const std::string& endpoint, std::string* error) -> std::optional<CanTransport> {
      for (int b = 0; b < kBuses; ++b) {
        if (endpoint != "test:" + kNames[b]) continue;
        if (!robot_end[b]) break;
        std::optional<CanTransport> end = std::move(robot_end[b]);
        robot_end[b].reset();
        return end;
      }
      *error = "no test socket for '" + endpoint + "'";
      return std::nullopt;
    };
    c.now = [this] { return now(); };
    c.startup_timeout = 0.2;
    return c;
  }

  double now() const { return 1000.0 + tick * 1e-3; }

  void write(int bus, const CanFrame& frame) {
    if (!peer[bus]) return;  // hung up by the test
    EXPECT_EQ(peer[bus]->write(frame), can::IoStatus::kOk);
  }
  template <typename Message>
  void send(int bus, const Message& message) {
    CanFrame frame;
    ASSERT_TRUE(can::encode(message, &frame).ok());
    if (!muted.count(can::standardId(frame))) write(bus, frame);
  }

  static int busOfBoard(int board) { return 1 + board / 2; }
  static std::vector<int> nodes() {
    std::vector<int> n{can::kPalmNode};
    for (int b = 0; b < 6; ++b) n.push_back(can::valveBoardNode(b));
    for (int b = 0; b < 6; ++b) n.push_back(can::sensorBoardNode(b));
    return n;
  }
  static int busOfNode(int node) { return node == can::kPalmNode ? 0 : busOfBoard(node & 0x07); }

  void heartbeats() {
    for (int node : nodes()) {
      can::HeartbeatFrame h;
      h.node = static_cast<std::uint8_t>(node);
      h.version = version[node];
      h.state = state[node];
      h.flags = flags[node];
      h.seq = seq[0x700 + node]++;
      send(busOfNode(node), h);
    }
  }
  // Joint groups (bit g: joints 4g..4g+3; arm_hand has 28: groups 0..6), one palm sample.
  void joints(std::uint32_t groups = 0x7F, bool new_sample = true) {
    if (new_sample) ++joint_seq;
    for (std::uint8_t g = 0; g < 7; ++g) {
      if (!(groups & (1u << g))) continue;
      can::JointAnglesFrame f;
      f.first_joint = static_cast<std::uint8_t>(4 * g);
      for (int k = 0; k < 4; ++k) f.angles[k] = joint[4 * g + k];
      f.seq = joint_seq;
      send(0, f);
    }
  }
  void touches() {
    ++touch_seq;
    for (std::uint8_t g = 0; g < 2; ++g) {
      can::TouchFrame f;
      f.first_sensor = static_cast<std::uint8_t>(4 * g);
      for (int k = 0; k < 4; ++k) f.forces[k] = touch[4 * g + k];
      f.seq = touch_seq;
      send(0, f);
    }
  }
  // Sensor boards (bit b): pressures and lengths of channels 0..7, and the supply (board 0).
  void boards(std::uint32_t which = 0x3F) {
    for (std::uint8_t b = 0; b < 6; ++b) {
      if (!(which & (1u << b))) continue;
      const std::uint8_t s = ++board_seq[b];
      for (std::uint8_t g = 0; g < 2; ++g) {
        can::SensorFrame p, l;
        p.board = l.board = b;
        p.kind = can::SensorKind::kPressure;
        l.kind = can::SensorKind::kLength;
        p.first_channel = l.first_channel = static_cast<std::uint8_t>(4 * g);
        for (int k = 0; k < 4; ++k) {
          p.values[k] = pressure[b][4 * g + k];
          l.values[k] = length[b][4 * g + k];
        }
        p.seq = l.seq = s;
        send(busOfBoard(b), p);
        send(busOfBoard(b), l);
      }
      if (b == 0) send(1, can::SupplyFrame{0, supply, s});
    }
  }
  void sample() {
    joints();
    touches();
    boards();
  }

  // Everything the robot sent since the last drain, stamped with the test clock.
  void drain() {
    CanFrame frames[64];
    for (int b = 0; b < kBuses; ++b) {
      if (!peer[b]) continue;
      for (;;) {
        const can::ReadResult r = peer[b]->read(frames, 64, std::chrono::nanoseconds(0));
        for (std::size_t k = 0; k < r.count; ++k) received.push_back({b, now(), frames[k]});
        if (r.count < 64) break;
      }
    }
  }

  // `seconds` of 1 ms robot steps with the boards streaming on their schedule (joints every
  // 2 ms, touch and sensor boards every 4 ms, heartbeats every 100 ms). `each` runs before
  // every step (e.g. a controller).
  template <typename Each>
  void run(Robot& robot, double seconds, Each each) {
    const int steps = static_cast<int>(std::lround(seconds * 1000));
    for (int k = 0; k < steps; ++k) {
      ++tick;
      if (tick % 2 == 0) joints();
      if (tick % 4 == 0) {
        touches();
        boards();
      }
      if (tick % 100 == 0) heartbeats();
      each();
      robot.step();
      drain();
    }
  }
  void run(Robot& robot, double seconds) {
    run(robot, seconds, [] {});
  }

  std::vector<Received> withId(std::uint32_t id) const {
    std::vector<Received> out;
    for (const auto& r : received)
      if (r.id() == id) out.push_back(r);
    return out;
  }
  std::vector<Received> ofType(FrameType type) const {
    std::vector<Received> out;
    for (const auto& r : received)
      if (can::frameType(r.id()) == type) out.push_back(r);
    return out;
  }
  // The host's e-stop frames with this action (and cause, if given) on each bus.
  std::array<int, kBuses> estops(can::EstopAction action, std::optional<can::EstopCause> cause = {}) const {
    std::array<int, kBuses> count{};
    for (const auto& r : withId(can::kEstopIdBase + can::kHostNode)) {
      can::EstopFrame e;
      EXPECT_EQ(can::decode(r.frame, &e), can::DecodeError::kNone);
      if (e.action == action && (!cause || e.cause == *cause)) ++count[r.bus];
    }
    return count;
  }

  static inline const std::string kNames[kBuses] = {"palm", "act0", "act1", "act2"};
  std::array<std::optional<CanTransport>, kBuses> robot_end, peer;
  long tick = 0;
  std::array<double, 32> joint{}, touch{};
  std::array<std::array<double, 8>, 6> pressure{}, length{};
  double supply = 600e3;
  std::array<can::NodeState, 64> state{};
  std::array<std::uint8_t, 64> flags{}, version{};
  std::array<std::uint8_t, 0x800> seq{};
  std::uint8_t joint_seq = 0, touch_seq = 0;
  std::array<std::uint8_t, 6> board_seq{};
  std::set<std::uint32_t> muted;  // identifiers the boards do not send
  std::vector<Received> received;
};

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

std::string diagnostic(const Robot& robot, const std::string& key) {
  DiagnosticValues values;
  robot.addDiagnostics(&values);
  for (const auto& [k, v] : values)
    if (k == key) return v;
  return "(no " + key + ")";
}

std::int16_t rawChannel(const CanFrame& f, int k) {
  return static_cast<std::int16_t>(f.data[1 + 2 * k] | (f.data[2 + 2 * k] << 8));
}

class CanRobotTest : public ::testing::Test {
 protected:
  void start(CanRobotConfig config) {
    boards_.heartbeats();
    boards_.sample();
    robot_ = std::make_unique<CanRobot>(std::move(config));
    boards_.drain();
  }
  void start() { start(boards_.config()); }
  std::string startError(CanRobotConfig config) {
    boards_.heartbeats();
    boards_.sample();
    return errorOf([&] { CanRobot robot(std::move(config)); });
  }
  int joint(const std::string& name) const {
    const auto& names = robot_->jointNames();
    return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
  }
  int cylinder(const std::string& name) const {
    const auto& names = robot_->cylinderNames();
    return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
  }
  CommandResult command(const std::vector<std::uint16_t>& cylinders, const std::vector<double>& volts) {
    return robot_->applyValves(robot_->checkValves({}, cylinders, volts));
  }
  void run(double seconds) { boards_.run(*robot_, seconds); }
  template <typename Each>
  void run(double seconds, Each each) {
    boards_.run(*robot_, seconds, each);
  }

  FakeBoards boards_;  // outlives the robot, whose config refers to it
  std::unique_ptr<CanRobot> robot_;
};

// ---------------------------------------------------------------------------- start-up

TEST_F(CanRobotTest, StartsReleasedAndSaysSoOnEveryBus) {
  start();
  EXPECT_FALSE(robot_->safety().safe_state);
  EXPECT_FALSE(robot_->safety().watchdog_armed);
  EXPECT_EQ(robot_->neverCommanded(), 48u);
  EXPECT_EQ(robot_->jointNames().size(), 28u);
  EXPECT_EQ(robot_->cylinderNames().size(), 48u);
  EXPECT_EQ(robot_->touchNames().size(), 5u);
  EXPECT_EQ(robot_->mode(), ActuationMode::kPneumatic);
  EXPECT_TRUE(robot_->drivenByInput());
  EXPECT_FALSE(robot_->simulated());
  const auto releases = boards_.estops(can::EstopAction::kRelease, can::EstopCause::kNone);
  for (int b = 0; b < kBuses; ++b) {
    EXPECT_EQ(releases[b], 1) << "bus " << b;
    // A host heartbeat precedes the release (a board obeys it only with one in the last 300 ms).
    std::size_t heartbeat = boards_.received.size(), release = 0;
    for (std::size_t k = 0; k < boards_.received.size(); ++k) {
      const Received& r = boards_.received[k];
      if (r.bus != b) continue;
      if (r.id() == can::kHeartbeatIdBase && heartbeat == boards_.received.size()) heartbeat = k;
      if (r.id() == can::kEstopIdBase) release = k;
    }
    EXPECT_LT(heartbeat, release) << "bus " << b;
  }
  EXPECT_TRUE(boards_.ofType(FrameType::kValveCommand).empty());  // nothing commanded yet
  EXPECT_EQ(diagnostic(*robot_, "start-up release"), "sent");
  EXPECT_EQ(diagnostic(*robot_, "bus act1"), "test:act1: ok");
  // The start-up sample is in already.
  EXPECT_NEAR(robot_->sensed().joint_position[0], 0.1, 0.5e-3);
  EXPECT_NEAR(robot_->sensed().supply_pressure, 600e3, 50);
}

TEST_F(CanRobotTest, StartInSafeStateSendsNoReleaseUntilAsked) {
  CanRobotConfig c = boards_.config();
  c.start_in_safe_state = true;
  start(std::move(c));
  EXPECT_TRUE(robot_->safety().safe_state);
  EXPECT_TRUE(robot_->safety().estop_latched);
  EXPECT_EQ(boards_.estops(can::EstopAction::kRelease), (std::array<int, kBuses>{}));
  EXPECT_EQ(boards_.estops(can::EstopAction::kEngage, can::EstopCause::kOperator),
            (std::array<int, kBuses>{1, 1, 1, 1}));
  EXPECT_EQ(diagnostic(*robot_, "start-up release"), "not sent (start_in_safe_state)");
  std::string why;
  ASSERT_TRUE(robot_->release(&why)) << why;
  EXPECT_EQ(why, "released");
  EXPECT_EQ(boards_.estops(can::EstopAction::kRelease), (std::array<int, kBuses>{}));  // not drained yet
  boards_.drain();
  EXPECT_EQ(boards_.estops(can::EstopAction::kRelease), (std::array<int, kBuses>{1, 1, 1, 1}));
}

TEST_F(CanRobotTest, AMissingNodeIsNamedAfterTheStartupTimeout) {
  boards_.muted.insert(can::kHeartbeatIdBase + can::valveBoardNode(3));
  const auto start_time = std::chrono::steady_clock::now();
  const std::string error = startError(boards_.config());  // the test clock stands still: real time bounds it
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_time).count();
  EXPECT_TRUE(contains(error, "CAN start-up: within 0.2 s: no heartbeat from valve board 3 on bus 'act1' (test:act1)"))
      << error;
  EXPECT_EQ(error.find('\n'), std::string::npos);
  EXPECT_GE(waited, 0.19);
  EXPECT_LT(waited, 1.0);
}

TEST_F(CanRobotTest, AStreamThatNeverStartsIsNamed) {
  boards_.muted.insert(can::kPressureIdBase + 8 * 3 + 1);
  const std::string error = startError(boards_.config());
  EXPECT_TRUE(contains(error, "streams never heard: pressure stream of sensor board 3 (0x159, channels 4..7)"))
      << error;
}

TEST_F(CanRobotTest, ANodeOfAnotherProtocolVersionIsRefused) {
  boards_.version[can::kPalmNode] = 2;
  const std::string error = startError(boards_.config());
  EXPECT_EQ(error, "CAN start-up: palm MCU on bus 'palm' speaks protocol version 2, this driver version 1: refused");
}

TEST_F(CanRobotTest, ABusThatCannotBeOpenedIsNamedWithTheReason) {
  CanRobotConfig c = boards_.config();
  c.buses[3] = "test:nothing";
  EXPECT_EQ(startError(std::move(c)), "cannot open CAN bus 'act2' (test:nothing): no test socket for 'test:nothing'");
  // The real opener: an emulator path where nobody listens.
  c = boards_.config();
  c.open_bus = nullptr;
  c.buses = {"unix:/tmp/adroit_no_such_emulator_palm", "unix:/x1", "unix:/x2", "unix:/x3"};
  const std::string error = errorOf([&] { CanRobot robot(std::move(c)); });
  EXPECT_TRUE(contains(error, "cannot open CAN bus 'palm' (unix:/tmp/adroit_no_such_emulator_palm): cannot connect"))
      << error;
  EXPECT_TRUE(contains(error, "is the emulator running?")) << error;
}

TEST_F(CanRobotTest, BadConfigurationGivesOneLineNamingTheParameter) {
  const auto expectError = [&](CanRobotConfig c, const std::string& start) {
    const std::string error = errorOf([&] { CanRobot robot(std::move(c)); });
    EXPECT_EQ(error.rfind(start, 0), 0u) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  };
  CanRobotConfig c = boards_.config();
  c.control_period = 0.05;
  expectError(c, "~control_period must be in [0.004, 0.01] s");
  c = boards_.config();
  c.watchdog_timeout = 0.5;
  expectError(c, "~watchdog_timeout must be in [0.01, 0.2] s, got 0.5");
  c = boards_.config();
  c.joint_velocity_cutoff = 300;
  expectError(c, "~joint_velocity_cutoff must be in (0, 250] Hz");
  c = boards_.config();
  c.buses.pop_back();
  expectError(c, "~buses has 3 endpoints, the mapping 4 buses (palm, act0, act1, act2)");
  c = boards_.config();
  c.buses[1] = "";
  expectError(c, "~buses: endpoint 1 is empty");
  c = boards_.config();
  c.model_path = "";
  expectError(c, "~scene (or ~model_file) must name a model");
  c = boards_.config();
  c.calibration = can::identityCalibration(28, 48);
  c.calibration->joint[6].gain = 3;
  expectError(c, "calibration (in memory): joints.FFJ3.gain must be in [0.5, 2], got 3");
  c = boards_.config();
  c.mapping = can::Mapping{};
  expectError(c, "CAN mapping: needs 1 to 16 buses, has 0");
}

// ---------------------------------------------------------------------------- sensing

TEST_F(CanRobotTest, JointAnglesAreCalibratedAndFreshOnlyAsAWholeSample) {
  CanRobotConfig c = boards_.config();
  c.calibration = can::identityCalibration(28, 48);
  c.calibration->joint[6] = {1.05, 0.02};  // FFJ3
  start(std::move(c));
  const int ffj3 = joint("FFJ3"), arj0 = joint("ARJ0");
  ASSERT_EQ(ffj3, 6);
  EXPECT_EQ(robot_->mapping().joint[ffj3], 2);   // hand joints from 0 in model order
  EXPECT_EQ(robot_->mapping().joint[arj0], 27);  // arm joints at 24..27 (group 6)
  robot_->takeFresh();
  boards_.joint[2] = 0.3;
  boards_.joint[27] = -1.25;
  boards_.joints(0x3F);  // groups 0..5 of a new sample: not complete
  robot_->step();
  EXPECT_EQ(robot_->takeFresh() & Robot::kJoints, 0u);
  EXPECT_NEAR(robot_->sensed().joint_position[ffj3], 1.05 * 0.1 + 0.02, 1e-3);  // the old sample still
  boards_.joints(0x40, false);                                                  // group 6 of the same sample
  robot_->step();
  EXPECT_EQ(robot_->takeFresh(), static_cast<unsigned>(Robot::kJoints));
  EXPECT_EQ(robot_->takeFresh(), 0u);
  const double lsb = can::kJointAngleLsb;
  EXPECT_NEAR(robot_->sensed().joint_position[ffj3], 1.05 * 0.3 + 0.02, 1.05 * lsb / 2 + 1e-12);
  EXPECT_NEAR(robot_->sensed().joint_position[arj0], -1.25, lsb / 2 + 1e-12);
  EXPECT_EQ(robot_->sensed().joint_effort[ffj3], 0.0);
  // A sample whose groups carry two sequence numbers is not a sample.
  boards_.joint[2] = 0.5;
  boards_.joints(0x3F);
  boards_.joints(0x40);
  robot_->step();
  EXPECT_EQ(robot_->takeFresh() & Robot::kJoints, 0u);
}

TEST_F(CanRobotTest, CylinderSignalsAreCalibratedWithTensionFromPressure) {
  CanRobotConfig c = boards_.config();
  c.calibration = can::identityCalibration(28, 48);
  c.calibration->pressure[5] = {1.02, 1000};
  c.calibration->length[5] = {1.0, 0.001};
  c.calibration->supply = {0.99, 0};
  start(std::move(c));
  boards_.pressure[0][5] = 400e3;
  boards_.length[0][5] = 0.05;
  boards_.pressure[2][3] = 90e3;  // below atmosphere: no tension (a tendon cannot push)
  boards_.touch[1] = 2.5;
  run(0.008);
  const Signals& s = robot_->sensed();
  const double p = 1.02 * 400e3 + 1000;
  EXPECT_NEAR(s.pressure[5], p, 1.02 * 50 + 1e-6);
  EXPECT_NEAR(s.tension[5], (s.pressure[5] - kAtm) * robot_->cylinders()[5].bore_area, 1e-9);
  EXPECT_GT(s.tension[5], 0);
  EXPECT_NEAR(s.length[5], 0.051, 5e-6 + 1e-12);
  EXPECT_NEAR(s.pressure[2 * 8 + 3], 90e3, 50);
  EXPECT_EQ(s.tension[2 * 8 + 3], 0.0);
  EXPECT_NEAR(s.supply_pressure, 0.99 * 600e3, 0.99 * 50);
  EXPECT_NEAR(s.touch[1], 2.5, 0.5e-3);
  EXPECT_TRUE(robot_->sensedIsFinite());
  // kActuators once every sensor board has delivered a whole sample.
  robot_->takeFresh();
  boards_.boards(0x1F);
  robot_->step();
  EXPECT_EQ(robot_->takeFresh() & Robot::kActuators, 0u);
  boards_.boards(0x20);
  robot_->step();
  EXPECT_EQ(robot_->takeFresh() & Robot::kActuators, static_cast<unsigned>(Robot::kActuators));
  boards_.touches();
  robot_->step();
  EXPECT_EQ(robot_->takeFresh(), static_cast<unsigned>(Robot::kTouch));
}

TEST_F(CanRobotTest, VelocityAndLengthRateFollowARamp) {
  start();
  const int ffj3 = joint("FFJ3");
  // Whole resolution steps per sample, so the quantisation adds nothing.
  const double joint_step = 2 * can::kJointAngleLsb;  // per 2 ms: 0.488 rad/s
  double q = 0.1, l = 0.02;
  boards_.joint[2] = q;
  run(0.2, [&] {
    if (boards_.tick % 2 == 1) boards_.joint[2] = (q += joint_step);
    if (boards_.tick % 4 == 3) boards_.length[0][5] = (l += 0.004 * 0.1);  // 0.1 m/s at 250 Hz
  });
  EXPECT_NEAR(robot_->sensed().joint_velocity[ffj3], joint_step / 0.002, 1e-3);
  EXPECT_NEAR(robot_->sensed().length_rate[5], 0.1, 0.005);
  EXPECT_NEAR(robot_->sensed().joint_velocity[0], 0.0, 1e-9);
}

TEST_F(CanRobotTest, DataHoldsTheSensedJointsForKinematics) {
  start();
  boards_.joint[2] = 0.7;
  run(0.02);
  const mjModel* m = robot_->model();
  const int id = mj_name2id(m, mjOBJ_JOINT, "FFJ3");
  EXPECT_EQ(robot_->data()->qpos[m->jnt_qposadr[id]], robot_->sensed().joint_position[joint("FFJ3")]);
  EXPECT_NEAR(robot_->data()->time, robot_->clock(), 0.0105);
}

TEST_F(CanRobotTest, GarbageFramesAreCountedAndNeverChangeSensed) {
  start();
  run(0.01);
  const Signals before = robot_->sensed();
  CanFrame f;
  ASSERT_TRUE(can::encode(can::JointAnglesFrame{4, {1, 1, 1, 1}, 200}, &f).ok());
  CanFrame short_frame = f;
  short_frame.dlc = 5;
  boards_.write(0, short_frame);                       // wrong length
  boards_.write(0, can::makeFrame(0x3FF, f.data, 8));  // unassigned identifier
  CanFrame out_of_range = f;
  out_of_range.data[1] = 0x58;  // field 0 = 7000 > 6434
  out_of_range.data[2] = static_cast<std::uint8_t>((f.data[2] & 0xC0) | 0x1B);
  boards_.write(0, out_of_range);
  CanFrame extended = f;
  extended.id |= can::kEffFlag;
  boards_.write(0, extended);  // not a standard data frame
  ASSERT_TRUE(can::encode(can::SensorFrame{0, can::SensorKind::kPressure, 0, {2e5, 2e5, 2e5, 2e5}, 77}, &f).ok());
  f.data[1] = 0xE0;  // field 0 = 13024 > 12000
  f.data[2] = static_cast<std::uint8_t>((f.data[2] & 0xC0) | 0x32);
  boards_.write(1, f);
  can::HeartbeatFrame h{can::kPalmNode, 1, can::NodeState::kOperational, 0, 9};
  ASSERT_TRUE(can::encode(h, &f).ok());
  f.data[3] = 0x80;  // a reserved flag
  boards_.write(0, f);
  robot_->step();  // the clock stands still: nothing else arrives
  const Signals& after = robot_->sensed();
  EXPECT_EQ(after.joint_position, before.joint_position);
  EXPECT_EQ(after.pressure, before.pressure);
  EXPECT_EQ(after.supply_pressure, before.supply_pressure);
  EXPECT_FALSE(robot_->safety().safe_state);
  EXPECT_EQ(diagnostic(*robot_, "bus palm decode errors"),
            "not a standard data frame 1, unknown identifier 1, wrong length 1, reserved bits set 1, "
            "raw value out of range 1");
  EXPECT_EQ(diagnostic(*robot_, "bus act0 decode errors"), "raw value out of range 1");
}

TEST_F(CanRobotTest, NoReadingIsNeverPublishedAndLatchesAFault) {
  start();
  run(0.01);
  const int ffj3 = joint("FFJ3");
  const double last = robot_->sensed().joint_position[ffj3];
  boards_.joint[2] = std::nan("");  // the palm sends "no reading"
  run(0.004);
  EXPECT_TRUE(robot_->sensedIsFinite());
  EXPECT_EQ(robot_->sensed().joint_position[ffj3], last);
  ASSERT_TRUE(robot_->safety().fault_latched);
  const SafetyEvent& e = robot_->safetyEvents().fault;
  EXPECT_EQ(e.fault, FaultSource::kStream);
  EXPECT_EQ(e.index, 0x100);
  EXPECT_TRUE(contains(robot_->describe(e),
                       "fault: joint stream of the palm (0x100, joints 0..3): no reading for "
                       "joint 'FFJ3'"))
      << robot_->describe(e);
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "still reports no reading")) << why;
  boards_.joint[2] = 0.2;
  run(0.004);
  EXPECT_TRUE(robot_->release(&why)) << why;
  // A pressure channel likewise, naming the cylinder.
  boards_.pressure[1][2] = std::nan("");
  run(0.004);
  ASSERT_TRUE(robot_->safety().fault_latched);
  EXPECT_EQ(robot_->safetyEvents().fault.cylinder, 10);
  EXPECT_TRUE(contains(robot_->safety().fault, "no reading for cylinder '" + robot_->cylinderNames()[10] + "'"))
      << robot_->safety().fault;
  EXPECT_TRUE(robot_->sensedIsFinite());
}

// ---------------------------------------------------------------------------- valves

TEST_F(CanRobotTest, AValveCommandGoesOutAtOnceAndEveryCycle) {
  start();
  run(0.01);
  boards_.received.clear();
  const CommandResult r = command({0, 1}, {2.5, -1.0});
  ASSERT_TRUE(r.applied) << r.error;
  boards_.drain();  // without a step: applyValves sent it
  auto frames = boards_.withId(can::kValveCommandIdBase + 0);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].bus, 1);
  EXPECT_EQ(frames[0].frame.dlc, 7);
  EXPECT_EQ(rawChannel(frames[0].frame, 0), 16384);                // 2.5 V
  EXPECT_EQ(rawChannel(frames[0].frame, 1), -6553);                // -1 V
  EXPECT_EQ(rawChannel(frames[0].frame, 2), -32767);               // never commanded: exhaust
  EXPECT_EQ(boards_.ofType(FrameType::kValveCommand).size(), 1u);  // no other group
  EXPECT_NEAR(robot_->appliedCommand()[0], 2.5, kVoltLsb);
  EXPECT_EQ(robot_->appliedCommand()[2], -5.0);
  // Without new commands the 200 Hz cycle repeats it once it has not gone out for a whole
  // period (the board's watchdog needs it), one sequence number more each time.
  run(0.04);
  frames = boards_.withId(can::kValveCommandIdBase + 0);
  ASSERT_GE(frames.size(), 5u);
  EXPECT_LE(frames.size(), 9u);
  for (std::size_t k = 1; k < frames.size(); ++k) {
    EXPECT_EQ(frames[k].frame.data[0], static_cast<std::uint8_t>(frames[0].frame.data[0] + k));
    const double interval = frames[k].time - frames[k - 1].time;
    EXPECT_GE(interval, 0.005 - 1e-6);
    EXPECT_LE(interval, 0.010 + 1e-6);
    EXPECT_EQ(std::memcmp(frames[k].frame.data + 1, frames[0].frame.data + 1, 6), 0);
  }
  EXPECT_EQ(boards_.ofType(FrameType::kValveCommand).size(), frames.size());
}

TEST_F(CanRobotTest, AGroupGoesOutAtMostEveryMinimumInterval) {
  start();
  run(0.01);
  boards_.received.clear();
  ASSERT_TRUE(command({25}, {1.0}).applied);  // board 3 channel 1: group 0 of board 3 (0x098) on act1
  ASSERT_TRUE(command({25}, {2.0}).applied);
  boards_.drain();
  auto frames = boards_.withId(can::kValveCommandIdBase + 8 * 3);
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].bus, 2);
  EXPECT_EQ(rawChannel(frames[0].frame, 1), 6553);
  const double first = frames[0].time;
  run(0.003);
  frames = boards_.withId(can::kValveCommandIdBase + 8 * 3);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(rawChannel(frames[1].frame, 1), 13107);  // 2 V, at the first step kMinGroupInterval later
  EXPECT_NEAR(frames[1].time - first, kMinGroupInterval, 1e-9);
}

TEST_F(CanRobotTest, ACommandAtTheSensorRateIsNeverHeldBackByTheCycle) {
  start();
  run(0.01);
  boards_.received.clear();
  // A controller answering every 250 Hz sample: each command goes out in the step it came in.
  std::vector<std::pair<double, double>> sent;  // (time, volts)
  run(0.1, [&] {
    if (boards_.tick % 4 != 0) return;
    const double volts = 0.5 + 0.01 * static_cast<double>(sent.size());
    ASSERT_TRUE(command({0}, {volts}).applied);
    sent.emplace_back(boards_.now(), volts);
  });
  // Only the commands: the cycle found the group sent within its period every time.
  const auto frames = boards_.withId(can::kValveCommandIdBase + 0);
  ASSERT_EQ(frames.size(), sent.size());
  for (std::size_t k = 0; k < sent.size(); ++k) {
    EXPECT_NEAR(frames[k].time, sent[k].first, 1e-9) << "command " << k;
    EXPECT_NEAR(rawChannel(frames[k].frame, 0) * 5.0 / 32767, sent[k].second, kVoltLsb) << "command " << k;
  }
}

TEST_F(CanRobotTest, AReleaseOutsideTheSafeStateKeepsCommanding) {
  start();
  run(0.01);
  ASSERT_TRUE(command({0}, {1.0}).applied);
  boards_.received.clear();
  std::string why;
  ASSERT_TRUE(robot_->release(&why));
  EXPECT_EQ(why, "not in the safe state");
  EXPECT_TRUE(robot_->safety().watchdog_armed);
  EXPECT_TRUE(robot_->everCommanded(0));
  run(0.02);  // the board keeps getting its group, or its own watchdog would trip
  EXPECT_GE(boards_.withId(can::kValveCommandIdBase).size(), 4u);
  EXPECT_EQ(boards_.estops(can::EstopAction::kRelease), (std::array<int, kBuses>{1, 1, 1, 1}));
  run(0.04);
  EXPECT_TRUE(robot_->safety().watchdog_latched);  // still watched
}

TEST_F(CanRobotTest, ForceCommandsAreTheWrongMode) {
  start();
  const CheckedCommand checked = robot_->checkForces({}, {0}, {5.0});
  EXPECT_EQ(checked.verdict, CommandVerdict::kBadAddressing);
  const CommandResult r = robot_->applyForces(checked);
  EXPECT_FALSE(r.applied);
  EXPECT_TRUE(contains(r.error, "pneumatic")) << r.error;
  EXPECT_EQ(robot_->counters().rejected_wrong_mode, 1u);
  const CommandResult bad = command({0}, {7.0});
  EXPECT_EQ(bad.verdict, CommandVerdict::kOutOfRange);
  EXPECT_EQ(robot_->counters().rejected_range, 1u);
}

// ---------------------------------------------------------------------------- safety

TEST_F(CanRobotTest, TheWatchdogLatchesWithinAStepAndStopsTheValves) {
  start();
  run(0.01);
  ASSERT_TRUE(command({0}, {1.0}).applied);
  const double commanded = robot_->clock();
  EXPECT_TRUE(robot_->safety().watchdog_armed);
  while (!robot_->safety().safe_state && robot_->clock() < commanded + 0.1) run(0.001);
  ASSERT_TRUE(robot_->safety().watchdog_latched);
  const double late = robot_->safetyEvents().watchdog.clock - commanded;
  EXPECT_GE(late, 0.05 - 1e-9);
  EXPECT_LE(late, 0.051 + 1e-9);
  EXPECT_NEAR(robot_->takeCommandAgeMax(), late, 1e-9);  // the margin reached: all of it
  EXPECT_EQ(robot_->safetyEvents().watchdog.cylinder, 0);
  EXPECT_EQ(robot_->counters().watchdog_trips, 1u);
  EXPECT_EQ(
      robot_->describe(robot_->safetyEvents().watchdog).rfind("watchdog: 'A_ARJ3_flex' not commanded for 0.05 s", 0),
      0u);
  EXPECT_EQ(boards_.estops(can::EstopAction::kEngage, can::EstopCause::kWatchdog),
            (std::array<int, kBuses>{1, 1, 1, 1}));
  EXPECT_EQ(robot_->appliedCommand()[0], -5.0);
  // Latched: no valve frame any more, heartbeats go on, the e-stop is repeated every 100 ms.
  boards_.received.clear();
  run(0.25);
  EXPECT_TRUE(boards_.ofType(FrameType::kValveCommand).empty());
  const std::size_t heartbeats = boards_.withId(can::kHeartbeatIdBase).size();  // 2 or 3 per bus
  EXPECT_GE(heartbeats, 4u * 2);
  EXPECT_LE(heartbeats, 4u * 3);
  const auto repeats = boards_.estops(can::EstopAction::kEngage);
  for (int b = 0; b < kBuses; ++b) EXPECT_EQ(repeats[b], 2) << "bus " << b;
  const CommandResult ignored = command({0}, {1.0});
  EXPECT_FALSE(ignored.applied);
  EXPECT_EQ(robot_->counters().ignored_while_safe, 1u);
  // Release: the watchdog is unarmed again until the next command.
  std::string why;
  ASSERT_TRUE(robot_->release(&why)) << why;
  EXPECT_FALSE(robot_->safety().watchdog_armed);
  EXPECT_EQ(robot_->neverCommanded(), 48u);
  run(0.1);
  EXPECT_FALSE(robot_->safety().safe_state);
}

TEST_F(CanRobotTest, ASilentStreamIsAFaultNamingIt) {
  start();
  run(0.02);
  boards_.muted.insert(can::kPressureIdBase + 8 * 2);  // sensor board 2, channels 0..3
  const double muted = robot_->clock();
  run(0.02);
  ASSERT_TRUE(robot_->safety().fault_latched);
  const SafetyEvent& e = robot_->safetyEvents().fault;
  EXPECT_EQ(e.fault, FaultSource::kStream);
  EXPECT_EQ(e.index, 0x150);
  EXPECT_LE(e.clock - muted, 0.012 + 0.004 + 0.001 + 1e-9);  // 3 periods after the last frame, in a step
  const std::string text = robot_->describe(e);
  EXPECT_EQ(
      text.rfind("fault: pressure stream of sensor board 2 silent for 0.013 s (0x150, channels 0..3, bus 'act1')", 0),
      0u)
      << text;
  EXPECT_EQ(boards_.estops(can::EstopAction::kEngage, can::EstopCause::kFault), (std::array<int, kBuses>{1, 1, 1, 1}));
  EXPECT_TRUE(robot_->safety().fault_persists);
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "the pressure stream of sensor board 2 (0x150, channels 0..3) is silent")) << why;
  boards_.muted.clear();
  run(0.01);
  EXPECT_FALSE(robot_->safety().fault_persists);
  EXPECT_TRUE(robot_->release(&why)) << why;
  EXPECT_FALSE(robot_->safety().safe_state);
}

TEST_F(CanRobotTest, SilentPeriodsSetsHowLongAStreamMayPause) {
  CanRobotConfig c = boards_.config();
  c.silent_periods = 10;  // boards played on the same machine (hardware.launch emulate:=true)
  start(c);
  run(0.02);
  boards_.muted.insert(can::kJointAnglesIdBase);  // the palm's joints 0..3, 2 ms period
  const double muted = robot_->clock();
  run(0.016);  // 8 periods: a pause, not yet a fault
  EXPECT_FALSE(robot_->safety().fault_latched);
  run(0.01);
  ASSERT_TRUE(robot_->safety().fault_latched);
  const SafetyEvent& e = robot_->safetyEvents().fault;
  EXPECT_EQ(e.index, static_cast<int>(can::kJointAnglesIdBase));
  EXPECT_GE(e.clock - muted, 0.018);  // 10 periods after the last frame
  EXPECT_LE(e.clock - muted, 0.020 + 0.002 + 0.001 + 1e-9);
  for (int bad : {2, 21}) {
    c.silent_periods = bad;
    EXPECT_NE(validate(c).find("~silent_periods"), std::string::npos) << bad;
  }
}

TEST_F(CanRobotTest, AStallOfTheDriverIsNotSilenceOfTheBuses) {
  start();
  run(0.02);
  // The whole machine stalls for 20 ms (a virtual machine whose emulated boards stall with the
  // driver): nothing is sent, nothing is stepped. Without the discount every stream would be
  // 3 periods silent at the next step.
  boards_.tick += 20;
  run(0.01);
  EXPECT_FALSE(robot_->safety().safe_state) << robot_->describe(robot_->safetyEvents().last);
  // A stream that stays silent while the driver runs is still found.
  boards_.muted.insert(can::kPressureIdBase + 8 * 2);
  run(0.02);
  EXPECT_TRUE(robot_->safety().fault_latched);
  EXPECT_EQ(robot_->safetyEvents().fault.index, 0x150);
}

TEST_F(CanRobotTest, AMissingHeartbeatIsAFault) {
  start();
  boards_.muted.insert(can::kHeartbeatIdBase + can::valveBoardNode(3));
  run(0.35);
  ASSERT_TRUE(robot_->safety().fault_latched);
  const SafetyEvent& e = robot_->safetyEvents().fault;
  EXPECT_EQ(e.fault, FaultSource::kHeartbeat);
  EXPECT_EQ(e.index, can::valveBoardNode(3));
  EXPECT_TRUE(contains(robot_->describe(e), "fault: heartbeat of valve board 3 (bus 'act1') missing for 0.3"))
      << robot_->describe(e);
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "no heartbeat from valve board 3")) << why;
  boards_.muted.clear();
  run(0.1);
  EXPECT_TRUE(robot_->release(&why)) << why;
}

TEST_F(CanRobotTest, AHeartbeatOfAnotherVersionAfterStartIsAFault) {
  start();
  run(0.01);
  boards_.version[can::sensorBoardNode(4)] = 3;
  boards_.heartbeats();
  robot_->step();
  ASSERT_TRUE(robot_->safety().fault_latched);
  EXPECT_EQ(robot_->safetyEvents().fault.fault, FaultSource::kHeartbeat);
  EXPECT_TRUE(contains(robot_->safety().fault, "sensor board 4 (bus 'act2') speaks protocol version 3, this driver 1"))
      << robot_->safety().fault;
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "sensor board 4 speaks protocol version 3")) << why;
}

TEST_F(CanRobotTest, ABoardFaultFrameIsAFault) {
  start();
  run(0.01);
  boards_.send(2, can::FaultFrame{can::valveBoardNode(3), can::FaultCode::kCommandTimeout, 0, 52, 0});
  robot_->step();
  ASSERT_TRUE(robot_->safety().fault_latched);
  const SafetyEvent& e = robot_->safetyEvents().fault;
  EXPECT_EQ(e.fault, FaultSource::kBoard);
  EXPECT_EQ(e.index, can::valveBoardNode(3));
  EXPECT_EQ(e.cylinder, 24);
  EXPECT_EQ(robot_->describe(e).rfind("fault: valve board 3 reported command timeout on channel 0 (52 ms), cylinder '" +
                                          robot_->cylinderNames()[24] + "'",
                                      0),
            0u)
      << robot_->describe(e);
  boards_.drain();
  EXPECT_EQ(boards_.estops(can::EstopAction::kEngage, can::EstopCause::kFault), (std::array<int, kBuses>{1, 1, 1, 1}));
  // Nothing persists: release is accepted and said on every bus.
  boards_.received.clear();
  std::string why;
  ASSERT_TRUE(robot_->release(&why)) << why;
  boards_.drain();
  EXPECT_EQ(boards_.estops(can::EstopAction::kRelease), (std::array<int, kBuses>{1, 1, 1, 1}));
}

TEST_F(CanRobotTest, AValveBoardThatStopsOnItsOwnIsAFault) {
  start();
  run(0.01);
  run(0.05, [&] {
    if (boards_.tick % 5 == 0) command({0, 1, 2}, {0.5, 0.5, 0.5});
  });
  ASSERT_FALSE(robot_->safety().safe_state);
  boards_.state[can::valveBoardNode(0)] = can::NodeState::kSafe;
  boards_.flags[can::valveBoardNode(0)] = can::kFlagWatchdog;
  boards_.heartbeats();
  robot_->step();
  ASSERT_TRUE(robot_->safety().fault_latched);
  EXPECT_EQ(robot_->safetyEvents().fault.fault, FaultSource::kBoard);
  EXPECT_TRUE(contains(robot_->describe(robot_->safetyEvents().fault),
                       "valve board 0 went safe on its own while commanded (its command watchdog tripped)"));
  // A board that is not commanded may be safe (e.g. after the release, before its first command).
  boards_.state[can::valveBoardNode(0)] = can::NodeState::kOperational;
  boards_.state[can::valveBoardNode(5)] = can::NodeState::kSafe;
  std::string why;
  run(0.1);
  ASSERT_TRUE(robot_->release(&why)) << why;
  run(0.2);
  EXPECT_FALSE(robot_->safety().safe_state);
}

TEST_F(CanRobotTest, ABoardsEstopButtonStopsEverythingUntilItIsReleased) {
  start();
  run(0.01);
  boards_.received.clear();
  boards_.send(1, can::EstopFrame{can::sensorBoardNode(1), can::EstopAction::kEngage, can::EstopCause::kButton, 0});
  boards_.flags[can::sensorBoardNode(1)] = can::kFlagEstopInput;
  robot_->step();
  ASSERT_TRUE(robot_->safety().safe_state);
  EXPECT_TRUE(robot_->safety().estop_latched);
  EXPECT_TRUE(robot_->safety().estop_input);
  EXPECT_EQ(robot_->safetyEvents().estop.index, can::sensorBoardNode(1));
  EXPECT_EQ(robot_->describe(robot_->safetyEvents().estop).rfind("e-stop from sensor board 1", 0), 0u);
  boards_.drain();
  EXPECT_EQ(boards_.estops(can::EstopAction::kEngage, can::EstopCause::kButton), (std::array<int, kBuses>{1, 1, 1, 1}));
  run(0.15);  // heartbeats: the button is still held
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "the e-stop button of sensor board 1 (bus 'act0') is held")) << why;
  boards_.flags[can::sensorBoardNode(1)] = 0;
  run(0.1);
  EXPECT_FALSE(robot_->safety().estop_input);
  EXPECT_TRUE(robot_->release(&why)) << why;
  EXPECT_FALSE(robot_->safety().safe_state);
}

TEST_F(CanRobotTest, AButtonFlagInAHeartbeatAloneLatchesTheEstop) {
  start();
  run(0.01);
  boards_.flags[can::kPalmNode] = can::kFlagEstopInput;  // its e-stop frame was lost
  boards_.heartbeats();
  robot_->step();
  ASSERT_TRUE(robot_->safety().estop_latched);
  EXPECT_EQ(robot_->safetyEvents().estop.index, can::kPalmNode);
  EXPECT_EQ(robot_->counters().estops, 1u);
  boards_.heartbeats();  // still held: no new event
  robot_->step();
  EXPECT_EQ(robot_->counters().estops, 1u);
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_EQ(why, "refused: the e-stop button of palm MCU (bus 'palm') is held");
  boards_.flags[can::kPalmNode] = 0;
  boards_.heartbeats();
  robot_->step();
  EXPECT_TRUE(robot_->release(&why)) << why;
}

TEST_F(CanRobotTest, OperatorEstopAndEstopInput) {
  start();
  run(0.01);
  boards_.received.clear();
  robot_->estop();
  boards_.drain();
  EXPECT_EQ(boards_.estops(can::EstopAction::kEngage, can::EstopCause::kOperator),
            (std::array<int, kBuses>{1, 1, 1, 1}));
  EXPECT_EQ(robot_->describe(robot_->safetyEvents().estop).rfind("e-stop (clock", 0), 0u);
  std::string why;
  ASSERT_TRUE(robot_->release(&why)) << why;
  robot_->setEstopInput(true);
  EXPECT_TRUE(robot_->safety().safe_state);
  EXPECT_TRUE(robot_->safety().estop_input);
  EXPECT_EQ(robot_->counters().estops, 2u);
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_EQ(why, "refused: the e-stop input is held");
  boards_.received.clear();
  run(0.1);  // the host's heartbeat says so
  const auto heartbeats = boards_.withId(can::kHeartbeatIdBase);
  ASSERT_FALSE(heartbeats.empty());
  can::HeartbeatFrame h;
  ASSERT_EQ(can::decode(heartbeats.back().frame, &h), can::DecodeError::kNone);
  EXPECT_EQ(h.flags, can::kFlagEstopInput);
  EXPECT_EQ(h.state, can::NodeState::kSafe);
  robot_->setEstopInput(false);
  EXPECT_TRUE(robot_->release(&why)) << why;
}

TEST_F(CanRobotTest, AHungUpBusIsAFaultUntilRecovered) {
  start();
  run(0.01);
  boards_.peer[0].reset();  // the palm's end closes
  robot_->step();
  ASSERT_TRUE(robot_->safety().fault_latched);
  const SafetyEvent& e = robot_->safetyEvents().fault;
  EXPECT_EQ(e.fault, FaultSource::kBus);
  EXPECT_EQ(e.index, 0);
  EXPECT_EQ(robot_->describe(e).rfind("fault: bus 'palm' (test:palm) hung up", 0), 0u) << robot_->describe(e);
  EXPECT_EQ(diagnostic(*robot_, "bus palm"), "test:palm: hung up");
  // waitForInput leaves the dead socket out (it would poll readable for ever).
  const auto before = std::chrono::steady_clock::now();
  EXPECT_FALSE(robot_->waitForInput(0.02));
  EXPECT_GE(std::chrono::steady_clock::now() - before, std::chrono::milliseconds(15));
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "bus 'palm' (test:palm) is hung up: call recover")) << why;
  EXPECT_FALSE(robot_->recover(&why));  // nothing to connect to yet
  EXPECT_EQ(why, "cannot reopen bus 'palm' (test:palm): no test socket for 'test:palm'");
  boards_.connect(0);
  ASSERT_TRUE(robot_->recover(&why)) << why;
  EXPECT_EQ(why, "reopened bus 'palm' (test:palm) (the safe state stays latched until release)");
  EXPECT_TRUE(robot_->safety().fault_latched);
  boards_.drain();
  EXPECT_FALSE(boards_.withId(can::kHeartbeatIdBase).empty());
  boards_.heartbeats();
  run(0.02);
  EXPECT_TRUE(robot_->release(&why)) << why;
  EXPECT_EQ(diagnostic(*robot_, "bus palm recoveries"), "1");
  EXPECT_EQ(diagnostic(*robot_, "recover calls"), "2");
  EXPECT_TRUE(robot_->recover(&why));
  EXPECT_EQ(why, "every bus is up: nothing to recover");
}

TEST_F(CanRobotTest, BusOffIsAFaultUntilTheControllerRestarts) {
  start();
  run(0.01);
  CanFrame bus_off;
  bus_off.id = can::kErrFlag | can::kErrBusOff;
  bus_off.dlc = 8;
  boards_.write(2, bus_off);
  robot_->step();
  ASSERT_TRUE(robot_->safety().fault_latched);
  EXPECT_EQ(robot_->safetyEvents().fault.index, 2);
  EXPECT_TRUE(contains(robot_->safety().fault, "bus 'act1' (test:act1) went bus-off")) << robot_->safety().fault;
  std::string why;
  EXPECT_FALSE(robot_->release(&why));
  EXPECT_TRUE(contains(why, "is bus-off: call recover")) << why;
  CanFrame restarted;
  restarted.id = can::kErrFlag | can::kErrRestarted;
  restarted.dlc = 8;
  boards_.write(2, restarted);
  run(0.01);
  EXPECT_TRUE(robot_->release(&why)) << why;
}

TEST_F(CanRobotTest, WaitForInputOnlyPolls) {
  start();
  run(0.01);
  auto before = std::chrono::steady_clock::now();
  EXPECT_FALSE(robot_->waitForInput(0.01));
  EXPECT_GE(std::chrono::steady_clock::now() - before, std::chrono::milliseconds(8));
  robot_->takeFresh();
  boards_.joints();
  before = std::chrono::steady_clock::now();
  EXPECT_TRUE(robot_->waitForInput(1.0));
  EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::milliseconds(500));
  EXPECT_TRUE(robot_->waitForInput(0.0));  // still there: it did not read
  robot_->step();
  EXPECT_EQ(robot_->takeFresh() & Robot::kJoints, static_cast<unsigned>(Robot::kJoints));
}

TEST_F(CanRobotTest, StepsAndAcceptedCommandsAllocateNothing) {
  start();
  run(0.01);
  const CheckedCommand checked = robot_->checkValves({}, {0, 1, 20, 40}, {0.5, -0.5, 1.0, 2.0});
  std::size_t allocations = 0;
  run(0.3, [&] {  // streaming, commanding, heartbeats, kinematics; the robot's calls counted
    allocation_window::start();
    if (boards_.tick % 3 == 0) robot_->applyValves(checked);
    robot_->step();
    robot_->takeFresh();
    allocations += allocation_window::stop();
  });
  EXPECT_EQ(allocations, 0u);
  EXPECT_FALSE(robot_->safety().safe_state);
  EXPECT_GT(boards_.ofType(FrameType::kValveCommand).size(), 100u);
}

TEST_F(CanRobotTest, DiagnosticsNameBusesAndNodes) {
  start();
  run(0.05);
  EXPECT_EQ(diagnostic(*robot_, "bus act2"), "test:act2: ok");
  EXPECT_TRUE(contains(diagnostic(*robot_, "bus palm frames"), "read ")) << diagnostic(*robot_, "bus palm frames");
  EXPECT_EQ(diagnostic(*robot_, "bus palm decode errors"), "none");
  EXPECT_EQ(diagnostic(*robot_, "bus act0 sequence"), "lost 0, duplicates 0, resyncs 0");
  EXPECT_EQ(diagnostic(*robot_, "node valve board 5").rfind("operational, heartbeat ", 0), 0u);
  EXPECT_TRUE(contains(diagnostic(*robot_, "complete samples"), "joints 26"))
      << diagnostic(*robot_, "complete samples");
}

}  // namespace
}  // namespace adroit::driver
