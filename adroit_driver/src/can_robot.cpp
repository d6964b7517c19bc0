#include "adroit_driver/can_robot.h"

#include <poll.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "adroit_driver/can_calibration.h"
#include "adroit_core/number_text.h"

namespace adroit::driver {

using can::CanFrame;
using can::DecodeError;
using can::FrameType;

namespace {

constexpr double kExhaustVolts = -5.0;  // what a valve board holds every channel at when not commanded
constexpr double kTwoPi = 6.283185307179586;
constexpr double kTimeEps = 1e-9;
// A valve board's heartbeat sent before it obeyed our release may arrive after its first
// command: its state counts only this long after that command.
constexpr double kBoardStateGrace = 0.02;
constexpr double kKinematicsPeriod = 0.01;  // s, at most this often (data() for markers and tf)
constexpr std::size_t kReceiveFrames = 256;
constexpr int kReadRoundsPerStep = 8;  // bounded: a flooding bus cannot hold the step
constexpr std::size_t kMaxBuses = 16;
constexpr const char* kForcesOnHardware = "tendon force command rejected: the hardware has valves (pneumatic mode)";

using adroit::shortNumber;

std::string hex(std::uint32_t id) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%03X", id);
  return text;
}

double steadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

template <typename T>
std::string describeBad(const std::string& param, const std::string& rule, T value) {
  std::ostringstream out;
  out << param << " must be " << rule << ", got " << value;
  return out.str();
}

bool positiveFinite(double v) { return std::isfinite(v) && v > 0; }

// 1 - exp(-dt * 2 pi fc): the gain of a first-order low-pass over one interval dt.
double lowPassGain(double dt, double cutoff) { return -std::expm1(-dt * kTwoPi * cutoff); }

const char* faultCodeText(can::FaultCode code) {
  switch (code) {
    case can::FaultCode::kCommandTimeout: return "command timeout";
    case can::FaultCode::kSensor: return "sensor fault";
    case can::FaultCode::kValveDriver: return "valve driver fault";
    case can::FaultCode::kSupplyPressure: return "supply pressure out of limits";
    case can::FaultCode::kBusError: return "CAN errors";
    case can::FaultCode::kVersionMismatch: return "protocol version mismatch";
    case can::FaultCode::kOverTemperature: return "over-temperature";
    case can::FaultCode::kInternal: return "internal fault";
  }
  return "fault";
}


// The mapping must fit the model and the protocol; one line naming what does not.
void checkMapping(const can::Mapping& m, std::size_t joints, std::size_t cylinders,
                  const std::vector<std::string>& model_touch) {
  auto fail = [](const std::string& what) { throw std::invalid_argument("CAN mapping: " + what); };
  if (m.buses.empty() || m.buses.size() > kMaxBuses)
    fail("needs 1 to " + std::to_string(kMaxBuses) + " buses, has " + std::to_string(m.buses.size()));
  if (m.valve_boards.size() != m.buses.size() || m.sensor_boards.size() != m.buses.size())
    fail("valve_boards and sensor_boards need one list per bus");
  if (m.joint.size() != joints)
    fail("has " + std::to_string(m.joint.size()) + " joints, the model " + std::to_string(joints));
  std::vector<char> joint_used(can::kMaxJoints, 0);
  for (std::size_t j = 0; j < m.joint.size(); ++j) {
    const int p = m.joint[j];
    if (p < 0 || p >= can::kMaxJoints) fail("joint " + std::to_string(j) + " has protocol index " + std::to_string(p));
    if (joint_used[p]++) fail("protocol joint index " + std::to_string(p) + " used twice");
  }
  if (m.cylinder.size() != cylinders)
    fail("has " + std::to_string(m.cylinder.size()) + " cylinders, the model " + std::to_string(cylinders));
  std::vector<int> board_bus(can::kMaxBoards, -1);
  std::vector<char> used(can::kMaxBoards * can::kMaxValveChannels, 0);
  const auto listed = [](const std::vector<std::uint8_t>& boards, std::uint8_t b) {
    return std::find(boards.begin(), boards.end(), b) != boards.end();
  };
  for (std::size_t c = 0; c < m.cylinder.size(); ++c) {
    const can::CylinderChannel& ch = m.cylinder[c];
    const std::string which = "cylinder " + std::to_string(c);
    if (ch.bus < 0 || ch.bus >= static_cast<int>(m.buses.size())) fail(which + " is on bus " + std::to_string(ch.bus));
    if (ch.board >= can::kMaxBoards) fail(which + " is on board " + std::to_string(ch.board));
    if (ch.channel >= can::kMaxValveChannels) fail(which + " is on channel " + std::to_string(ch.channel));
    if (board_bus[ch.board] >= 0 && board_bus[ch.board] != ch.bus)
      fail("board " + std::to_string(ch.board) + " is on two buses");
    board_bus[ch.board] = ch.bus;
    if (used[ch.board * can::kMaxValveChannels + ch.channel]++)
      fail("board " + std::to_string(ch.board) + " channel " + std::to_string(ch.channel) + " used twice");
    if (!listed(m.valve_boards[ch.bus], ch.board) || !listed(m.sensor_boards[ch.bus], ch.board))
      fail("board " + std::to_string(ch.board) + " of " + which + " is not listed on bus '" + m.buses[ch.bus] + "'");
  }
  if (m.supply_bus < 0 || m.supply_bus >= static_cast<int>(m.buses.size()) || m.supply_board >= can::kMaxBoards)
    fail("the supply sensor board is not on a bus");
  if (board_bus[m.supply_board] >= 0 && board_bus[m.supply_board] != m.supply_bus)
    fail("the supply sensor board " + std::to_string(m.supply_board) + " is on two buses");
  if (m.touch.size() > static_cast<std::size_t>(can::kMaxTouchSensors)) fail("too many touch sensors");
  for (const auto& t : m.touch) {
    if (std::find(model_touch.begin(), model_touch.end(), t) == model_touch.end())
      fail("touch sensor '" + t + "' is not a touch sensor of the model");
    if (std::count(m.touch.begin(), m.touch.end(), t) > 1) fail("touch sensor '" + t + "' listed twice");
  }
}

}  // namespace

std::string validate(const CanRobotConfig& c) {
  if (c.model_path.empty()) return "~scene (or ~model_file) must name a model";
  if (!positiveFinite(c.timestep) || c.timestep > 0.01) return describeBad("~timestep", "in (0, 0.01] s", c.timestep);
  if (!(c.control_period >= 0.004 && c.control_period <= 0.01))
    return describeBad("~control_period", "in [0.004, 0.01] s (valve cycle of 100 to 250 Hz)", c.control_period);
  if (!(c.watchdog_timeout >= kMinWatchdogTimeout && c.watchdog_timeout <= kMaxWatchdogTimeout))
    return describeBad("~watchdog_timeout", "in [0.01, 0.2] s", c.watchdog_timeout);
  if (!positiveFinite(c.startup_timeout) || c.startup_timeout > 60)
    return describeBad("~startup_timeout", "in (0, 60] s", c.startup_timeout);
  if (!positiveFinite(c.joint_period) || c.joint_period > 0.1)
    return describeBad("~joint_period", "in (0, 0.1] s", c.joint_period);
  if (!positiveFinite(c.sensor_period) || c.sensor_period > 0.1)
    return describeBad("~sensor_period", "in (0, 0.1] s", c.sensor_period);
  if (c.silent_periods < 3 || c.silent_periods > 20)
    return describeBad("~silent_periods", "in [3, 20]", c.silent_periods);
  if (!positiveFinite(c.joint_velocity_cutoff) || c.joint_velocity_cutoff > 0.5 / c.joint_period)
    return describeBad("~joint_velocity_cutoff", "in (0, " + shortNumber(0.5 / c.joint_period) + "] Hz (Nyquist)",
                       c.joint_velocity_cutoff);
  if (!positiveFinite(c.length_rate_cutoff) || c.length_rate_cutoff > 0.5 / c.sensor_period)
    return describeBad("~length_rate_cutoff", "in (0, " + shortNumber(0.5 / c.sensor_period) + "] Hz (Nyquist)",
                       c.length_rate_cutoff);
  if (!(c.supply_pressure > 150e3 && c.supply_pressure <= 1e6))
    return describeBad("~supply_pressure", "in (150e3, 1e6] Pa absolute", c.supply_pressure);
  for (std::size_t b = 0; b < c.buses.size(); ++b)
    if (c.buses[b].empty()) return "~buses: endpoint " + std::to_string(b) + " is empty (\"can0\" or \"unix:<path>\")";
  return "";
}

// ---------------------------------------------------------------------------- construction

