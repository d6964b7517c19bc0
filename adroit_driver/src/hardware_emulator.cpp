#include "adroit_driver/hardware_emulator.h"

#include "adroit_core/pi_mutex.h"
#include "adroit_core/scheduling.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <cmath>
#include <cstdio>
#include <limits>
#include <mutex>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <variant>

#include "adroit_driver/can_transport.h"
#include "adroit_driver/simulated_robot.h"

namespace adroit::driver::can {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kExhaustVolts = -5.0;          // a board's safe output (section 8)
constexpr double kGroupWatchdog = 0.050;        // s, fixed in protocol version 1
constexpr double kHostHeartbeatTimeout = 0.300;  // s, fixed in protocol version 1
constexpr double kTimeEps = 1e-9;
constexpr int kNodes = 64;  // 6-bit node numbers
// 1 s of the busiest bus (palm, 3520 frames/s) fits, so any allowed delay is honoured.
constexpr std::size_t kDelayCapacity = 4096;
constexpr std::size_t kReadBatch = 64;
constexpr int kMaxReadBatches = 16;  // per bus and step: a flooding host cannot stall the simulation
constexpr auto kLateRestart = std::chrono::milliseconds(50);

// Physical ranges of the packed quantities (section 5.1), in bus units.
constexpr double kJointRange = kJointAngleMaxRaw * kJointAngleLsb;
constexpr double kTouchRange = kTouchMaxRaw / kTouchPerLsb;
constexpr double kPressureRange = kPressureMaxRaw * kPressureLsb;
constexpr double kLengthRange = kLengthMaxRaw / kLengthPerLsb;

// NaN ("no reading") passes through.
double clampTo(double v, double lo, double hi) { return std::isnan(v) ? v : std::min(hi, std::max(lo, v)); }

std::string hex(unsigned value) {
  char text[8];
  std::snprintf(text, sizeof text, "0x%02X", value);
  return text;
}

std::string nodeName(std::uint8_t node) {
  if (node == kHostNode) return "host";
  if (node == kPalmNode) return "palm";
  if (node >= kValveBoardNodeBase && node < kValveBoardNodeBase + kMaxBoards)
    return "valve board " + std::to_string(node - kValveBoardNodeBase);
  if (node >= kSensorBoardNodeBase && node < kSensorBoardNodeBase + kMaxBoards)
    return "sensor board " + std::to_string(node - kSensorBoardNodeBase);
  return "node " + hex(node);
}

std::string number(double x) {
  std::ostringstream o;
  o << x;
  return o.str();
}

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

void checkProbability(double p, const char* what) {
  require(p >= 0 && p <= 1, std::string(what) + " must be in [0, 1], got " + number(p));
}
void checkDelay(double seconds) {
  require(seconds >= 0 && seconds <= kMaxInjectedDelay,
          "delay must be in [0, " + number(kMaxInjectedDelay) + "] s, got " + number(seconds));
}

// A copy of `f` that a strict decoder rejects: a value the protocol reserves (out-of-range raw
// field, reserved bit, undefined enumeration) when `content`, else a wrong length.
CanFrame corruptFrame(const CanFrame& f, bool content) {
  Message check;
  if (content) {
    CanFrame g = f;
    const auto setField0 = [&g](std::uint16_t raw) {  // bits 0..13 of the packed 56-bit number
      g.data[1] = static_cast<std::uint8_t>(raw & 0xFF);
      g.data[2] = static_cast<std::uint8_t>((g.data[2] & 0xC0) | ((raw >> 8) & 0x3F));
    };
    switch (frameType(standardId(f))) {
      case FrameType::kJointAngles: setField0(0x1FFF); break;  // +8191 > 6434
      case FrameType::kTouch:
      case FrameType::kPressure:
      case FrameType::kLength: setField0(0x3FFE); break;  // between the maximum and "no reading"
      case FrameType::kSupply: g.data[2] |= 0x80; break;   // reserved bit 15
      case FrameType::kHeartbeat: g.data[3] |= 0x80; break;  // reserved flag bit 7
      case FrameType::kEstop:
      case FrameType::kFault: g.data[1] = 0; break;  // undefined action / code
      default: break;
    }
    if (decode(g, &check) != DecodeError::kNone) return g;
  }
  CanFrame g = f;
  g.dlc = static_cast<std::uint8_t>(f.dlc > 1 ? f.dlc - 1 : f.dlc + 1);
  return g;
}

// Outgoing frames held back by an injected delay: a preallocated FIFO of (time sent, frame).
// A frame is due at its time plus the bus's current delay, so a changed delay applies to the
// frames already held and the order on the bus is kept.
class DelayRing {
 public:
  DelayRing() : slots_(kDelayCapacity) {}
  bool push(double sent, const CanFrame& frame) {
    if (size_ == slots_.size()) return false;
    slots_[(head_ + size_) % slots_.size()] = {sent, frame};
    ++size_;
    return true;
  }
  bool empty() const { return size_ == 0; }
  bool frontDue(double now, double delay) const { return size_ > 0 && slots_[head_].sent + delay <= now + kTimeEps; }
  CanFrame pop() {
    const CanFrame f = slots_[head_].frame;
    head_ = (head_ + 1) % slots_.size();
    --size_;
    return f;
  }
  void clear() { head_ = size_ = 0; }