CanRobot::CanRobot(CanRobotConfig config) : config_(std::move(config)) {
  const std::string invalid = validate(config_);
  if (!invalid.empty()) throw std::invalid_argument(invalid);
  if (!config_.open_bus) config_.open_bus = can::openBus;
  if (!config_.now) config_.now = steadySeconds;
  origin_ = config_.now();

  model_ = loadModelFile(config_.model_path).model;
  const mjModel* m = model_.get();
  data_ = makeData(m);
  if (m->nkey > 0) mj_resetDataKeyframe(m, data_.get(), 0);
  actuators_ = NameIndex(m, mjOBJ_ACTUATOR);
  cylinders_ = description::cylinderTable(m);
  if (static_cast<int>(cylinders_.size()) != m->nu)
    throw std::invalid_argument("model '" + config_.model_path + "': every actuator must be a tendon cylinder");
  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
    joint_names_.push_back(mj_id2name(m, mjOBJ_JOINT, j));
    joint_qpos_.push_back(m->jnt_qposadr[j]);
  }
  std::vector<std::string> model_touch;
  for (int s = 0; s < m->nsensor; ++s)
    if (m->sensor_type[s] == mjSENS_TOUCH) model_touch.push_back(mj_id2name(m, mjOBJ_SENSOR, s));

  mapping_ = config_.mapping ? *config_.mapping : can::defaultMapping(joint_names_, actuators_.names(), model_touch);
  checkMapping(mapping_, joint_names_.size(), cylinders_.size(), model_touch);
  calibration_ =
      config_.calibration ? *config_.calibration : can::identityCalibration(joint_names_.size(), cylinders_.size());
  const std::string bad_calibration = can::validateCalibration(calibration_, joint_names_, actuators_.names());
  if (!bad_calibration.empty()) throw std::invalid_argument(bad_calibration);
  if (config_.buses.size() != mapping_.buses.size()) {
    std::string names;
    for (const auto& b : mapping_.buses) names += (names.empty() ? "" : ", ") + b;
    throw std::invalid_argument("~buses has " + std::to_string(config_.buses.size()) + " endpoints, the mapping " +
                                std::to_string(mapping_.buses.size()) + " buses (" + names + ")");
  }

  const std::size_t n = cylinders_.size();
  valve_limits_.lower.assign(n, -can::kValveFullScale);
  valve_limits_.upper.assign(n, can::kValveFullScale);
  command_.assign(n, kExhaustVolts);
  applied_command_.assign(n, kExhaustVolts);
  last_command_clock_.assign(n, kNeverCommanded);
  never_commanded_ = n;
  const std::size_t nj = joint_names_.size();
  sensed_.joint_position.assign(nj, 0.0);
  sensed_.joint_velocity.assign(nj, 0.0);
  sensed_.joint_effort.assign(nj, 0.0);
  sensed_.pressure.assign(n, description::kAtmosphericPressure);
  sensed_.length.assign(n, 0.0);
  sensed_.length_rate.assign(n, 0.0);
  sensed_.tension.assign(n, 0.0);
  sensed_.supply_pressure = description::kAtmosphericPressure;
  sensed_.touch.assign(mapping_.touch.size(), 0.0);
  previous_joint_.assign(nj, std::nan(""));
  previous_length_.assign(n, std::nan(""));
  rx_.resize(kReceiveFrames);

  buildTables();
  openBuses();
  startUp();
}

CanRobot::~CanRobot() = default;

double CanRobot::clock() const { return config_.now() - origin_; }

void CanRobot::buildTables() {
  stream_of_id_.fill(-1);
  for (auto& board : cylinder_at_) board.fill(-1);
  const auto expect = [&](std::uint8_t node, int bus) {
    if (nodes_[node].expected) return;
    nodes_[node].expected = true;
    nodes_[node].bus = bus;
    expected_nodes_.push_back(node);
  };
  const auto addStream = [&](std::uint32_t id, int bus, int sample, double period) {
    Stream s;
    s.id = id;
    s.bus = bus;
    s.type = can::frameType(id);
    s.sample = sample;
    s.period = period;
    Sample& set = samples_[sample];
    s.bit = 1u << __builtin_popcount(set.full);
    set.full |= s.bit;
    stream_of_id_[id] = static_cast<std::int16_t>(streams_.size());
    streams_.push_back(s);
  };
  samples_.reserve(2 + can::kMaxBoards);
  const auto newSample = [&](SampleKind kind, int bus, std::uint8_t board) {
    Sample set;
    set.kind = kind;
    set.bus = bus;
    set.board = board;
    samples_.push_back(set);
    return static_cast<int>(samples_.size()) - 1;
  };

  // The palm: its heartbeat, the joint groups the mapping uses, the touch groups.
  expect(can::kPalmNode, can::kPalmBus);
  std::uint32_t joint_groups = 0;
  for (int p : mapping_.joint) joint_groups |= 1u << (p / can::kPackedFields);
  if (joint_groups) {
    joint_sample_ = newSample(SampleKind::kJoints, can::kPalmBus, 0);
    for (int g = 0; g < can::kGroupsPerBoard; ++g)
      if (joint_groups & (1u << g))
        addStream(can::kJointAnglesIdBase + g, can::kPalmBus, joint_sample_, config_.joint_period);
  }
  if (!mapping_.touch.empty()) {
    touch_sample_ = newSample(SampleKind::kTouch, can::kPalmBus, 0);
    const int groups = static_cast<int>((mapping_.touch.size() + can::kPackedFields - 1) / can::kPackedFields);
    for (int g = 0; g < groups; ++g)
      addStream(can::kTouchIdBase + g, can::kPalmBus, touch_sample_, config_.sensor_period);
  }

  // Boards: the nodes listed per bus; the sensor boards' streams; the valve boards' groups.
  for (std::size_t b = 0; b < mapping_.buses.size(); ++b) {
    for (std::uint8_t v : mapping_.valve_boards[b]) expect(can::valveBoardNode(v), static_cast<int>(b));
    for (std::uint8_t s : mapping_.sensor_boards[b]) expect(can::sensorBoardNode(s), static_cast<int>(b));
  }
  expect(can::sensorBoardNode(mapping_.supply_board), mapping_.supply_bus);
  std::array<int, can::kMaxBoards> board_bus;
  board_bus.fill(-1);
  std::array<std::uint32_t, can::kMaxBoards> sensor_groups{}, valve_channels_max{};
  std::array<bool, can::kMaxBoards> has_valves{};
  for (std::size_t c = 0; c < mapping_.cylinder.size(); ++c) {
    const can::CylinderChannel& ch = mapping_.cylinder[c];
    board_bus[ch.board] = ch.bus;
    sensor_groups[ch.board] |= 1u << (ch.channel / can::kPackedFields);
    valve_channels_max[ch.board] = std::max<std::uint32_t>(valve_channels_max[ch.board], ch.channel + 1u);
    has_valves[ch.board] = true;
    cylinder_at_[ch.board][ch.channel] = static_cast<std::int16_t>(c);
  }
  board_bus[mapping_.supply_board] = mapping_.supply_bus;
  for (std::uint8_t board = 0; board < can::kMaxBoards; ++board) {
    const bool supply = board == mapping_.supply_board;
    if (!sensor_groups[board] && !supply) continue;
    const int sample = newSample(SampleKind::kBoard, board_bus[board], board);
    samples_[sample].supply = supply;
    for (std::size_t c = 0; c < mapping_.cylinder.size(); ++c)
      if (mapping_.cylinder[c].board == board) samples_[sample].cylinders.push_back(static_cast<int>(c));
    for (std::uint32_t g = 0; g < can::kGroupsPerBoard; ++g)
      if (sensor_groups[board] & (1u << g))
        addStream(can::kPressureIdBase + can::kGroupsPerBoard * board + g, board_bus[board], sample,
                  config_.sensor_period);
    for (std::uint32_t g = 0; g < can::kGroupsPerBoard; ++g)
      if (sensor_groups[board] & (1u << g))
        addStream(can::kLengthIdBase + can::kGroupsPerBoard * board + g, board_bus[board], sample,
                  config_.sensor_period);
    if (supply) addStream(can::kSupplyIdBase + board, board_bus[board], sample, config_.sensor_period);
  }

  // Valve groups: a board has 8, 16 or 24 channels (the frames' lengths follow, docs 5.2);
  // groups with a mapped channel are sent, their unmapped channels at exhaust.
  group_of_cylinder_.assign(mapping_.cylinder.size(), -1);
  for (std::uint8_t board = 0; board < can::kMaxBoards; ++board) {
    if (!has_valves[board]) continue;
    const int channels = std::min<int>(can::kMaxValveChannels, (valve_channels_max[board] + 7) / 8 * 8);
    for (int g = 0; g * can::kValveChannelsPerFrame < channels; ++g) {
      ValveGroup group;
      group.bus = board_bus[board];
      group.board = board;
      group.group = static_cast<std::uint8_t>(g);
      group.count =
          static_cast<std::uint8_t>(std::min(can::kValveChannelsPerFrame, channels - g * can::kValveChannelsPerFrame));
      bool used = false;
      for (int k = 0; k < group.count; ++k) {
        const int c = cylinder_at_[board][g * can::kValveChannelsPerFrame + k];
        group.cylinder[k] = c;
        if (c < 0) continue;
        used = true;
        group_of_cylinder_[c] = static_cast<int>(groups_.size());
      }
      if (used) groups_.push_back(group);
    }
  }
  touched_groups_.reserve(groups_.size());
}

void CanRobot::openBuses() {
  buses_.resize(mapping_.buses.size());
  poll_fds_ = std::make_unique<std::atomic<int>[]>(buses_.size());
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    Bus& bus = buses_[b];
    bus.name = mapping_.buses[b];
    bus.endpoint = config_.buses[b];
    std::string error;
    auto transport = config_.open_bus(bus.endpoint, &error);
    if (!transport)
      throw std::runtime_error("cannot open CAN bus '" + bus.name + "' (" + bus.endpoint +
                               "): " + (error.empty() ? std::string("no reason given") : error));
    bus.transport = std::move(*transport);
    poll_fds_[b].store(bus.transport->fd(), std::memory_order_release);
  }
}

void CanRobot::startUp() {
  const double real_start = steadySeconds();
  double t = clock();
  sendHeartbeats();
  next_heartbeat_ = t + kHeartbeatPeriod;
  // Heard: every configured node's heartbeat (of our version), every stream, and one complete
  // sample of each set, so that sensed() holds real values from the start.
  const auto everythingHeard = [&] {
    for (int node : expected_nodes_)
      if (nodes_[node].last_heartbeat == kNever || nodes_[node].bad_version >= 0) return false;
    for (const Stream& s : streams_)
      if (s.last == kNever) return false;
    for (const Sample& s : samples_)
      if (s.complete == 0) return false;
    return true;
  };
  for (;;) {
    receive(t);
    for (int node : expected_nodes_)
      if (nodes_[node].bad_version >= 0)
        throw std::runtime_error("CAN start-up: " + nodeName(node) + " on bus '" + buses_[nodes_[node].bus].name +
                                 "' speaks protocol version " + std::to_string(nodes_[node].bad_version) +
                                 ", this driver version " + std::to_string(can::kProtocolVersion) + ": refused");
    for (std::size_t b = 0; b < buses_.size(); ++b)
      if (buses_[b].down != BusDown::kUp && buses_[b].down != BusDown::kBusOff)
        throw std::runtime_error("CAN start-up: " + busName(static_cast<int>(b)) + " failed (" +
                                 (buses_[b].down == BusDown::kHungUp ? std::string("hung up")
                                                                     : std::string(std::strerror(buses_[b].error))) +
                                 ")");
    if (everythingHeard()) break;
    t = clock();
    const double waited = std::max(t, steadySeconds() - real_start);  // an injected clock may stand still
    if (waited >= config_.startup_timeout) {
      std::string missing;
      const auto add = [&](const std::string& what) { missing += (missing.empty() ? "" : "; ") + what; };
      for (int node : expected_nodes_)
        if (nodes_[node].last_heartbeat == kNever)
          add("no heartbeat from " + nodeName(node) + " on bus '" + buses_[nodes_[node].bus].name + "' (" +
              buses_[nodes_[node].bus].endpoint + ")");
      std::string streams;
      for (const Stream& s : streams_)
        if (s.last == kNever) streams += (streams.empty() ? "" : ", ") + streamName(s.id);
      if (!streams.empty()) add("streams never heard: " + streams);
      if (missing.empty()) add("no complete sample (frames of one sample with one sequence number)");
      throw std::runtime_error("CAN start-up: within " + shortNumber(config_.startup_timeout) + " s: " + missing);
    }
    if (t >= next_heartbeat_) {
      sendHeartbeats();
      next_heartbeat_ = t + kHeartbeatPeriod;
    }
    waitForInput(std::min(0.01, config_.startup_timeout - waited));
  }
  started_ = true;
  t = clock();
  next_cycle_ = t;
  next_heartbeat_ = t + kHeartbeatPeriod;
  if (config_.start_in_safe_state) {
    enterSafeState(SafeCause::kEstop, can::EstopCause::kOperator);
  } else if (!safety_.safe_state) {
    // A heartbeat just before, so that a board that booted a moment ago has seen the host
    // (it obeys a release only then, docs section 8).
    sendHeartbeats();
    sendEstops(can::EstopAction::kRelease, can::EstopCause::kNone);
    startup_release_sent_ = true;
  }
  latchBusFaults();
  kinematics_due_ = true;
  updateKinematics(t);
}

// ---------------------------------------------------------------------------- receiving

void CanRobot::receive(double t) {
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    Bus& bus = buses_[b];
    if (!bus.transport || (bus.down != BusDown::kUp && bus.down != BusDown::kBusOff)) continue;
    for (int round = 0; round < kReadRoundsPerStep; ++round) {
      const can::ReadResult r = bus.transport->read(rx_.data(), rx_.size(), std::chrono::nanoseconds(0));
      for (std::size_t k = 0; k < r.count; ++k) handleFrame(static_cast<int>(b), rx_[k], t);
      if (r.status == can::IoStatus::kHangUp) {
        markBusDown(static_cast<int>(b), BusDown::kHungUp, 0);
        break;
      }
      if (r.status == can::IoStatus::kError) {
        markBusDown(static_cast<int>(b), BusDown::kReadError, r.error);
        break;
      }
      if (r.count < rx_.size()) break;
    }
    if (!bus.transport) continue;
    const bool bus_off = bus.transport->busState() == can::BusState::kBusOff;
    if (bus_off && bus.down == BusDown::kUp) markBusDown(static_cast<int>(b), BusDown::kBusOff, 0);
    if (!bus_off && bus.down == BusDown::kBusOff) bus.down = BusDown::kUp;  // the controller restarted
  }
}

void CanRobot::handleFrame(int b, const CanFrame& frame, double t) {
  Bus& bus = buses_[b];
  if (!can::isStandardData(frame)) {
    ++bus.decode_errors[static_cast<int>(DecodeError::kNotDataFrame)];
    return;
  }
  const std::uint32_t id = can::standardId(frame);
  switch (can::frameType(id)) {
    case FrameType::kJointAngles:
    case FrameType::kTouch:
    case FrameType::kPressure:
    case FrameType::kLength:
    case FrameType::kSupply: {
      const int s = stream_of_id_[id];
      if (s < 0 || streams_[s].bus != b) {
        ++bus.unexpected;  // a stream nothing is mapped to, or on the wrong bus
        return;
      }
      handleData(b, s, frame, t);
      return;
    }
    case FrameType::kHeartbeat: handleHeartbeat(b, frame, t); return;
    case FrameType::kEstop: {
      can::EstopFrame e;
      const DecodeError error = can::decode(frame, &e);
      if (error != DecodeError::kNone) {
        ++bus.decode_errors[static_cast<int>(error)];
        return;
      }
      // Only the host releases (docs 5.5); a node's engage stops everything, whatever node.
      if (e.node == can::kHostNode || e.action != can::EstopAction::kEngage) {
        ++bus.unexpected;
        return;
      }
      if (e.cause == can::EstopCause::kButton) nodes_[e.node].button_held = true;
      enterSafeState(SafeCause::kEstop, e.cause, e.node);
      return;
    }
    case FrameType::kFault: {
      can::FaultFrame f;
      const DecodeError error = can::decode(frame, &f);
      if (error != DecodeError::kNone) {
        ++bus.decode_errors[static_cast<int>(error)];
        return;
      }
      if (f.node == can::kHostNode) {
        ++bus.unexpected;
        return;
      }
      ++nodes_[f.node].faults_reported;
      int cylinder = -1;
      const bool board = f.node >= can::kValveBoardNodeBase;
      if (board && f.channel < can::kMaxSensorChannels) cylinder = cylinder_at_[f.node & 0x07][f.channel];
      FaultDetail detail;
      detail.kind = FaultKind::kFaultFrame;
      detail.code = static_cast<int>(f.code);
      detail.channel = f.channel == can::kNoChannel ? -1 : f.channel;
      detail.value = f.detail;
      fault(FaultSource::kBoard, f.node, cylinder, detail);
      return;
    }
    case FrameType::kValveCommand: ++bus.unexpected; return;  // the host's own identifiers
    case FrameType::kUnknown: ++bus.decode_errors[static_cast<int>(DecodeError::kUnknownId)]; return;
  }
}