 private:
  struct Slot {
    double sent = 0;
    CanFrame frame;
  };
  std::vector<Slot> slots_;
  std::size_t head_ = 0, size_ = 0;
};

struct ValveBoard {
  std::uint8_t board = 0, node = 0;
  int bus = 0;
  int channels = 8;  // 8, 16 or 24
  NodeState state = NodeState::kBoot;
  bool watchdog_flag = false;  // latched until the next release
  std::array<double, kMaxValveChannels> volts{};  // last commanded
  std::array<int, kMaxValveChannels> cylinder{};  // -1: no cylinder on the channel
  std::array<bool, kGroupsPerBoard> commanded{};  // since the last release
  std::array<double, kGroupsPerBoard> last_command{};
  std::uint64_t watchdog_trips = 0;
  int groups() const { return (channels + kValveChannelsPerFrame - 1) / kValveChannelsPerFrame; }
};

struct SensorBoard {
  std::uint8_t board = 0, node = 0;
  int bus = 0;
  std::array<int, kMaxSensorChannels> cylinder{};  // -1: nothing on the channel
  std::uint8_t groups = 0;  // bit g: group g has a cylinder
  bool supply = false;      // wired to the supply sensor
};

// What the setters change, copied by the simulation at the start of each step.
struct Settings {
  std::vector<double> drop, corrupt, delay;  // per bus
  std::vector<char> stuck;                   // per cylinder
  std::array<bool, kNodes> silent_node{}, button{};
  bool silent_joints = false, silent_touch = false;
  std::array<bool, kMaxBoards> silent_pressure{}, silent_length{}, silent_supply{};
};

enum class ActionKind { kBusOff, kDisconnect, kBoardFault, kPowerCycle };
struct Action {
  ActionKind kind = ActionKind::kDisconnect;
  int bus = kAllBuses;
  std::uint8_t node = 0;
  FaultCode code = FaultCode::kInternal;
};

struct Bus {
  std::string name, path;
  std::optional<SeqpacketListener> listener;
  std::optional<CanTransport> link;
  bool bus_off = false;
  double last_host_heartbeat = -kInf;
  int host_bad_version = -1;  // the version of the host's last heartbeat if it was not ours
  std::uint64_t seen_bad_datagrams = 0;  // of the current link
  DelayRing ring;
  BusStatus status;
};

Mapping checkMapping(Mapping m, std::size_t joints, std::size_t cylinders, const std::vector<std::string>& touch) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("CAN mapping: " + what); };
  const int buses = static_cast<int>(m.buses.size());
  if (buses < 2) bad("needs the palm bus and at least one actuation bus");
  if (m.joint.size() != joints)
    bad(std::to_string(m.joint.size()) + " joints, the model has " + std::to_string(joints));
  std::vector<bool> used(kMaxJoints, false);
  for (int j : m.joint) {
    if (j < 0 || j >= kMaxJoints) bad("joint index " + std::to_string(j) + " is not in [0, 31]");
    if (used[j]) bad("joint index " + std::to_string(j) + " is used twice");
    used[j] = true;
  }
  if (m.cylinder.size() != cylinders)
    bad(std::to_string(m.cylinder.size()) + " cylinders, the model has " + std::to_string(cylinders));
  std::vector<int> board_bus(kMaxBoards, -1);
  std::vector<bool> channel_used(kMaxBoards * kMaxValveChannels, false);
  for (const auto& c : m.cylinder) {
    if (c.bus < 1 || c.bus >= buses) bad("cylinder on bus " + std::to_string(c.bus) + ": not an actuation bus");
    if (c.board >= kMaxBoards || c.channel >= kMaxValveChannels)
      bad("board " + std::to_string(c.board) + " channel " + std::to_string(c.channel) + " is not addressable");
    if (board_bus[c.board] >= 0 && board_bus[c.board] != c.bus)
      bad("board " + std::to_string(c.board) + " has cylinders on two buses");
    board_bus[c.board] = c.bus;
    auto&& slot = channel_used[c.board * kMaxValveChannels + c.channel];
    if (slot) bad("board " + std::to_string(c.board) + " channel " + std::to_string(c.channel) + " is used twice");
    slot = true;
  }
  if (m.supply_bus < 1 || m.supply_bus >= buses || m.supply_board >= kMaxBoards)
    bad("the supply sensor must be on a sensor board (0..7) of an actuation bus");
  if (board_bus[m.supply_board] >= 0 && board_bus[m.supply_board] != m.supply_bus)
    bad("sensor board " + std::to_string(m.supply_board) + " reads the supply on another bus than its cylinders");
  if (m.touch.size() > static_cast<std::size_t>(kMaxTouchSensors)) bad("more than 32 touch sensors");
  for (const auto& t : m.touch)
    if (std::find(touch.begin(), touch.end(), t) == touch.end()) bad("unknown touch sensor '" + t + "'");
  // Boards on each bus: those listed, and those the cylinders and the supply put there.
  m.valve_boards.resize(buses);
  m.sensor_boards.resize(buses);
  const auto add = [&](std::vector<std::vector<std::uint8_t>>* lists, int bus, std::uint8_t board) {
    if (board >= kMaxBoards) bad("board " + std::to_string(board) + " is not addressable");
    for (int b = 0; b < buses; ++b) {
      const auto& l = (*lists)[b];
      if (std::find(l.begin(), l.end(), board) != l.end() && b != bus)
        bad("board " + std::to_string(board) + " listed on two buses");
    }
    auto& l = (*lists)[bus];
    if (std::find(l.begin(), l.end(), board) == l.end()) l.push_back(board);
  };
  for (int b = 1; b < buses; ++b) {
    for (auto board : std::vector<std::uint8_t>(m.valve_boards[b])) add(&m.valve_boards, b, board);
    for (auto board : std::vector<std::uint8_t>(m.sensor_boards[b])) add(&m.sensor_boards, b, board);
  }
  if (!m.valve_boards[0].empty() || !m.sensor_boards[0].empty()) bad("boards listed on the palm bus");
  for (const auto& c : m.cylinder) {
    add(&m.valve_boards, c.bus, c.board);
    add(&m.sensor_boards, c.bus, c.board);
  }
  add(&m.sensor_boards, m.supply_bus, m.supply_board);
  for (int b = 0; b < buses; ++b) {
    std::sort(m.valve_boards[b].begin(), m.valve_boards[b].end());
    std::sort(m.sensor_boards[b].begin(), m.sensor_boards[b].end());
  }
  return m;
}

void checkCalibration(const Calibration& c, std::size_t joints, std::size_t cylinders) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("calibration: " + what); };
  if (c.joint.size() != joints || c.pressure.size() != cylinders || c.length.size() != cylinders)
    bad("sizes do not match the model (" + std::to_string(joints) + " joints, " + std::to_string(cylinders) +
        " cylinders)");
  const auto ok = [](const Affine& a) { return std::isfinite(a.gain) && a.gain != 0 && std::isfinite(a.offset); };
  for (const auto* list : {&c.joint, &c.pressure, &c.length})
    for (const auto& a : *list)
      if (!ok(a)) bad("every gain must be finite and non-zero, every offset finite");
  if (!ok(c.supply)) bad("the supply's gain must be finite and non-zero, its offset finite");
}

}  // namespace

std::string defaultBusPath(const std::string& bus) { return "/tmp/adroit_can_" + bus; }

// ============================================================================ Impl

struct HardwareEmulator::Impl {
  explicit Impl(const EmulatorConfig& c);

  // --- simulation thread (or the caller of tick()) ---
  void tick();
  void run();
  void takeSettings();
  void acceptConnections();
  void runActions(double now);
  void pressButtons(double now);
  void readHost(int bus, double now);
  void handleHostFrame(int bus, const CanFrame& frame, double now);
  void applyCommand(int bus, const ValveCommandFrame& command, double now);
  void release(ValveBoard& vb, double now);
  void runBoardTimers(double now);
  void updateSupplyValve();
  void applyVolts();
  void updateStuck();
  void sendStreams(double t);
  void sendJoints(double t);
  void sendTouch(double t);
  void sendSensors(double t);
  void sendHeartbeats(double t);
  void sendFault(std::uint8_t node, FaultCode code, std::uint8_t channel, std::uint16_t detail, double t);
  bool sendEstop(std::uint8_t node, EstopCause cause, double t);
  void send(int bus, const CanFrame& frame, double t);
  void write(int bus, const CanFrame& frame);
  void flushDelayed(double t);
  void closeLink(int bus);
  void boardsSafeOnBus(int bus);
  void goSafe(ValveBoard& vb) {
    if (vb.state != NodeState::kFault) vb.state = NodeState::kSafe;
  }
  std::uint8_t flagsOf(std::uint8_t node) const;
  NodeState stateOf(std::uint8_t node) const;
  void publish();
  void placeObject();  // a placement asked for by HardwareEmulator::placeObject

  // --- any thread ---
  void checkBus(int bus) const;
  void checkNode(std::uint8_t node) const;
  int parseBus(const std::string& text) const;
  std::uint8_t parseNode(const std::string& text) const;
  SilenceTarget parseSilence(const std::string& text) const;
  std::size_t parseCylinder(const std::string& text) const;
  std::string silenceName(const SilenceTarget& t) const;
  void describeInjections(const Settings& s, std::vector<std::string>* out) const;
  ValveBoard* valveBoardOfNode(std::uint8_t node) {
    const int b = node - kValveBoardNodeBase;
    return b >= 0 && b < kMaxBoards && valve_index_[b] >= 0 ? &valves_[valve_index_[b]] : nullptr;
  }

  EmulatorConfig config_;
  std::unique_ptr<SimulatedRobot> robot_;
  Mapping mapping_;
  std::vector<std::string> bus_paths_;
  std::size_t joints_ = 0, cylinders_ = 0;

  // Layout, constant after construction.
  std::array<int, kMaxJoints> joint_at_{};      // protocol joint index -> robot joint, -1
  std::vector<int> touch_source_;              // per Mapping::touch: index in the robot's touch sensors
  std::uint8_t joint_groups_ = 0, touch_groups_ = 0;
  std::array<int, kNodes> node_bus_{};          // -1: not a node of this robot
  std::array<int, kMaxBoards> valve_index_{}, sensor_index_{};
  std::vector<ValveBoard> valves_;
  std::vector<SensorBoard> sensors_;
  std::vector<Bus> buses_;
  double joint_period_ = 0, touch_period_ = 0, sensor_period_ = 0, heartbeat_period_ = 0;