void CanRobot::handleData(int b, int index, const CanFrame& frame, double t) {
  Stream& stream = streams_[index];
  std::array<double, can::kPackedFields> values{};
  std::uint8_t seq = 0;
  DecodeError error = DecodeError::kNone;
  switch (stream.type) {
    case FrameType::kJointAngles: {
      can::JointAnglesFrame f;
      error = can::decode(frame, &f);
      values = f.angles;
      seq = f.seq;
      break;
    }
    case FrameType::kTouch: {
      can::TouchFrame f;
      error = can::decode(frame, &f);
      values = f.forces;
      seq = f.seq;
      break;
    }
    case FrameType::kPressure:
    case FrameType::kLength: {
      can::SensorFrame f;
      error = can::decode(frame, &f);
      values = f.values;
      seq = f.seq;
      break;
    }
    case FrameType::kSupply: {
      can::SupplyFrame f;
      error = can::decode(frame, &f);
      values[0] = f.pressure;
      seq = f.seq;
      break;
    }
    default: error = DecodeError::kWrongType; break;
  }
  if (error != DecodeError::kNone) {
    ++buses_[b].decode_errors[static_cast<int>(error)];
    return;
  }
  const can::SequenceVerdict verdict = stream.sequence.observe(seq);
  // A repeated or late frame is older than what we have: it never overwrites a newer sample.
  if (verdict == can::SequenceVerdict::kDuplicate || verdict == can::SequenceVerdict::kLate) return;
  stream.last = t;
  stream.values = values;
  Sample& sample = samples_[stream.sample];
  if (!sample.collecting || sample.seq != seq) {
    sample.collecting = true;
    sample.seq = seq;
    sample.mask = 0;
  }
  sample.mask |= stream.bit;
  if (sample.mask == sample.full) completeSample(stream.sample);
}

void CanRobot::completeSample(int index) {
  Sample& s = samples_[index];
  s.collecting = false;
  s.mask = 0;
  switch (s.kind) {
    case SampleKind::kJoints: applyJoints(s); break;
    case SampleKind::kTouch: applyTouch(s); break;
    case SampleKind::kBoard: applyBoard(s); break;
  }
  s.previous_seq = s.seq;
  s.have_previous = true;
  ++s.complete;
  s.fresh = true;
}

namespace {
// Time between two samples from their sequence numbers (0: not comparable, e.g. a resync).
double sampleInterval(bool have_previous, std::uint8_t previous, std::uint8_t now, double period) {
  if (!have_previous) return 0;
  const int step = static_cast<std::uint8_t>(now - previous);
  return step >= 1 && step <= 127 ? step * period : 0;
}
}  // namespace

void CanRobot::noReading(const Stream& stream, int field, int cylinder, int joint) {
  FaultDetail detail;
  detail.kind = FaultKind::kNoReading;
  detail.channel = field;
  detail.code = joint;
  fault(FaultSource::kStream, static_cast<int>(stream.id), cylinder, detail);
}

void CanRobot::applyJoints(Sample& s) {
  const double dt = sampleInterval(s.have_previous, s.previous_seq, s.seq, config_.joint_period);
  const double gain = dt > 0 ? lowPassGain(dt, config_.joint_velocity_cutoff) : 0;
  for (Stream& stream : streams_)
    if (stream.sample == joint_sample_) stream.no_reading = 0;
  for (std::size_t j = 0; j < mapping_.joint.size(); ++j) {
    const int p = mapping_.joint[j];
    Stream& stream = streams_[stream_of_id_[can::kJointAnglesIdBase + p / can::kPackedFields]];
    const int field = p % can::kPackedFields;
    const double raw = stream.values[field];
    if (!std::isfinite(raw)) {  // "no reading": keep the last value, never publish NaN
      stream.no_reading |= static_cast<std::uint8_t>(1u << field);
      previous_joint_[j] = std::nan("");
      noReading(stream, field, -1, static_cast<int>(j));
      continue;
    }
    const double q = calibration_.joint[j].apply(raw);
    if (dt > 0 && std::isfinite(previous_joint_[j]))
      sensed_.joint_velocity[j] += gain * ((q - previous_joint_[j]) / dt - sensed_.joint_velocity[j]);
    previous_joint_[j] = q;
    sensed_.joint_position[j] = q;
  }
  kinematics_due_ = true;
}

void CanRobot::applyTouch(Sample&) {
  for (Stream& stream : streams_)
    if (stream.sample == touch_sample_) stream.no_reading = 0;
  for (std::size_t k = 0; k < mapping_.touch.size(); ++k) {
    Stream& stream = streams_[stream_of_id_[can::kTouchIdBase + k / can::kPackedFields]];
    const int field = static_cast<int>(k % can::kPackedFields);
    const double raw = stream.values[field];
    if (!std::isfinite(raw)) {
      stream.no_reading |= static_cast<std::uint8_t>(1u << field);
      noReading(stream, field, -1, -1);
      continue;
    }
    sensed_.touch[k] = raw;
  }
}

void CanRobot::applyBoard(Sample& s) {
  const double dt = sampleInterval(s.have_previous, s.previous_seq, s.seq, config_.sensor_period);
  const double gain = dt > 0 ? lowPassGain(dt, config_.length_rate_cutoff) : 0;
  const std::uint32_t board_base = can::kGroupsPerBoard * s.board;
  for (Stream& stream : streams_)
    if (&samples_[stream.sample] == &s) stream.no_reading = 0;
  for (int c : s.cylinders) {
    const int channel = mapping_.cylinder[c].channel;
    const int group = channel / can::kPackedFields, field = channel % can::kPackedFields;
    const auto bit = static_cast<std::uint8_t>(1u << field);
    Stream& pressure = streams_[stream_of_id_[can::kPressureIdBase + board_base + group]];
    Stream& length = streams_[stream_of_id_[can::kLengthIdBase + board_base + group]];
    const double p_raw = pressure.values[field], l_raw = length.values[field];
    if (std::isfinite(p_raw)) {
      const double p = calibration_.pressure[c].apply(p_raw);
      sensed_.pressure[c] = p;
      // No tension sensor: the chamber's pull, (p - p_atm) x piston area; it cannot push.
      sensed_.tension[c] = std::max(0.0, (p - description::kAtmosphericPressure) * cylinders_[c].bore_area);
    } else {
      pressure.no_reading |= bit;
      noReading(pressure, field, c, -1);
    }
    if (std::isfinite(l_raw)) {
      const double l = calibration_.length[c].apply(l_raw);
      if (dt > 0 && std::isfinite(previous_length_[c]))
        sensed_.length_rate[c] += gain * ((l - previous_length_[c]) / dt - sensed_.length_rate[c]);
      previous_length_[c] = l;
      sensed_.length[c] = l;
    } else {
      length.no_reading |= bit;
      previous_length_[c] = std::nan("");
      noReading(length, field, c, -1);
    }
  }
  if (s.supply) {
    Stream& supply = streams_[stream_of_id_[can::kSupplyIdBase + s.board]];
    if (std::isfinite(supply.values[0])) {
      sensed_.supply_pressure = calibration_.supply.apply(supply.values[0]);
    } else {
      supply.no_reading = 1;
      noReading(supply, 0, -1, -1);
    }
  }
}

void CanRobot::handleHeartbeat(int b, const CanFrame& frame, double t) {
  Bus& bus = buses_[b];
  const auto node_number = static_cast<std::uint8_t>(can::standardId(frame) - can::kHeartbeatIdBase);
  can::HeartbeatFrame h;
  const DecodeError error = can::decode(frame, &h);
  Node& node = nodes_[node_number];
  if (error == DecodeError::kBadVersion) {
    ++bus.decode_errors[static_cast<int>(error)];
    if (!node.expected || node.bus != b) return;
    node.bad_version = frame.data[1];
    if (started_) {
      FaultDetail detail;
      detail.kind = FaultKind::kBadVersion;
      detail.code = node.bad_version;
      fault(FaultSource::kHeartbeat, node_number, -1, detail);
    }
    return;
  }
  if (error != DecodeError::kNone) {
    ++bus.decode_errors[static_cast<int>(error)];
    return;
  }
  if (!node.expected || node.bus != b) {
    ++bus.unexpected;  // the host's own identifier, or a node not configured on this bus
    return;
  }
  node.heartbeats.observe(h.seq);
  node.last_heartbeat = t;
  node.bad_version = -1;
  node.state = h.state;
  node.flags = h.flags;
  const bool held = (h.flags & can::kFlagEstopInput) != 0;
  if (held && !node.button_held) {
    node.button_held = true;  // pressed and its e-stop frame missed: the flag alone latches
    enterSafeState(SafeCause::kEstop, can::EstopCause::kButton, node_number);
  }
  node.button_held = held;
  if (started_) checkNodeState(node_number, t);
}

void CanRobot::checkNodeState(int number, double t) {
  const Node& node = nodes_[number];
  FaultDetail detail;
  detail.code = static_cast<int>(node.state);
  detail.channel = node.flags;
  if (node.state == can::NodeState::kFault) {
    detail.kind = FaultKind::kNodeFault;
    fault(FaultSource::kBoard, number, -1, detail);
    return;
  }
  // A valve board we command that is not operational has stopped on its own (its watchdog,
  // its own bus-off, a reboot): the host must stop too, or it would command a dead board.
  const bool valve_board = number >= can::kValveBoardNodeBase && number < can::kSensorBoardNodeBase;
  if (valve_board && !safety_.safe_state && node.commanded && t - node.first_command > kBoardStateGrace &&
      node.state != can::NodeState::kOperational) {
    detail.kind = FaultKind::kBoardSafe;
    fault(FaultSource::kBoard, number, -1, detail);
  }
}

// ---------------------------------------------------------------------------- stepping

void CanRobot::step() {
  const double t = clock();
  discountStall(t);
  receive(t);
  latchBusFaults();
  checkSafety(t);
  sendDue(t);
  latchBusFaults();
  updateKinematics(t);
  ++counters_.steps;
}

// Time this thread did not run is time it could not observe: a stream is silent only when
// frames fail to come while the host is looking. After a stall of the driver (descheduled, or a
// virtual machine whose boards' emulator stalled with it) the streams, heartbeats and commands
// are judged from the last step on; a host-only stall loses nothing (the frames wait in the
// socket) and a real silence is still found, one stall later. The boards' own 50 ms command
// watchdogs do not discount anything: they stop the valves of a host that stalls too long.
void CanRobot::discountStall(double t) {
  if (last_step_ != kNever && t - last_step_ > 2 * config_.timestep) {
    const double unobserved = t - last_step_ - config_.timestep;
    for (Stream& s : streams_)
      if (s.last != kNever) s.last += unobserved;
    for (Node& n : nodes_)
      if (n.last_heartbeat != kNever) n.last_heartbeat += unobserved;
    for (double& c : last_command_clock_)
      if (c != kNeverCommanded) c += unobserved;
    ++stalls_discounted_;
  }
  last_step_ = t;
}

void CanRobot::checkSafety(double t) {
  // Host command watchdog, exactly as the simulation's: every cylinder a controller has
  // commanded must keep being commanded; the stalest one is recorded.
  if (!safety_.safe_state && safety_.watchdog_armed) {
    int stalest = -1;
    for (std::size_t i = 0; i < last_command_clock_.size(); ++i) {
      const double c = last_command_clock_[i];
      if (c != kNeverCommanded && (stalest < 0 || c < last_command_clock_[stalest])) stalest = static_cast<int>(i);
    }
    if (stalest >= 0) {
      const double age = t - last_command_clock_[stalest];
      command_age_max_ = std::max(command_age_max_, age);
      if (age >= config_.watchdog_timeout - kTimeEps)
        enterSafeState(SafeCause::kWatchdog, can::EstopCause::kWatchdog, -1, stalest);
    }
  }
  bool persists = false;
  for (const Bus& bus : buses_) persists |= bus.down != BusDown::kUp;
  for (const Stream& s : streams_) {
    persists |= s.no_reading != 0;
    if (!streamSilent(s, t)) continue;
    persists = true;
    FaultDetail detail;
    detail.kind = FaultKind::kStreamSilent;
    detail.value = t - s.last;
    fault(FaultSource::kStream, static_cast<int>(s.id), -1, detail);
  }
  bool button = host_estop_input_;
  for (int number : expected_nodes_) {
    const Node& node = nodes_[number];
    button |= node.button_held;
    persists |= node.bad_version >= 0 || node.state == can::NodeState::kFault;
    if (!heartbeatMissing(node, t)) continue;
    persists = true;
    FaultDetail detail;
    detail.kind = FaultKind::kHeartbeatMissing;
    detail.value = t - node.last_heartbeat;
    fault(FaultSource::kHeartbeat, number, -1, detail);
  }
  safety_.fault_persists = persists;
  safety_.estop_input = button;
  if (persists) ++counters_.faulted_steps;
}

void CanRobot::updateKinematics(double t) {
  if (!kinematics_due_ || t - last_kinematics_ < kKinematicsPeriod - kTimeEps) return;
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  for (std::size_t j = 0; j < joint_qpos_.size(); ++j) d->qpos[joint_qpos_[j]] = sensed_.joint_position[j];
  d->time = t;
  // Bodies, sites, geoms and the tendons' paths: what markers and tf draw.
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_tendon(m, d);
  last_kinematics_ = t;
  kinematics_due_ = false;
}

unsigned CanRobot::takeFresh() {
  unsigned fresh = 0;
  if (joint_sample_ >= 0 && samples_[joint_sample_].fresh) {
    fresh |= kJoints;
    samples_[joint_sample_].fresh = false;
  }
  if (touch_sample_ >= 0 && samples_[touch_sample_].fresh) {
    fresh |= kTouch;
    samples_[touch_sample_].fresh = false;
  }
  // Actuators: one message per round of every sensor board, so each holds a whole sample.
  bool boards = false, all = true;
  for (const Sample& s : samples_) {
    if (s.kind != SampleKind::kBoard) continue;
    boards = true;
    all &= s.fresh;
  }
  if (boards && all) {
    fresh |= kActuators;
    for (Sample& s : samples_)
      if (s.kind == SampleKind::kBoard) s.fresh = false;
  }
  return fresh;
}

bool CanRobot::waitForInput(double seconds) {
  std::array<pollfd, kMaxBuses> fds;
  nfds_t n = 0;
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    const int fd = poll_fds_[b].load(std::memory_order_acquire);
    if (fd >= 0) fds[n++] = pollfd{fd, POLLIN, 0};
  }
  seconds = std::isfinite(seconds) ? std::max(0.0, seconds) : 0.0;
  timespec timeout;
  timeout.tv_sec = static_cast<time_t>(seconds);
  timeout.tv_nsec = static_cast<long>((seconds - static_cast<double>(timeout.tv_sec)) * 1e9);
  return ::ppoll(fds.data(), n, &timeout, nullptr) > 0;
}

// ---------------------------------------------------------------------------- sending

void CanRobot::send(int b, const CanFrame& frame) {
  Bus& bus = buses_[b];
  if (!bus.transport || (bus.down != BusDown::kUp && bus.down != BusDown::kBusOff)) return;
  switch (bus.transport->write(frame)) {
    case can::IoStatus::kOk:
    case can::IoStatus::kFull:  // counted by the transport; the next cycle sends again
    case can::IoStatus::kTimeout: return;
    case can::IoStatus::kHangUp: markBusDown(b, BusDown::kHungUp, 0); return;
    case can::IoStatus::kError: markBusDown(b, BusDown::kWriteError, bus.transport->lastError()); return;
  }
}

void CanRobot::sendHeartbeat(int b) {
  can::HeartbeatFrame h;
  h.node = can::kHostNode;
  h.state = safety_.safe_state ? can::NodeState::kSafe : can::NodeState::kOperational;
  h.flags = host_estop_input_ ? can::kFlagEstopInput : 0;
  h.seq = buses_[b].heartbeat_seq++;
  CanFrame frame;
  if (can::encode(h, &frame).ok()) send(b, frame);
}

void CanRobot::sendHeartbeats() {
  for (std::size_t b = 0; b < buses_.size(); ++b) sendHeartbeat(static_cast<int>(b));
}

void CanRobot::sendEstop(int b, can::EstopAction action, can::EstopCause cause) {
  can::EstopFrame e;
  e.node = can::kHostNode;
  e.action = action;
  e.cause = cause;
  e.seq = buses_[b].estop_seq++;
  CanFrame frame;
  if (can::encode(e, &frame).ok()) send(b, frame);
}

void CanRobot::sendEstops(can::EstopAction action, can::EstopCause cause) {
  for (std::size_t b = 0; b < buses_.size(); ++b) sendEstop(static_cast<int>(b), action, cause);
}

void CanRobot::sendGroup(int index, double t) {
  ValveGroup& g = groups_[index];
  can::ValveCommandFrame f;
  f.board = g.board;
  f.first_channel = static_cast<std::uint8_t>(g.group * can::kValveChannelsPerFrame);
  f.count = g.count;
  for (int k = 0; k < g.count; ++k) {
    const int c = g.cylinder[k];
    // Channels not commanded since start / release stay at exhaust, as the board holds them.
    const bool commanded = c >= 0 && last_command_clock_[c] != kNeverCommanded;
    f.volts[k] = commanded ? command_[c] : kExhaustVolts;
    if (c >= 0) applied_command_[c] = f.volts[k];
  }
  f.seq = g.seq++;
  CanFrame frame;
  if (can::encode(f, &frame).ok()) send(g.bus, frame);
  g.last_sent = t;
  g.pending = false;
  Node& board = nodes_[can::valveBoardNode(g.board)];
  if (!board.commanded) {
    board.commanded = true;
    board.first_command = t;
  }
}