  // Simulation state.
  struct Placement {
    std::array<double, 3> position, linear, angular;
    std::array<double, 4> quaternion;
    std::uint64_t id;
  };
  Calibration calibration_;
  Settings active_;
  std::optional<Placement> placing_;  // taken from placement_ at the start of the step
  std::vector<Action> actions_;
  std::array<bool, kNodes> button_was_{};
  std::vector<char> stuck_was_;
  std::vector<double> stuck_pressure_, stuck_length_;
  std::vector<double> joint_sent_, touch_sent_, pressure_sent_, length_sent_;
  double supply_sent_ = kNaN;
  std::vector<double> volts_;
  std::vector<std::uint16_t> indices_;
  bool supply_open_ = false;
  std::uint8_t joint_seq_ = 0, touch_seq_ = 0;
  std::array<std::uint8_t, kMaxBoards> sensor_seq_{};
  std::array<std::uint8_t, kNodes> heartbeat_seq_{}, estop_seq_{}, fault_seq_{};
  std::array<std::uint64_t, kNodes> faults_sent_{};
  double next_joint_ = kNaN, next_touch_ = kNaN, next_sensor_ = kNaN, next_heartbeat_ = kNaN;
  std::uint64_t steps_ = 0, overruns_ = 0;
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> uniform_{0.0, 1.0};
  std::array<CanFrame, kReadBatch> rx_{};

  // Shared with the other threads, under mutex_.
  // Priority inheritance: a normal-priority reader (the node's timers) preempted while holding it
  // runs at the SCHED_FIFO stepping thread's priority until it lets go.
  mutable PiMutex mutex_;
  Settings settings_;
  std::vector<Action> pending_;
  std::optional<Calibration> new_calibration_;
  EmulatorSnapshot published_;
  std::optional<Placement> placement_;           // the next step applies it
  std::uint64_t placements_done_ = 0;            // id of the last placement applied or refused
  std::string placement_error_;                  // its refusal ("" applied)
  std::condition_variable_any placed_;
  std::uint64_t placements_requested_ = 0;

  std::thread thread_;
  std::atomic<int> fifo_{0};  // the thread's scheduling: 1 SCHED_FIFO, -1 refused, 0 not asked (yet)
  std::atomic<bool> stop_{false};
  bool started_ = false, stopped_ = false;
};

HardwareEmulator::Impl::Impl(const EmulatorConfig& c) : config_(c), rng_(c.seed) {
  require(c.sim.mode == ActuationMode::kPneumatic,
          "the hardware emulator needs the pneumatic mode: the robot's boards drive valves");
  const auto rate = [](double hz, const char* name) {
    require(std::isfinite(hz) && hz > 0, std::string(name) + " must be a finite rate > 0 Hz, got " + number(hz));
    return 1.0 / hz;
  };
  joint_period_ = rate(c.joint_rate, "joint_rate");
  touch_period_ = rate(c.touch_rate, "touch_rate");
  sensor_period_ = rate(c.sensor_rate, "sensor_rate");
  heartbeat_period_ = rate(c.heartbeat_rate, "heartbeat_rate");
  checkProbability(c.faults.drop_probability, "drop probability");
  checkProbability(c.faults.corrupt_probability, "corrupt probability");
  checkDelay(c.faults.delay);

  robot_ = std::make_unique<SimulatedRobot>(c.sim);
  joints_ = robot_->jointNames().size();
  cylinders_ = robot_->cylinderNames().size();
  const auto& touch_names = robot_->touchNames();
  const Mapping mapping =
      c.mapping ? *c.mapping : defaultMapping(robot_->jointNames(), robot_->cylinderNames(), touch_names);
  mapping_ = checkMapping(mapping, joints_, cylinders_, touch_names);
  calibration_ = c.calibration ? *c.calibration : identityCalibration(joints_, cylinders_);
  checkCalibration(calibration_, joints_, cylinders_);
  const int nbuses = static_cast<int>(mapping_.buses.size());
  bus_paths_ = c.bus_paths;
  if (bus_paths_.empty())
    for (const auto& b : mapping_.buses) bus_paths_.push_back(defaultBusPath(b));
  require(bus_paths_.size() == mapping_.buses.size(), "bus_paths: " + std::to_string(bus_paths_.size()) +
                                                          " paths for " + std::to_string(nbuses) + " buses");

  // Streams of the palm.
  joint_at_.fill(-1);
  for (std::size_t j = 0; j < joints_; ++j) {
    joint_at_[mapping_.joint[j]] = static_cast<int>(j);
    joint_groups_ |= static_cast<std::uint8_t>(1u << (mapping_.joint[j] / kPackedFields));
  }
  for (std::size_t k = 0; k < mapping_.touch.size(); ++k) {
    touch_source_.push_back(static_cast<int>(
        std::find(touch_names.begin(), touch_names.end(), mapping_.touch[k]) - touch_names.begin()));
    touch_groups_ |= static_cast<std::uint8_t>(1u << (k / kPackedFields));
  }

  // Boards.
  node_bus_.fill(-1);
  valve_index_.fill(-1);
  sensor_index_.fill(-1);
  node_bus_[kPalmNode] = kPalmBus;
  for (int b = 1; b < nbuses; ++b) {
    for (std::uint8_t board : mapping_.valve_boards[b]) {
      ValveBoard vb;
      vb.board = board;
      vb.node = valveBoardNode(board);
      vb.bus = b;
      vb.cylinder.fill(-1);
      vb.volts.fill(kExhaustVolts);
      valve_index_[board] = static_cast<int>(valves_.size());
      node_bus_[vb.node] = b;
      valves_.push_back(vb);
    }
    for (std::uint8_t board : mapping_.sensor_boards[b]) {
      SensorBoard sb;
      sb.board = board;
      sb.node = sensorBoardNode(board);
      sb.bus = b;
      sb.cylinder.fill(-1);
      sb.supply = b == mapping_.supply_bus && board == mapping_.supply_board;
      sensor_index_[board] = static_cast<int>(sensors_.size());
      node_bus_[sb.node] = b;
      sensors_.push_back(sb);
    }
  }
  for (std::size_t i = 0; i < cylinders_; ++i) {
    const auto& ch = mapping_.cylinder[i];
    ValveBoard& vb = valves_[valve_index_[ch.board]];
    vb.cylinder[ch.channel] = static_cast<int>(i);
    // Boards come with 8 channels, or 16 / 24 when more are wired (section 5.2).
    vb.channels = std::max(vb.channels, std::min(kMaxValveChannels, (ch.channel / 8 + 1) * 8));
    SensorBoard& sb = sensors_[sensor_index_[ch.board]];
    sb.cylinder[ch.channel] = static_cast<int>(i);
    sb.groups |= static_cast<std::uint8_t>(1u << (ch.channel / kPackedFields));
  }
  const auto byBoard = [](const auto& a, const auto& b) { return a.board < b.board; };
  std::sort(valves_.begin(), valves_.end(), byBoard);
  std::sort(sensors_.begin(), sensors_.end(), byBoard);
  for (std::size_t k = 0; k < valves_.size(); ++k) valve_index_[valves_[k].board] = static_cast<int>(k);
  for (std::size_t k = 0; k < sensors_.size(); ++k) sensor_index_[sensors_[k].board] = static_cast<int>(k);

  buses_.resize(nbuses);
  for (int b = 0; b < nbuses; ++b) {
    buses_[b].name = mapping_.buses[b];
    buses_[b].path = bus_paths_[b];
    buses_[b].status.name = buses_[b].name;
    buses_[b].status.path = buses_[b].path;
  }

  settings_.drop.assign(nbuses, c.faults.drop_probability);
  settings_.corrupt.assign(nbuses, c.faults.corrupt_probability);
  settings_.delay.assign(nbuses, c.faults.delay);
  settings_.stuck.assign(cylinders_, 0);
  active_ = settings_;
  stuck_was_.assign(cylinders_, 0);
  stuck_pressure_.assign(cylinders_, kNaN);
  stuck_length_.assign(cylinders_, kNaN);
  joint_sent_.assign(joints_, kNaN);
  touch_sent_.assign(mapping_.touch.size(), kNaN);
  pressure_sent_.assign(cylinders_, kNaN);
  length_sent_.assign(cylinders_, kNaN);
  volts_.assign(cylinders_, kExhaustVolts);
  for (std::size_t i = 0; i < cylinders_; ++i) indices_.push_back(static_cast<std::uint16_t>(i));
  actions_.reserve(64);
  pending_.reserve(64);

  // The boards boot safe: the supply valve is closed until valve board 0 is released.
  robot_->estop();

  published_.has_object = robot_->hasObject();
  published_.palm.node = kPalmNode;
  published_.palm.bus = kPalmBus;
  for (const auto& vb : valves_) published_.valve_boards.push_back({vb.node, vb.bus});
  for (const auto& sb : sensors_) published_.sensor_boards.push_back({sb.node, sb.bus});
  for (const auto& b : buses_) published_.buses.push_back(b.status);
  publish();
}