void CanRobot::sendDue(double t) {
  if (t >= next_heartbeat_ - kTimeEps) {
    sendHeartbeats();
    next_heartbeat_ += kHeartbeatPeriod;
    if (next_heartbeat_ <= t) next_heartbeat_ = t + kHeartbeatPeriod;
  }
  if (safety_.safe_state) {
    // A board that reconnects (or missed the first frame) learns that the host is stopped.
    if (t >= next_estop_repeat_ - kTimeEps) {
      sendEstops(can::EstopAction::kEngage, latched_cause_);
      next_estop_repeat_ = t + kHeartbeatPeriod;
    }
    return;
  }
  const bool cycle = t >= next_cycle_ - kTimeEps;
  if (cycle) {
    next_cycle_ += config_.control_period;
    if (next_cycle_ <= t) next_cycle_ = t + config_.control_period;  // far behind: no burst
  }
  // A new command waiting for its group's minimum interval goes out as soon as that passed;
  // the cycle repeats only the groups no command has sent for a whole period (the boards'
  // 50 ms watchdog needs them), so a repeat never stands in the way of a new command.
  for (std::size_t g = 0; g < groups_.size(); ++g) {
    const ValveGroup& group = groups_[g];
    if (!group.commanded) continue;
    const double since = t - group.last_sent;
    if ((group.pending && since >= kMinGroupInterval - kTimeEps) ||
        (cycle && since >= config_.control_period - kTimeEps))
      sendGroup(static_cast<int>(g), t);
  }
}

// ---------------------------------------------------------------------------- commands

CheckedCommand CanRobot::checkValves(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                                     const std::vector<double>& volts) const {
  return checkCommand(actuators_, names, indices, volts, valve_limits_);
}

CheckedCommand CanRobot::checkForces(const std::vector<std::string>&, const std::vector<std::uint16_t>&,
                                     const std::vector<double>&) const {
  return {CommandVerdict::kBadAddressing, kForcesOnHardware, {}, {}};
}

CommandResult CanRobot::applyForces(const CheckedCommand&) {
  ++counters_.rejected_wrong_mode;
  return {CommandVerdict::kBadAddressing, false, kForcesOnHardware};
}

CommandResult CanRobot::applyValves(const CheckedCommand& checked) {
  const double t = clock();
  CommandResult result = acceptCommand(checked, t);
  if (!result.applied) return result;
  // Lowest latency from the sensors through the pools to the valves: out at once, unless the
  // group went out less than kMinGroupInterval ago (a flood of commands: step() sends it when
  // that has passed, so no group exceeds 500 Hz and the bus stays within budget).
  for (int g : touched_groups_)
    if (t - groups_[g].last_sent >= kMinGroupInterval - kTimeEps) sendGroup(g, t);
  touched_groups_.clear();
  latchBusFaults();
  return result;
}

CommandResult CanRobot::acceptCommand(const CheckedCommand& checked, double t) {
  CommandResult result = countCommand(checked, safety_.safe_state, &counters_);
  if (!result.applied) return result;
  for (std::size_t k = 0; k < checked.actuator.size(); ++k) {
    const int a = checked.actuator[k];
    if (last_command_clock_[a] == kNeverCommanded) --never_commanded_;
    command_[a] = checked.value[k];
    last_command_clock_[a] = t;
    const int g = group_of_cylinder_[a];
    if (g < 0) continue;
    groups_[g].commanded = true;
    if (!groups_[g].pending) {
      groups_[g].pending = true;
      touched_groups_.push_back(g);
    }
  }
  safety_.watchdog_armed = true;
  return result;
}

// ---------------------------------------------------------------------------- safety

void CanRobot::enterSafeState(SafeCause cause, can::EstopCause estop_cause, int index, int cylinder, FaultSource source,
                              const FaultDetail* detail) {
  const double t = clock();
  SafetyEvent event;
  event.cause = cause;
  event.clock = t;
  event.cylinder = cylinder;
  event.index = index;
  event.fault = cause == SafeCause::kFault ? source : FaultSource::kNone;
  if (!latchSafeState(&event, &safety_, &counters_, &events_)) return;
  if (cause == SafeCause::kFault) {
    FaultDetail d = detail ? *detail : FaultDetail{};
    d.sequence = event.sequence;
    {
      std::lock_guard<std::mutex> lock(details_mutex_);
      details_[event.sequence % details_.size()] = d;
    }
    safety_.fault = faultText(event, &d);  // formatted once per fault event
  }
  for (ValveGroup& g : groups_) g.pending = false;
  std::fill(applied_command_.begin(), applied_command_.end(), kExhaustVolts);
  // Every bus at once: the boards exhaust every valve and the supply (docs section 8).
  latched_cause_ = estop_cause;
  sendEstops(can::EstopAction::kEngage, estop_cause);
  next_estop_repeat_ = t + kHeartbeatPeriod;
}

void CanRobot::fault(FaultSource source, int index, int cylinder, const FaultDetail& detail) {
  if (safety_.fault_latched) return;  // cheap: the checks run every step while a cause persists
  enterSafeState(SafeCause::kFault, can::EstopCause::kFault, index, cylinder, source, &detail);
}

void CanRobot::markBusDown(int b, BusDown why, int error) {
  Bus& bus = buses_[b];
  if (bus.down != BusDown::kUp && bus.down != BusDown::kBusOff) return;  // keep the first reason
  bus.down = why;
  bus.error = error;
  bus.reported = false;
  // A hung-up socket polls readable for ever: waitForInput() leaves it out.
  if (why != BusDown::kBusOff) poll_fds_[b].store(-1, std::memory_order_release);
  bus_news_ = true;
}

void CanRobot::latchBusFaults() {
  if (!bus_news_) return;
  bus_news_ = false;
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    Bus& bus = buses_[b];
    if (bus.down == BusDown::kUp || bus.reported) continue;
    bus.reported = true;
    FaultDetail detail;
    detail.code = bus.error;
    switch (bus.down) {
      case BusDown::kHungUp: detail.kind = FaultKind::kBusHungUp; break;
      case BusDown::kBusOff: detail.kind = FaultKind::kBusOff; break;
      case BusDown::kWriteError: detail.kind = FaultKind::kBusWriteError; break;
      default: detail.kind = FaultKind::kBusReadError; break;
    }
    fault(FaultSource::kBus, static_cast<int>(b), -1, detail);
  }
}

void CanRobot::estop() { enterSafeState(SafeCause::kEstop, can::EstopCause::kOperator); }

void CanRobot::setEstopInput(bool held) {
  if (held && !host_estop_input_) enterSafeState(SafeCause::kEstop, can::EstopCause::kButton, can::kHostNode);
  host_estop_input_ = held;
  bool any = held;
  for (int number : expected_nodes_) any |= nodes_[number].button_held;
  safety_.estop_input = any;
}

std::string CanRobot::persistingCause() const {
  const double t = clock();
  std::vector<std::string> causes;
  if (host_estop_input_) causes.push_back("the e-stop input is held");
  for (int number : expected_nodes_)
    if (nodes_[number].button_held)
      causes.push_back("the e-stop button of " + nodeName(number) + " (bus '" + buses_[nodes_[number].bus].name +
                       "') is held");
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    const Bus& bus = buses_[b];
    switch (bus.down) {
      case BusDown::kUp: break;
      case BusDown::kHungUp: causes.push_back(busName(static_cast<int>(b)) + " is hung up: call recover"); break;
      case BusDown::kBusOff: causes.push_back(busName(static_cast<int>(b)) + " is bus-off: call recover"); break;
      default:
        causes.push_back(busName(static_cast<int>(b)) + " failed (" + std::strerror(bus.error) + "): call recover");
    }
  }
  for (int number : expected_nodes_) {
    const Node& node = nodes_[number];
    if (node.bad_version >= 0)
      causes.push_back(nodeName(number) + " speaks protocol version " + std::to_string(node.bad_version));
    else if (heartbeatMissing(node, t))
      causes.push_back("no heartbeat from " + nodeName(number) + " for " + shortNumber(t - node.last_heartbeat) + " s");
    else if (node.state == can::NodeState::kFault)
      causes.push_back(nodeName(number) + " is in the fault state (power-cycle it)");
  }
  for (const Stream& s : streams_) {
    if (buses_[s.bus].down != BusDown::kUp) continue;  // said above
    if (streamSilent(s, t))
      causes.push_back("the " + streamName(s.id) + " is silent");
    else if (s.no_reading)
      causes.push_back("the " + streamName(s.id) + " still reports no reading");
  }
  std::string text;
  const std::size_t shown = std::min<std::size_t>(causes.size(), 4);
  for (std::size_t k = 0; k < shown; ++k) text += (k ? "; " : "") + causes[k];
  if (causes.size() > shown) text += "; and " + std::to_string(causes.size() - shown) + " more";
  return text;
}

bool CanRobot::release(std::string* why) {
  const std::string cause = persistingCause();
  if (!cause.empty()) {
    if (why) *why = "refused: " + cause;
    return false;
  }
  if (!safety_.safe_state) {
    // Unlike the simulation, the commands and the watchdog stay: the boards keep applying
    // the commanded groups, so the host must keep commanding them (or their own watchdogs
    // trip). The release frame again lets a board that missed the last one come up.
    sendHeartbeats();
    sendEstops(can::EstopAction::kRelease, can::EstopCause::kNone);
    latchBusFaults();
    if (why) *why = safety_.fault_latched ? "refused: " + safety_.fault : "not in the safe state";
    return !safety_.fault_latched;
  }
  safety_ = SafetyStatus{};
  std::fill(command_.begin(), command_.end(), kExhaustVolts);
  std::fill(applied_command_.begin(), applied_command_.end(), kExhaustVolts);
  std::fill(last_command_clock_.begin(), last_command_clock_.end(), kNeverCommanded);
  never_commanded_ = last_command_clock_.size();
  for (ValveGroup& g : groups_) {
    g.commanded = false;
    g.pending = false;
  }
  for (Node& node : nodes_) {
    node.commanded = false;
    node.first_command = kNever;
  }
  // The boards obey the release only with a recent host heartbeat (docs section 8).
  sendHeartbeats();
  sendEstops(can::EstopAction::kRelease, can::EstopCause::kNone);
  latchBusFaults();
  if (safety_.fault_latched) {
    if (why) *why = "refused: " + safety_.fault;
    return false;
  }
  if (why) *why = "released";
  return true;
}

bool CanRobot::recover(std::string* why) {
  ++recover_calls_;
  std::string done, failed;
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    Bus& bus = buses_[b];
    const bool down = bus.down != BusDown::kUp || !bus.transport || bus.transport->hungUp() ||
                      bus.transport->busState() == can::BusState::kBusOff;
    if (!down) continue;
    poll_fds_[b].store(-1, std::memory_order_release);
    if (bus.transport) {
      const can::TransportCounters& c = bus.transport->counters();
      bus.previous.frames_read += c.frames_read;
      bus.previous.frames_written += c.frames_written;
      bus.previous.write_full += c.write_full;
      bus.previous.error_frames += c.error_frames;
      bus.previous.wrong_size += c.wrong_size;
      bus.previous.bad_dlc += c.bad_dlc;
      bus.transport.reset();
    }
    std::string error;
    auto transport = config_.open_bus(bus.endpoint, &error);
    if (!transport) {
      if (bus.down == BusDown::kUp || bus.down == BusDown::kBusOff) bus.down = BusDown::kHungUp;
      bus.reported = true;  // already latched (or latched now by nobody: it has no transport)
      failed += (failed.empty() ? "" : "; ") + busName(static_cast<int>(b)) + ": " + error;
      continue;
    }
    bus.transport = std::move(*transport);
    bus.down = BusDown::kUp;
    bus.error = 0;
    bus.reported = false;
    ++bus.recoveries;
    poll_fds_[b].store(bus.transport->fd(), std::memory_order_release);
    // Tell the bus's boards at once that the host is back (and still stopped, if it is).
    sendHeartbeat(static_cast<int>(b));
    if (safety_.safe_state) sendEstop(static_cast<int>(b), can::EstopAction::kEngage, latched_cause_);
    done += (done.empty() ? "" : ", ") + busName(static_cast<int>(b));
  }
  latchBusFaults();
  if (!failed.empty()) {
    if (why) *why = "cannot reopen " + failed + (done.empty() ? "" : "; reopened " + done);
    return false;
  }
  if (why) {
    *why = done.empty() ? "every bus is up: nothing to recover" : "reopened " + done;
    if (safety_.safe_state) *why += " (the safe state stays latched until release)";
  }
  return true;
}

// ---------------------------------------------------------------------------- describing

std::string CanRobot::nodeName(int node) const {
  if (node == can::kHostNode) return "the host";
  if (node == can::kPalmNode) return "palm MCU";
  if (node >= can::kValveBoardNodeBase && node < can::kValveBoardNodeBase + can::kMaxBoards)
    return "valve board " + std::to_string(node - can::kValveBoardNodeBase);
  if (node >= can::kSensorBoardNodeBase && node < can::kSensorBoardNodeBase + can::kMaxBoards)
    return "sensor board " + std::to_string(node - can::kSensorBoardNodeBase);
  return "node " + hex(static_cast<std::uint32_t>(node));
}

std::string CanRobot::busName(int b) const {
  if (b < 0 || b >= static_cast<int>(buses_.size())) return "bus #" + std::to_string(b);
  return "bus '" + buses_[b].name + "' (" + buses_[b].endpoint + ")";
}

std::string CanRobot::streamName(std::uint32_t id) const {
  const auto range = [](const char* what, std::uint32_t first, std::uint32_t count) {
    return std::string(what) + " " + std::to_string(first) + ".." + std::to_string(first + count - 1);
  };
  const auto board_group = [&](std::uint32_t base, const char* kind) {
    const std::uint32_t board = (id - base) / can::kGroupsPerBoard, group = (id - base) % can::kGroupsPerBoard;
    return std::string(kind) + " stream of sensor board " + std::to_string(board) + " (" + hex(id) + ", " +
           range("channels", group * can::kPackedFields, can::kPackedFields) + ")";
  };
  switch (can::frameType(id)) {
    case FrameType::kJointAngles:
      return "joint stream of the palm (" + hex(id) + ", " +
             range("joints", (id - can::kJointAnglesIdBase) * can::kPackedFields, can::kPackedFields) + ")";
    case FrameType::kTouch:
      return "touch stream of the palm (" + hex(id) + ", " +
             range("sensors", (id - can::kTouchIdBase) * can::kPackedFields, can::kPackedFields) + ")";
    case FrameType::kPressure: return board_group(can::kPressureIdBase, "pressure");
    case FrameType::kLength: return board_group(can::kLengthIdBase, "length");
    case FrameType::kSupply:
      return "supply stream of sensor board " + std::to_string(id - can::kSupplyIdBase) + " (" + hex(id) + ")";
    default: break;
  }
  return "stream " + hex(id);
}