// ---------------------------------------------------------------------------- stepping

void HardwareEmulator::Impl::run() {
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(robot_->timestep()));
  if (config_.realtime_priority > 0) {
    fifo_.store(enterFifo(config_.realtime_priority, nullptr) ? 1 : -1);
  }
  auto deadline = Clock::now();
  while (!stop_.load(std::memory_order_relaxed)) {
    tick();
    deadline += period;
    const auto now = Clock::now();
    if (now - deadline > kLateRestart) {  // e.g. the machine was suspended: do not race to catch up
      deadline = now;
      ++overruns_;
    }
    std::this_thread::sleep_until(deadline);
  }
}

void HardwareEmulator::Impl::tick() {
  const double now = robot_->clock();
  takeSettings();
  placeObject();
  acceptConnections();
  runActions(now);
  pressButtons(now);
  for (int b = 0; b < static_cast<int>(buses_.size()); ++b) readHost(b, now);
  runBoardTimers(now);
  updateSupplyValve();
  applyVolts();
  robot_->step();
  const double t = robot_->clock();
  updateStuck();
  sendStreams(t);
  flushDelayed(t);
  for (auto& vb : valves_)
    if (vb.state == NodeState::kBoot) vb.state = NodeState::kSafe;  // boot lasts one step (its first heartbeat)
  ++steps_;
  publish();
}

void HardwareEmulator::Impl::takeSettings() {
  std::lock_guard<PiMutex> lock(mutex_);
  active_ = settings_;  // same sizes: no allocation
  actions_.clear();
  actions_.swap(pending_);
  placing_ = placement_;
  placement_.reset();
  if (new_calibration_) {
    calibration_ = std::move(*new_calibration_);
    new_calibration_.reset();
  }
}

void HardwareEmulator::Impl::placeObject() {
  if (!placing_) return;
  std::string error;
  const Placement& p = *placing_;
  const bool ok = robot_->setObjectPose(p.position, p.quaternion, p.linear, p.angular, &error);
  {
    std::lock_guard<PiMutex> lock(mutex_);
    placements_done_ = p.id;
    placement_error_ = ok ? std::string() : error;
  }
  placing_.reset();
  placed_.notify_all();
}

void HardwareEmulator::Impl::acceptConnections() {
  for (auto& b : buses_) {
    if (!b.listener) continue;
    // The newest connection wins: a host that reconnects replaces its old link.
    for (;;) {
      std::string error;
      auto link = b.listener->accept(std::chrono::nanoseconds(0), &error);
      if (!link) break;
      b.link = std::move(link);
      b.bus_off = false;
      b.ring.clear();
      b.seen_bad_datagrams = 0;
      ++b.status.connections;
    }
  }
}

void HardwareEmulator::Impl::closeLink(int bus) {
  Bus& b = buses_[bus];
  b.link.reset();
  b.ring.clear();
  b.bus_off = false;
}

void HardwareEmulator::Impl::boardsSafeOnBus(int bus) {
  for (auto& vb : valves_)
    if (vb.bus == bus) goSafe(vb);
}

void HardwareEmulator::Impl::runActions(double now) {
  for (const Action& a : actions_) {
    const int first = a.bus == kAllBuses ? 0 : a.bus;
    const int last = a.bus == kAllBuses ? static_cast<int>(buses_.size()) - 1 : a.bus;
    switch (a.kind) {
      case ActionKind::kBusOff:
        for (int b = first; b <= last; ++b) {
          Bus& bus = buses_[b];
          if (bus.link && !bus.bus_off) {
            // What the host's controller reports when it leaves the bus (linux/can/error.h);
            // not a data frame, so not counted as one.
            CanFrame error;
            error.id = kErrFlag | kErrBusOff;
            error.dlc = kMaxDataLength;
            if (bus.link->write(error) == IoStatus::kHangUp) closeLink(b);
          }
          if (bus.link) bus.bus_off = true;
          bus.ring.clear();
          boardsSafeOnBus(b);  // the boards are off that bus too
        }
        break;
      case ActionKind::kDisconnect:
        for (int b = first; b <= last; ++b) closeLink(b);
        break;
      case ActionKind::kBoardFault:
        if (ValveBoard* vb = valveBoardOfNode(a.node)) vb->state = NodeState::kFault;
        sendFault(a.node, a.code, kNoChannel, 0, now);
        break;
      case ActionKind::kPowerCycle:
        for (auto& vb : valves_) {
          if (vb.state != NodeState::kFault) continue;
          vb.state = NodeState::kSafe;
          vb.watchdog_flag = false;
          vb.commanded.fill(false);
        }
        break;
    }
  }
  actions_.clear();
}

void HardwareEmulator::Impl::pressButtons(double now) {
  for (int node = 0; node < kNodes; ++node) {
    const bool held = active_.button[node];
    if (held && !button_was_[node]) {
      const auto n = static_cast<std::uint8_t>(node);
      if (ValveBoard* vb = valveBoardOfNode(n)) goSafe(*vb);
      // Every board of the bus hears the engage frame and goes safe (section 8).
      if (sendEstop(n, EstopCause::kButton, now)) boardsSafeOnBus(node_bus_[node]);
    }
    button_was_[node] = held;
  }
}

void HardwareEmulator::Impl::readHost(int bus, double now) {
  Bus& b = buses_[bus];
  for (int batch = 0; batch < kMaxReadBatches && b.link; ++batch) {
    const ReadResult r = b.link->read(rx_.data(), rx_.size(), std::chrono::nanoseconds(0));
    const TransportCounters& c = b.link->counters();
    const std::uint64_t bad = c.wrong_size + c.bad_dlc + c.error_frames;
    b.status.bad_datagrams += bad - b.seen_bad_datagrams;
    b.seen_bad_datagrams = bad;
    const bool hung_up = r.status == IoStatus::kHangUp;
    if (b.bus_off) {
      b.status.ignored += r.count;  // off the bus: nothing the host sends arrives
    } else {
      for (std::size_t k = 0; k < r.count; ++k) handleHostFrame(bus, rx_[k], now);
    }
    if (hung_up) {
      closeLink(bus);
      return;
    }
    if (r.status != IoStatus::kOk || r.count < rx_.size()) return;
  }
}

void HardwareEmulator::Impl::handleHostFrame(int bus, const CanFrame& frame, double now) {
  Bus& b = buses_[bus];
  ++b.status.frames_received;
  Message m;
  const DecodeError e = decode(frame, &m);
  if (e != DecodeError::kNone) {
    ++b.status.bad_frames;
    if (e == DecodeError::kBadVersion && standardId(frame) == kHeartbeatIdBase + kHostNode)
      b.host_bad_version = frame.data[1];
    return;
  }
  if (const auto* hb = std::get_if<HeartbeatFrame>(&m)) {
    if (hb->node != kHostNode) {  // the emulator plays every other node of the bus
      ++b.status.bad_frames;
      return;
    }
    b.last_host_heartbeat = now;
    b.host_bad_version = -1;
    return;
  }
  if (const auto* es = std::get_if<EstopFrame>(&m)) {
    if (es->action == EstopAction::kEngage) {
      boardsSafeOnBus(bus);  // from any node
    } else if (es->node == kHostNode) {
      for (auto& vb : valves_)
        if (vb.bus == bus) release(vb, now);
    } else {
      ++b.status.bad_frames;  // only the host's release is obeyed, and the host sends only its own
    }
    return;
  }
  if (const auto* vc = std::get_if<ValveCommandFrame>(&m)) {
    applyCommand(bus, *vc, now);
    return;
  }
  ++b.status.bad_frames;  // a board's frame (data, fault): never the host's
}

void HardwareEmulator::Impl::applyCommand(int bus, const ValveCommandFrame& command, double now) {
  const int index = valve_index_[command.board];
  if (index < 0 || valves_[index].bus != bus || command.first_channel + command.count > valves_[index].channels) {
    ++buses_[bus].status.bad_frames;  // no such board or channel on this bus
    return;
  }
  ValveBoard& vb = valves_[index];
  if (vb.state != NodeState::kOperational) return;  // a safe board ignores commands until released
  for (int k = 0; k < command.count; ++k) vb.volts[command.first_channel + k] = command.volts[k];
  const int group = command.first_channel / kValveChannelsPerFrame;
  vb.commanded[group] = true;
  vb.last_command[group] = now;
}

void HardwareEmulator::Impl::release(ValveBoard& vb, double now) {
  if (vb.state != NodeState::kSafe) return;  // operational already, in fault, or still booting
  if (active_.button[vb.node]) return;       // its own e-stop input is held
  const Bus& b = buses_[vb.bus];
  if (b.host_bad_version >= 0) {
    sendFault(vb.node, FaultCode::kVersionMismatch, kNoChannel, static_cast<std::uint16_t>(b.host_bad_version), now);
    return;
  }
  if (now - b.last_host_heartbeat >= kHostHeartbeatTimeout - kTimeEps) return;
  vb.state = NodeState::kOperational;
  vb.watchdog_flag = false;
  vb.commanded.fill(false);  // every channel at -5 V until its group's first command
}

void HardwareEmulator::Impl::runBoardTimers(double now) {
  for (auto& vb : valves_) {
    if (vb.state != NodeState::kOperational) continue;
    if (now - buses_[vb.bus].last_host_heartbeat >= kHostHeartbeatTimeout - kTimeEps) {
      goSafe(vb);
      continue;
    }
    for (int g = 0; g < vb.groups(); ++g) {
      const double since = now - vb.last_command[g];
      if (!vb.commanded[g] || since < kGroupWatchdog - kTimeEps) continue;
      goSafe(vb);
      vb.watchdog_flag = true;
      ++vb.watchdog_trips;
      const double ms = std::min(65535.0, std::round(since * 1000));
      sendFault(vb.node, FaultCode::kCommandTimeout, static_cast<std::uint8_t>(g * kValveChannelsPerFrame),
                static_cast<std::uint16_t>(ms), now);
      break;
    }
  }
}

void HardwareEmulator::Impl::updateSupplyValve() {
  const int index = valve_index_[0];
  const bool open = index >= 0 && valves_[index].state == NodeState::kOperational;
  if (open == supply_open_) return;
  if (open) {
    std::string why;
    supply_open_ = robot_->release(&why);  // refused only while the simulation's physics faults
  } else {
    robot_->estop();
    supply_open_ = false;
  }
}

void HardwareEmulator::Impl::applyVolts() {
  for (std::size_t i = 0; i < cylinders_; ++i) {
    const auto& ch = mapping_.cylinder[i];
    const ValveBoard& vb = valves_[valve_index_[ch.board]];
    const bool live = vb.state == NodeState::kOperational && vb.commanded[ch.channel / kValveChannelsPerFrame];
    volts_[i] = live ? vb.volts[ch.channel] : kExhaustVolts;
  }
  // In the safe state the simulation exhausts every valve itself (and would only count the
  // command as ignored).
  if (!robot_->safety().safe_state) robot_->commandValves({}, indices_, volts_);
}

void HardwareEmulator::Impl::updateStuck() {
  const Signals& s = robot_->sensed();
  for (std::size_t i = 0; i < cylinders_; ++i) {
    if (active_.stuck[i] && !stuck_was_[i]) {  // freeze what the board sent last
      stuck_pressure_[i] = std::isnan(pressure_sent_[i]) ? s.pressure[i] : pressure_sent_[i];
      stuck_length_[i] = std::isnan(length_sent_[i]) ? s.length[i] : length_sent_[i];
    }
    stuck_was_[i] = active_.stuck[i];
  }
}

// ---------------------------------------------------------------------------- sending

void HardwareEmulator::Impl::sendStreams(double t) {
  // Each stream on its own period of simulated time; at most once per step.
  const auto due = [t](double* next, double period) {
    if (std::isnan(*next)) *next = t;  // the first sample at the first step, then one per period
    if (t + kTimeEps < *next) return false;
    *next += period;
    if (*next <= t) *next = t + period;
    return true;
  };
  if (due(&next_joint_, joint_period_)) sendJoints(t);
  if (due(&next_touch_, touch_period_)) sendTouch(t);
  if (due(&next_sensor_, sensor_period_)) sendSensors(t);
  if (due(&next_heartbeat_, heartbeat_period_)) sendHeartbeats(t);
}

void HardwareEmulator::Impl::sendJoints(double t) {
  const std::uint8_t seq = joint_seq_++;  // the palm's sample counter: advances even when silent
  if (active_.silent_node[kPalmNode] || active_.silent_joints) return;
  const auto& sensed = robot_->sensed().joint_position;
  for (int g = 0; g < kGroupsPerBoard; ++g) {
    if (!(joint_groups_ & (1u << g))) continue;
    JointAnglesFrame f;
    f.first_joint = static_cast<std::uint8_t>(g * kPackedFields);
    f.seq = seq;
    for (int k = 0; k < kPackedFields; ++k) {
      const int j = joint_at_[g * kPackedFields + k];
      if (j < 0) {
        f.angles[k] = kNaN;
        continue;
      }
      const Affine& cal = calibration_.joint[j];
      const double physical = sensed[j];
      const double raw = cal.invert(physical);
      const double sent = clampTo(raw, -kJointRange, kJointRange);
      f.angles[k] = sent;
      joint_sent_[j] = sent == raw ? physical : cal.apply(sent);
    }
    CanFrame frame;
    encode(f, &frame);
    send(kPalmBus, frame, t);
  }
}

void HardwareEmulator::Impl::sendTouch(double t) {
  const std::uint8_t seq = touch_seq_++;
  if (active_.silent_node[kPalmNode] || active_.silent_touch) return;
  const auto& sensed = robot_->sensed().touch;
  const int n = static_cast<int>(touch_source_.size());
  for (int g = 0; g < kGroupsPerBoard; ++g) {
    if (!(touch_groups_ & (1u << g))) continue;
    TouchFrame f;
    f.first_sensor = static_cast<std::uint8_t>(g * kPackedFields);
    f.seq = seq;
    for (int k = 0; k < kPackedFields; ++k) {
      const int i = g * kPackedFields + k;
      f.forces[k] = i < n ? clampTo(sensed[touch_source_[i]], 0, kTouchRange) : kNaN;
      if (i < n) touch_sent_[i] = f.forces[k];
    }
    CanFrame frame;
    encode(f, &frame);
    send(kPalmBus, frame, t);
  }
}

void HardwareEmulator::Impl::sendSensors(double t) {
  const Signals& s = robot_->sensed();
  for (const SensorBoard& sb : sensors_) {
    const std::uint8_t seq = sensor_seq_[sb.board]++;  // the board's sample counter, shared by its streams
    if (active_.silent_node[sb.node]) continue;
    for (int kind = 0; kind < 2; ++kind) {
      const bool pressure = kind == 0;
      if (pressure ? active_.silent_pressure[sb.board] : active_.silent_length[sb.board]) continue;
      for (int g = 0; g < kGroupsPerBoard; ++g) {
        if (!(sb.groups & (1u << g))) continue;
        SensorFrame f;
        f.board = sb.board;
        f.kind = pressure ? SensorKind::kPressure : SensorKind::kLength;
        f.first_channel = static_cast<std::uint8_t>(g * kPackedFields);
        f.seq = seq;
        for (int k = 0; k < kPackedFields; ++k) {
          const int c = sb.cylinder[g * kPackedFields + k];
          if (c < 0) {
            f.values[k] = kNaN;
            continue;
          }
          const Affine& cal = pressure ? calibration_.pressure[c] : calibration_.length[c];
          const double physical = active_.stuck[c] ? (pressure ? stuck_pressure_[c] : stuck_length_[c])
                                                   : (pressure ? s.pressure[c] : s.length[c]);
          const double raw = cal.invert(physical);
          const double sent = clampTo(raw, 0, pressure ? kPressureRange : kLengthRange);
          f.values[k] = sent;
          (pressure ? pressure_sent_ : length_sent_)[c] = sent == raw ? physical : cal.apply(sent);
        }
        CanFrame frame;
        encode(f, &frame);
        send(sb.bus, frame, t);
      }
    }
    if (sb.supply && !active_.silent_supply[sb.board]) {
      const Affine& cal = calibration_.supply;
      const double raw = cal.invert(s.supply_pressure);
      SupplyFrame f;
      f.board = sb.board;
      f.seq = seq;
      f.pressure = clampTo(raw, 0, kPressureRange);
      supply_sent_ = f.pressure == raw ? s.supply_pressure : cal.apply(f.pressure);
      CanFrame frame;
      encode(f, &frame);
      send(sb.bus, frame, t);
    }
  }
}