std::string CanRobot::faultText(const SafetyEvent& e, const FaultDetail* d) const {
  const FaultKind kind = d ? d->kind : FaultKind::kNone;
  const auto cylinder = [&] {
    return e.cylinder >= 0 && e.cylinder < static_cast<int>(cylinders_.size())
               ? "'" + actuators_.names()[e.cylinder] + "'"
               : std::string("?");
  };
  switch (e.fault) {
    case FaultSource::kBus: {
      const std::string bus = busName(e.index);
      switch (kind) {
        case FaultKind::kBusHungUp: return bus + " hung up";
        case FaultKind::kBusOff: return bus + " went bus-off";
        case FaultKind::kBusWriteError: return bus + ": write failed (" + std::strerror(d->code) + ")";
        case FaultKind::kBusReadError: return bus + ": read failed (" + std::strerror(d->code) + ")";
        default: return bus + " failed";
      }
    }
    case FaultSource::kStream: {
      const auto id = static_cast<std::uint32_t>(e.index);
      const FrameType type = can::frameType(id);
      std::string name = streamName(id);
      if (kind == FaultKind::kStreamSilent) {
        // "pressure stream of sensor board 2 silent for 0.013 s (0x150, channels 0..3, bus 'act1')"
        const std::size_t open = name.find(" (");
        std::string where = open == std::string::npos ? "" : name.substr(open + 2, name.size() - open - 3);
        const int s = id < stream_of_id_.size() ? stream_of_id_[id] : -1;
        if (s >= 0) where += ", bus '" + buses_[streams_[s].bus].name + "'";
        return name.substr(0, open) + " silent for " + shortNumber(d->value) + " s (" + where + ")";
      }
      if (kind == FaultKind::kNoReading) {
        std::string what = "field " + std::to_string(d->channel);
        if (type == FrameType::kJointAngles && d->code >= 0 && d->code < static_cast<int>(joint_names_.size()))
          what = "joint '" + joint_names_[d->code] + "'";
        else if (type == FrameType::kTouch)
          what = "touch sensor " + std::to_string((id - can::kTouchIdBase) * can::kPackedFields + d->channel);
        else if (type == FrameType::kSupply)
          what = "the supply pressure";
        else if (e.cylinder >= 0)
          what = "cylinder " + cylinder();
        return name + ": no reading for " + what;
      }
      return name + " failed";
    }
    case FaultSource::kHeartbeat: {
      const int bus = e.index >= 0 && e.index < 64 ? nodes_[e.index].bus : -1;
      const std::string on = bus >= 0 ? " (bus '" + buses_[bus].name + "')" : "";
      if (kind == FaultKind::kBadVersion)
        return nodeName(e.index) + on + " speaks protocol version " + std::to_string(d->code) + ", this driver " +
               std::to_string(can::kProtocolVersion);
      if (kind == FaultKind::kHeartbeatMissing)
        return "heartbeat of " + nodeName(e.index) + on + " missing for " + shortNumber(d->value) + " s";
      return "heartbeat of " + nodeName(e.index) + on + " missing or wrong";
    }
    case FaultSource::kBoard: {
      const std::string node = nodeName(e.index);
      if (kind == FaultKind::kFaultFrame) {
        const auto code = static_cast<can::FaultCode>(d->code);
        const std::string channel = d->channel >= 0 ? " on channel " + std::to_string(d->channel) : "";
        const auto detail = static_cast<unsigned>(d->value);
        std::string value;
        switch (code) {
          case can::FaultCode::kCommandTimeout: value = std::to_string(detail) + " ms"; break;
          case can::FaultCode::kSensor: value = "raw " + std::to_string(detail); break;
          case can::FaultCode::kValveDriver: value = detail == 0 ? "open load" : "short / over-current"; break;
          case can::FaultCode::kSupplyPressure: value = std::to_string(detail) + " kPa absolute"; break;
          case can::FaultCode::kBusError:
            value = "tx errors " + std::to_string(detail >> 8) + ", rx errors " + std::to_string(detail & 0xFF);
            break;
          case can::FaultCode::kVersionMismatch: value = "saw version " + std::to_string(detail); break;
          case can::FaultCode::kOverTemperature: value = std::to_string(detail) + " deg C"; break;
          default: value = "detail " + hex(detail); break;
        }
        std::string text = node + " reported " + faultCodeText(code) + channel + " (" + value + ")";
        if (e.cylinder >= 0) text += ", cylinder " + cylinder();
        return text;
      }
      const auto state = static_cast<can::NodeState>(d ? d->code : 0);
      if (kind == FaultKind::kBoardSafe) {
        std::string text = node + " went " + can::nodeStateName(state) + " on its own while commanded";
        if (d->channel & can::kFlagWatchdog) text += " (its command watchdog tripped)";
        if (d->channel & can::kFlagEstopInput) text += " (its e-stop input is held)";
        return text;
      }
      if (kind == FaultKind::kNodeFault) return node + " reports the fault state";
      return node + " failed";
    }
    default: break;
  }
  return "fault";
}

std::string CanRobot::describe(const SafetyEvent& e) const {
  const std::string when = " (clock " + shortNumber(e.clock) + " s, event " + std::to_string(e.sequence) + ")";
  switch (e.cause) {
    case SafeCause::kEstop:
      if (e.index < 0) return "e-stop" + when;
      if (e.index == can::kHostNode) return "e-stop: the e-stop input" + when;
      return "e-stop from " + nodeName(e.index) + when;
    case SafeCause::kWatchdog: {
      const std::string name =
          e.cylinder >= 0 && e.cylinder < static_cast<int>(cylinders_.size()) ? actuators_.names()[e.cylinder] : "?";
      return "watchdog: '" + name + "' not commanded for " + shortNumber(config_.watchdog_timeout) + " s" + when;
    }
    case SafeCause::kFault: {
      FaultDetail detail;
      {
        std::lock_guard<std::mutex> lock(details_mutex_);
        detail = details_[e.sequence % details_.size()];
      }
      return "fault: " + faultText(e, detail.sequence == e.sequence ? &detail : nullptr) + when;
    }
    case SafeCause::kNone: break;
  }
  return "no safety event";
}

void CanRobot::addDiagnostics(DiagnosticValues* values) const {
  const double t = clock();
  values->emplace_back("stalls_discounted", std::to_string(stalls_discounted_));
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    const Bus& bus = buses_[b];
    const std::string key = "bus " + bus.name;
    std::string state;
    switch (bus.down) {
      case BusDown::kUp: state = "ok"; break;
      case BusDown::kHungUp: state = "hung up"; break;
      case BusDown::kBusOff: state = "bus-off"; break;
      case BusDown::kWriteError: state = std::string("write error: ") + std::strerror(bus.error); break;
      case BusDown::kReadError: state = std::string("read error: ") + std::strerror(bus.error); break;
    }
    if (bus.transport && bus.down == BusDown::kUp && bus.transport->busState() != can::BusState::kErrorActive)
      state += std::string(" (") + can::busStateName(bus.transport->busState()) + ")";
    values->emplace_back(key, bus.endpoint + ": " + state);
    can::TransportCounters c = bus.previous;
    if (bus.transport) {
      const can::TransportCounters& now = bus.transport->counters();
      c.frames_read += now.frames_read;
      c.frames_written += now.frames_written;
      c.write_full += now.write_full;
      c.error_frames += now.error_frames;
      c.wrong_size += now.wrong_size;
      c.bad_dlc += now.bad_dlc;
    }
    values->emplace_back(key + " frames", "read " + std::to_string(c.frames_read) + ", written " +
                                              std::to_string(c.frames_written) + ", write_full " +
                                              std::to_string(c.write_full) + ", error frames " +
                                              std::to_string(c.error_frames));
    std::string errors;
    if (c.wrong_size) errors += "wrong datagram size " + std::to_string(c.wrong_size);
    if (c.bad_dlc) errors += (errors.empty() ? "" : ", ") + std::string("dlc > 8 ") + std::to_string(c.bad_dlc);
    for (std::size_t k = 1; k < bus.decode_errors.size(); ++k)
      if (bus.decode_errors[k])
        errors += (errors.empty() ? "" : ", ") + std::string(can::decodeErrorName(static_cast<DecodeError>(k))) + " " +
                  std::to_string(bus.decode_errors[k]);
    values->emplace_back(key + " decode errors", errors.empty() ? "none" : errors);
    std::uint64_t lost = 0, duplicates = 0, resyncs = 0;
    for (const Stream& s : streams_) {
      if (s.bus != static_cast<int>(b)) continue;
      lost += s.sequence.stats().lost;
      duplicates += s.sequence.stats().duplicates;
      resyncs += s.sequence.stats().resyncs;
    }
    for (int number : expected_nodes_) {
      if (nodes_[number].bus != static_cast<int>(b)) continue;
      lost += nodes_[number].heartbeats.stats().lost;
      duplicates += nodes_[number].heartbeats.stats().duplicates;
      resyncs += nodes_[number].heartbeats.stats().resyncs;
    }
    values->emplace_back(key + " sequence", "lost " + std::to_string(lost) + ", duplicates " +
                                                std::to_string(duplicates) + ", resyncs " + std::to_string(resyncs));
    values->emplace_back(key + " unexpected frames", std::to_string(bus.unexpected));
    values->emplace_back(key + " recoveries", std::to_string(bus.recoveries));
  }
  for (int number : expected_nodes_) {
    const Node& node = nodes_[number];
    std::string text = node.last_heartbeat == kNever ? std::string("never heard")
                                                     : std::string(can::nodeStateName(node.state)) + ", heartbeat " +
                                                           shortNumber(t - node.last_heartbeat) + " s ago";
    if (node.bad_version >= 0) text += ", protocol version " + std::to_string(node.bad_version);
    if (node.flags & can::kFlagEstopInput) text += ", e-stop input held";
    if (node.flags & can::kFlagWatchdog) text += ", command watchdog tripped";
    if (node.flags & can::kFlagSupplyOpen) text += ", supply valve open";
    if (node.faults_reported) text += ", faults reported " + std::to_string(node.faults_reported);
    values->emplace_back("node " + nodeName(number), text);
  }
  values->emplace_back("recover calls", std::to_string(recover_calls_));
  const char* release = "sent";
  if (!startup_release_sent_)
    release = config_.start_in_safe_state ? "not sent (start_in_safe_state)" : "not sent (safe state at start)";
  values->emplace_back("start-up release", release);
  std::string samples;
  for (const Sample& s : samples_) {
    const std::string what = s.kind == SampleKind::kJoints  ? "joints"
                             : s.kind == SampleKind::kTouch ? "touch"
                                                            : "sensor board " + std::to_string(s.board);
    samples += (samples.empty() ? "" : ", ") + what + " " + std::to_string(s.complete);
  }
  values->emplace_back("complete samples", samples);
}

}  // namespace adroit::driver