std::uint8_t HardwareEmulator::Impl::flagsOf(std::uint8_t node) const {
  std::uint8_t flags = active_.button[node] ? kFlagEstopInput : 0;
  const int b = node - kValveBoardNodeBase;
  if (b >= 0 && b < kMaxBoards && valve_index_[b] >= 0) {
    if (valves_[valve_index_[b]].watchdog_flag) flags |= kFlagWatchdog;
    if (b == 0 && supply_open_) flags |= kFlagSupplyOpen;
  }
  return flags;
}

NodeState HardwareEmulator::Impl::stateOf(std::uint8_t node) const {
  const int b = node - kValveBoardNodeBase;
  if (b >= 0 && b < kMaxBoards && valve_index_[b] >= 0) return valves_[valve_index_[b]].state;
  return NodeState::kOperational;  // the palm and the sensor boards stream from boot
}

void HardwareEmulator::Impl::sendHeartbeats(double t) {
  for (int node = 1; node < kNodes; ++node) {
    if (node_bus_[node] < 0) continue;
    HeartbeatFrame f;
    f.node = static_cast<std::uint8_t>(node);
    f.state = stateOf(f.node);
    f.flags = flagsOf(f.node);
    f.seq = heartbeat_seq_[node]++;
    if (active_.silent_node[node]) continue;
    CanFrame frame;
    encode(f, &frame);
    send(node_bus_[node], frame, t);
  }
}

void HardwareEmulator::Impl::sendFault(std::uint8_t node, FaultCode code, std::uint8_t channel, std::uint16_t detail,
                                       double t) {
  ++faults_sent_[node];
  FaultFrame f;
  f.node = node;
  f.code = code;
  f.channel = channel;
  f.detail = detail;
  f.seq = fault_seq_[node]++;
  if (active_.silent_node[node]) return;
  CanFrame frame;
  if (encode(f, &frame).ok()) send(node_bus_[node], frame, t);
}

bool HardwareEmulator::Impl::sendEstop(std::uint8_t node, EstopCause cause, double t) {
  EstopFrame f;
  f.node = node;
  f.action = EstopAction::kEngage;
  f.cause = cause;
  f.seq = estop_seq_[node]++;
  if (active_.silent_node[node]) return false;
  CanFrame frame;
  encode(f, &frame);
  send(node_bus_[node], frame, t);
  return true;
}

// Every outgoing frame passes the injections of its bus: drop, corrupt, delay.
void HardwareEmulator::Impl::send(int bus, const CanFrame& frame, double t) {
  Bus& b = buses_[bus];
  if (!b.link || b.bus_off) return;
  if (active_.drop[bus] > 0 && uniform_(rng_) < active_.drop[bus]) {
    ++b.status.dropped;
    return;
  }
  CanFrame out = frame;
  if (active_.corrupt[bus] > 0 && uniform_(rng_) < active_.corrupt[bus]) {
    out = corruptFrame(frame, (rng_() & 1) != 0);
    ++b.status.corrupted;
  }
  const double delay = active_.delay[bus];
  if (delay > 0 || !b.ring.empty()) {  // behind frames still held back: keep the order
    if (!b.ring.push(t, out)) {
      ++b.status.delay_overflow;
      return;
    }
    if (delay > 0) ++b.status.delayed;
    return;
  }
  write(bus, out);
}

void HardwareEmulator::Impl::write(int bus, const CanFrame& frame) {
  Bus& b = buses_[bus];
  switch (b.link->write(frame)) {
    case IoStatus::kOk: ++b.status.frames_sent; break;
    case IoStatus::kFull: ++b.status.write_full; break;
    case IoStatus::kHangUp: closeLink(bus); break;
    default: ++b.status.write_errors; break;
  }
}

void HardwareEmulator::Impl::flushDelayed(double t) {
  for (int bus = 0; bus < static_cast<int>(buses_.size()); ++bus) {
    Bus& b = buses_[bus];
    while (b.link && !b.bus_off && b.ring.frontDue(t, active_.delay[bus])) write(bus, b.ring.pop());
  }
}

void HardwareEmulator::Impl::publish() {
  const Signals& truth = robot_->truth();
  std::lock_guard<PiMutex> lock(mutex_);
  EmulatorSnapshot& s = published_;
  s.clock = robot_->clock();
  s.steps = steps_;
  s.overruns = overruns_;
  s.joint = joint_sent_;
  s.touch = touch_sent_;
  s.pressure = pressure_sent_;
  s.length = length_sent_;
  s.supply_pressure = supply_sent_;
  s.truth_joint = truth.joint_position;
  s.truth_pressure = truth.pressure;
  s.truth_length = truth.length;
  s.volts = volts_;
  s.supply_open = supply_open_;
  s.object = robot_->sensed().object;
  const auto board = [this](BoardStatus* out) {
    out->state = stateOf(out->node);
    out->flags = flagsOf(out->node);
    out->faults_sent = faults_sent_[out->node];
  };
  board(&s.palm);
  for (std::size_t k = 0; k < valves_.size(); ++k) {
    board(&s.valve_boards[k]);
    s.valve_boards[k].watchdog_trips = valves_[k].watchdog_trips;
  }
  for (auto& sb : s.sensor_boards) board(&sb);
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    BusStatus& out = s.buses[b];
    out = buses_[b].status;  // the strings keep their storage: no allocation
    out.connected = buses_[b].link.has_value();
    out.bus_off = buses_[b].bus_off;
    out.drop_probability = active_.drop[b];
    out.corrupt_probability = active_.corrupt[b];
    out.delay = active_.delay[b];
  }
}

// ---------------------------------------------------------------------------- text and checks

void HardwareEmulator::Impl::checkBus(int bus) const {
  require(bus == kAllBuses || (bus >= 0 && bus < static_cast<int>(buses_.size())),
          "bus " + std::to_string(bus) + " does not exist (" + std::to_string(buses_.size()) + " buses)");
}

void HardwareEmulator::Impl::checkNode(std::uint8_t node) const {
  require(node < kNodes && node_bus_[node] >= 0, "node " + hex(node) + " is not a board of this robot");
}

int HardwareEmulator::Impl::parseBus(const std::string& text) const {
  if (text.empty() || text == "all") return kAllBuses;
  for (std::size_t b = 0; b < buses_.size(); ++b)
    if (buses_[b].name == text) return static_cast<int>(b);
  std::string names;
  for (const auto& b : buses_) names += (names.empty() ? "" : ", ") + b.name;
  throw std::invalid_argument("unknown bus '" + text + "': expected " + names + " or empty for every bus");
}

std::uint8_t HardwareEmulator::Impl::parseNode(const std::string& text) const {
  const std::string expected =
      "expected palm, valve board <n>, sensor board <n> or the number of one of this robot's nodes (e.g. 0x12)";
  const auto boardNumber = [&](const std::string& prefix, int* board) {
    if (text.rfind(prefix, 0) != 0) return false;
    const std::string rest = text.substr(prefix.size());
    if (rest.size() != 1 || rest[0] < '0' || rest[0] > '7') return false;
    *board = rest[0] - '0';
    return true;
  };
  int node = -1, board = 0;
  if (text == "palm") {
    node = kPalmNode;
  } else if (boardNumber("valve board ", &board)) {
    node = valveBoardNode(static_cast<std::uint8_t>(board));
  } else if (boardNumber("sensor board ", &board)) {
    node = sensorBoardNode(static_cast<std::uint8_t>(board));
  } else if (!text.empty() && std::isdigit(static_cast<unsigned char>(text[0]))) {
    try {
      std::size_t used = 0;
      const unsigned long n = std::stoul(text, &used, 0);
      if (used == text.size() && n < kNodes) node = static_cast<int>(n);
    } catch (const std::exception&) {
    }
  }
  if (node < 0) throw std::invalid_argument("unknown node '" + text + "': " + expected);
  if (node_bus_[node] < 0)
    throw std::invalid_argument("node '" + text + "' (" + nodeName(static_cast<std::uint8_t>(node)) +
                                ") is not a board of this robot: " + expected);
  return static_cast<std::uint8_t>(node);
}

SilenceTarget HardwareEmulator::Impl::parseSilence(const std::string& text) const {
  if (text == "joints") return {Stream::kJoints, kPalmNode};
  if (text == "touch") return {Stream::kTouch, kPalmNode};
  if (text == "supply") return {Stream::kSupply, mapping_.supply_board};
  for (const auto& [prefix, stream] : {std::pair<std::string, Stream>{"pressure board ", Stream::kPressure},
                                       std::pair<std::string, Stream>{"length board ", Stream::kLength}}) {
    if (text.rfind(prefix, 0) != 0) continue;
    const std::string rest = text.substr(prefix.size());
    const int board = rest.size() == 1 && rest[0] >= '0' && rest[0] <= '7' ? rest[0] - '0' : -1;
    if (board < 0 || sensor_index_[board] < 0)
      throw std::invalid_argument("'" + text + "': no such sensor board on this robot");
    return {stream, static_cast<std::uint8_t>(board)};
  }
  try {
    return {Stream::kNode, parseNode(text)};
  } catch (const std::invalid_argument&) {
    throw std::invalid_argument("unknown stream or node '" + text +
                                "': expected joints, touch, supply, pressure board <n>, length board <n>, palm, "
                                "valve board <n>, sensor board <n> or a node number");
  }
}

std::size_t HardwareEmulator::Impl::parseCylinder(const std::string& text) const {
  const auto& names = robot_->cylinderNames();
  const auto it = std::find(names.begin(), names.end(), text);
  if (it == names.end())
    throw std::invalid_argument("unknown cylinder '" + text + "': expected an actuator name such as " + names.front());
  return static_cast<std::size_t>(it - names.begin());
}

std::string HardwareEmulator::Impl::silenceName(const SilenceTarget& t) const {
  switch (t.stream) {
    case Stream::kNode: return nodeName(t.id);
    case Stream::kJoints: return "joints";
    case Stream::kTouch: return "touch";
    case Stream::kPressure: return "pressure board " + std::to_string(t.id);
    case Stream::kLength: return "length board " + std::to_string(t.id);
    case Stream::kSupply: return "supply";
  }
  return "?";
}

void HardwareEmulator::Impl::describeInjections(const Settings& s, std::vector<std::string>* out) const {
  for (std::size_t b = 0; b < buses_.size(); ++b) {
    const std::string& bus = buses_[b].name;
    if (s.drop[b] > 0) out->push_back("drop " + bus + " " + number(s.drop[b]));
    if (s.corrupt[b] > 0) out->push_back("corrupt " + bus + " " + number(s.corrupt[b]));
    if (s.delay[b] > 0) out->push_back("delay " + bus + " " + number(s.delay[b]) + " s");
  }
  for (std::size_t c = 0; c < s.stuck.size(); ++c)
    if (s.stuck[c]) out->push_back("stuck_sensor " + robot_->cylinderNames()[c]);
  for (int n = 0; n < kNodes; ++n) {
    if (s.silent_node[n]) out->push_back("silence " + nodeName(static_cast<std::uint8_t>(n)));
    if (s.button[n]) out->push_back("button " + nodeName(static_cast<std::uint8_t>(n)));
  }
  if (s.silent_joints) out->push_back("silence joints");
  if (s.silent_touch) out->push_back("silence touch");
  for (int b = 0; b < kMaxBoards; ++b) {
    if (s.silent_pressure[b]) out->push_back("silence pressure board " + std::to_string(b));
    if (s.silent_length[b]) out->push_back("silence length board " + std::to_string(b));
    if (s.silent_supply[b]) out->push_back("silence supply");
  }
}

// ============================================================================ HardwareEmulator

HardwareEmulator::HardwareEmulator(const EmulatorConfig& config) : impl_(std::make_unique<Impl>(config)) {}

HardwareEmulator::~HardwareEmulator() { stop(); }

void HardwareEmulator::setBusPaths(const std::vector<std::string>& paths) {
  if (impl_->started_ || impl_->stopped_) throw std::logic_error("setBusPaths() after start()");
  require(paths.size() == impl_->buses_.size(), "bus_paths: " + std::to_string(paths.size()) + " paths for " +
                                                    std::to_string(impl_->buses_.size()) + " buses");
  impl_->bus_paths_ = paths;
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  for (std::size_t b = 0; b < paths.size(); ++b) {
    impl_->buses_[b].path = impl_->buses_[b].status.path = paths[b];
    impl_->published_.buses[b].path = paths[b];
  }
}

void HardwareEmulator::setCalibration(const Calibration& calibration) {
  checkCalibration(calibration, impl_->joints_, impl_->cylinders_);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  impl_->new_calibration_ = calibration;
}

void HardwareEmulator::start() {
  Impl& m = *impl_;
  if (m.started_ || m.stopped_) throw std::logic_error("HardwareEmulator::start() called twice");
  for (auto& b : m.buses_) {
    std::string error;
    b.listener = listenSeqpacket(b.path, &error);
    if (!b.listener) {
      for (auto& other : m.buses_) other.listener.reset();  // removes the socket files made so far
      throw std::runtime_error("bus " + b.name + ": " + error);
    }
  }
  m.started_ = true;
  if (m.config_.realtime) m.thread_ = std::thread([&m] { m.run(); });
}

void HardwareEmulator::stop() {
  Impl& m = *impl_;
  m.stop_ = true;
  if (m.thread_.joinable()) m.thread_.join();
  for (auto& b : m.buses_) {
    b.link.reset();
    b.listener.reset();  // unlinks the socket file
  }
  if (m.started_) m.stopped_ = true;
  m.started_ = false;
}

bool HardwareEmulator::started() const { return impl_->started_; }

void HardwareEmulator::tick() {
  if (impl_->config_.realtime) throw std::logic_error("tick() is for realtime = false: the emulator's thread steps");
  if (!impl_->started_) throw std::logic_error("tick() before start()");
  impl_->tick();
}

const Mapping& HardwareEmulator::mapping() const { return impl_->mapping_; }
const std::vector<std::string>& HardwareEmulator::busPaths() const { return impl_->bus_paths_; }
const std::vector<std::string>& HardwareEmulator::jointNames() const { return impl_->robot_->jointNames(); }
const std::vector<std::string>& HardwareEmulator::cylinderNames() const { return impl_->robot_->cylinderNames(); }
bool HardwareEmulator::hasObject() const { return impl_->robot_->hasObject(); }
double HardwareEmulator::timestep() const { return impl_->robot_->timestep(); }

EmulatorSnapshot HardwareEmulator::snapshot() const {
  Settings settings;
  EmulatorSnapshot s;
  {
    std::lock_guard<PiMutex> lock(impl_->mutex_);
    s = impl_->published_;
    settings = impl_->settings_;
  }
  impl_->describeInjections(settings, &s.injections);
  for (const auto& b : s.buses)
    if (b.bus_off) s.injections.push_back("bus_off " + b.name + " (until the host reconnects)");
  for (const auto& vb : s.valve_boards)
    if (vb.state == NodeState::kFault) s.injections.push_back("board_fault " + nodeName(vb.node));
  return s;
}

void HardwareEmulator::setDropProbability(double probability, int bus) {
  checkProbability(probability, "drop probability");
  impl_->checkBus(bus);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  auto& v = impl_->settings_.drop;
  if (bus == kAllBuses) std::fill(v.begin(), v.end(), probability); else v[bus] = probability;
}

void HardwareEmulator::setCorruptProbability(double probability, int bus) {
  checkProbability(probability, "corrupt probability");
  impl_->checkBus(bus);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  auto& v = impl_->settings_.corrupt;
  if (bus == kAllBuses) std::fill(v.begin(), v.end(), probability); else v[bus] = probability;
}

void HardwareEmulator::setDelay(double seconds, int bus) {
  checkDelay(seconds);
  impl_->checkBus(bus);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  auto& v = impl_->settings_.delay;
  if (bus == kAllBuses) std::fill(v.begin(), v.end(), seconds); else v[bus] = seconds;
}

void HardwareEmulator::setStuckSensor(std::size_t cylinder, bool stuck) {
  require(cylinder < impl_->cylinders_, "cylinder " + std::to_string(cylinder) + " does not exist");
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  impl_->settings_.stuck[cylinder] = stuck;
}

void HardwareEmulator::setSilenced(const SilenceTarget& target, bool silenced) {
  Impl& m = *impl_;
  const bool board_ok = target.id < kMaxBoards && m.sensor_index_[target.id] >= 0;
  switch (target.stream) {
    case Stream::kNode: m.checkNode(target.id); break;
    case Stream::kJoints:
    case Stream::kTouch: break;
    case Stream::kPressure:
    case Stream::kLength: require(board_ok, "sensor board " + std::to_string(target.id) + " does not exist"); break;
    case Stream::kSupply:
      require(board_ok && m.sensors_[m.sensor_index_[target.id]].supply,
              "sensor board " + std::to_string(target.id) + " does not read the supply");
      break;
  }
  std::lock_guard<PiMutex> lock(m.mutex_);
  Settings& s = m.settings_;
  switch (target.stream) {
    case Stream::kNode: s.silent_node[target.id] = silenced; break;
    case Stream::kJoints: s.silent_joints = silenced; break;
    case Stream::kTouch: s.silent_touch = silenced; break;
    case Stream::kPressure: s.silent_pressure[target.id] = silenced; break;
    case Stream::kLength: s.silent_length[target.id] = silenced; break;
    case Stream::kSupply: s.silent_supply[target.id] = silenced; break;
  }
}

void HardwareEmulator::busOff(int bus) {
  impl_->checkBus(bus);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  impl_->pending_.push_back({ActionKind::kBusOff, bus});
}

void HardwareEmulator::disconnect(int bus) {
  impl_->checkBus(bus);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  impl_->pending_.push_back({ActionKind::kDisconnect, bus});
}

void HardwareEmulator::boardFault(std::uint8_t node, FaultCode code) {
  impl_->checkNode(node);
  const auto c = static_cast<int>(code);
  require(c >= static_cast<int>(FaultCode::kCommandTimeout) && c <= static_cast<int>(FaultCode::kInternal),
          "fault code must be in [1, 8], got " + std::to_string(c));
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  impl_->pending_.push_back({ActionKind::kBoardFault, kAllBuses, node, code});
}

void HardwareEmulator::setButton(std::uint8_t node, bool held) {
  impl_->checkNode(node);
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  impl_->settings_.button[node] = held;
}

void HardwareEmulator::clearFaults() {
  std::lock_guard<PiMutex> lock(impl_->mutex_);
  Settings& s = impl_->settings_;
  const std::size_t buses = s.drop.size(), cylinders = s.stuck.size();
  s = Settings{};
  s.drop.assign(buses, 0);
  s.corrupt.assign(buses, 0);
  s.delay.assign(buses, 0);
  s.stuck.assign(cylinders, 0);
  impl_->pending_.push_back({ActionKind::kPowerCycle});
}

bool HardwareEmulator::placeObject(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                                   const std::array<double, 3>& linear, const std::array<double, 3>& angular,
                                   std::string* error, double timeout) {
  Impl& m = *impl_;
  std::unique_lock<PiMutex> lock(m.mutex_);
  const std::uint64_t id = ++m.placements_requested_;
  const Impl::Placement placement{position, linear, angular, quaternion, id};
  if (!m.thread_.joinable()) {  // nobody else steps: apply it here
    lock.unlock();
    m.placing_ = placement;
    m.placeObject();
    lock.lock();
  } else {
    m.placement_ = placement;  // a newer request replaces one the thread has not taken yet
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout);
    if (!m.placed_.wait_until(lock, deadline, [&] { return m.placements_done_ >= id; })) {
      if (m.placement_ && m.placement_->id == id) m.placement_.reset();  // not later, unasked
      if (error) *error = "the emulator's simulation did not step within " + std::to_string(timeout) + " s";
      return false;
    }
  }
  if (m.placements_done_ != id) {
    if (error) *error = "replaced by a newer placement before it was applied";
    return false;
  }
  if (!m.placement_error_.empty()) {
    if (error) *error = m.placement_error_;
    return false;
  }
  return true;
}

bool HardwareEmulator::inject(const std::string& fault, const std::string& target, double value,
                              std::string* message) {
  Impl& m = *impl_;
  std::string text;
  try {
    require(std::isfinite(value), "value must be finite");
    const auto busText = [&](int bus) { return bus == kAllBuses ? std::string("every bus") : m.buses_[bus].name; };
    if (fault == "drop") {
      const int bus = m.parseBus(target);
      setDropProbability(value, bus);
      text = "dropping outgoing frames on " + busText(bus) + " with probability " + number(value);
    } else if (fault == "corrupt") {
      const int bus = m.parseBus(target);
      setCorruptProbability(value, bus);
      text = "corrupting outgoing frames on " + busText(bus) + " with probability " + number(value);
    } else if (fault == "delay") {
      const int bus = m.parseBus(target);
      setDelay(value, bus);
      text = "delaying outgoing frames on " + busText(bus) + " by " + number(value) + " s";
    } else if (fault == "stuck_sensor") {
      const std::size_t c = m.parseCylinder(target);
      setStuckSensor(c, value >= 0);
      text = (value >= 0 ? "stuck: pressure and length of " : "unstuck: pressure and length of ") + target;
    } else if (fault == "silence") {
      const SilenceTarget t = m.parseSilence(target);
      setSilenced(t, value >= 0);
      text = (value >= 0 ? "silenced: " : "sending again: ") + m.silenceName(t);
    } else if (fault == "bus_off") {
      const int bus = m.parseBus(target);
      busOff(bus);
      text = "bus-off on " + busText(bus) + " until the host reconnects";
    } else if (fault == "disconnect") {
      const int bus = m.parseBus(target);
      disconnect(bus);
      text = "closing the host's connection on " + busText(bus);
    } else if (fault == "board_fault") {
      const std::uint8_t node = m.parseNode(target);
      require(value >= 0 && value <= 8 && value == std::floor(value), "value must be a fault code 1..8 (0: internal)");
      const auto code = value == 0 ? FaultCode::kInternal : static_cast<FaultCode>(static_cast<int>(value));
      boardFault(node, code);
      text = nodeName(node) + " reports fault " + std::to_string(static_cast<int>(code)) +
             (m.valveBoardOfNode(node) ? " and goes to the fault state" : "");
    } else if (fault == "button") {
      const std::uint8_t node = m.parseNode(target);
      setButton(node, value != 0);
      text = "e-stop input of " + nodeName(node) + (value != 0 ? " held" : " released");
    } else if (fault == "clear") {
      clearFaults();
      text = "every injection off";
    } else {
      throw std::invalid_argument("unknown fault '" + fault +
                                  "': expected drop, corrupt, delay, stuck_sensor, silence, bus_off, disconnect, "
                                  "board_fault, button or clear");
    }
  } catch (const std::invalid_argument& e) {
    if (message) *message = e.what();
    return false;
  }
  if (message) *message = text;
  return true;
}

int HardwareEmulator::realtimeScheduling() const { return impl_->fifo_.load(); }

}  // namespace adroit::driver::can
