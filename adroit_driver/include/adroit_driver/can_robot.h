// The ADROIT hardware as a Robot (robot.h), ROS-free: the palm MCU, the valve boards and the
// sensor boards over CAN (docs/can_protocol.md). Seen from the driver's ROS wrapper it
// behaves like SimulatedRobot: the same commands, host watchdog, e-stop latch, release and
// counters; in addition its faults come from the buses, the streams and the boards.
//
// One step(): take every frame that arrived on every bus (without waiting), decode and
// check it, update the sensed signals with the calibration applied, run the safety checks,
// then send what is due (host heartbeats every 100 ms; the valve cycle every control_period;
// while latched, e-stop engage every 100 ms instead of valve commands). Allocation-free after
// construction, except the one text formatted when a fault enters its latch.
//
// Threads: as robot.h. waitForInput() only polls the buses' descriptors (read atomically),
// so it runs without the robot lock while step()/recover() run under it.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "adroit_core/model_tables.h"
#include "adroit_core/mujoco_model.h"
#include "adroit_driver/can_mapping.h"
#include "adroit_driver/can_protocol.h"
#include "adroit_driver/can_transport.h"
#include "adroit_driver/robot.h"

namespace adroit::driver {

// Opens one bus given its endpoint ("can0", "unix:<path>"): nullopt and one line in *error on
// failure. The default is can::openBus; tests hand in socketpair ends.
using BusOpener = std::function<std::optional<can::CanTransport>(const std::string& endpoint, std::string* error)>;

// Every field has the name of the ROS parameter that sets it (config/hardware.yaml), so
// validation errors name the parameter to fix.
struct CanRobotConfig {
  std::string model_path;             // ~scene (or ~model_file): an MJCF of adroit_description
  std::vector<std::string> buses;     // ~buses/<name>: one endpoint per mapping bus, in mapping order
  std::optional<can::Mapping> mapping;          // nullopt: can::defaultMapping of the model
  std::optional<can::Calibration> calibration;  // nullopt: identity (~calibration_file: loadCalibration)
  double timestep = 0.001;            // ~timestep, s: the wrapper steps at least this often
  double control_period = 0.005;      // ~control_period, s, in [0.004, 0.01]: the valve cycle (200 Hz)
  double watchdog_timeout = 0.05;     // ~watchdog_timeout, s, in [0.01, 0.2]: as the simulation's
  double startup_timeout = 2.0;       // ~startup_timeout, s: for every node's heartbeat and stream
  bool start_in_safe_state = false;   // ~start_in_safe_state: no start-up release (e-stop latched)
  double joint_velocity_cutoff = 50.0;  // ~joint_velocity_cutoff, Hz: low-pass of the joint angles' difference
  double length_rate_cutoff = 40.0;     // ~length_rate_cutoff, Hz: low-pass of the piston lengths' difference
  double supply_pressure = 620e3;     // ~supply_pressure, Pa absolute, nominal (markers' scale)
  // Sampling periods of the streams (protocol: joints 500 Hz; touch, pressure, length, supply
  // 250 Hz). A stream is silent (a fault) after 3 periods without a frame; the sequence
  // counter's step times the period is the time between two samples (velocity estimates).
  double joint_period = 0.002;        // ~joint_period, s
  double sensor_period = 0.004;       // ~sensor_period, s
  // ~silent_periods, in [3, 20]: a stream silent this many periods is a fault. 3 on the robot
  // (the boards' MCUs keep their rates). Boards played by a process on the same machine
  // (adroit_can_emulator) share its scheduling stalls (7-9 ms seen on this VM, more than 3
  // joint periods), so hardware.launch emulate:=true allows more.
  int silent_periods = 3;
  BusOpener open_bus;                 // empty: can::openBus (construction and recover())
  std::function<double()> now;        // empty: std::chrono::steady_clock, in seconds
};

// Empty when valid (before the model is loaded: what does not need it), else one line naming
// the offending parameter, e.g. "~control_period must be in [0.004, 0.01] s, got 0.5".
std::string validate(const CanRobotConfig& config);

// Fixed by protocol version 1.
constexpr double kHeartbeatPeriod = 0.1;   // s, host heartbeats (and the e-stop repeat while latched)
constexpr double kHeartbeatTimeout = 0.3;  // s, a node's heartbeat missing this long is a fault
// A valve group is sent at most this often (500 Hz): a controller's commands at the sensor rate
// (the pools, 250 Hz) go out at once; a flood cannot take the bus (docs: bus load).
constexpr double kMinGroupInterval = 0.002;  // s

class CanRobot final : public Robot {
 public:
  // Loads the model, opens every bus, waits up to startup_timeout for every configured node's
  // heartbeat (version 1) and every mapped stream, then sends the start-up release (docs
  // section 9). Throws std::invalid_argument (configuration, mapping, calibration),
  // adroit::ModelLoadError, or std::runtime_error naming the bus that cannot be opened, the
  // nodes and streams not heard within startup_timeout, or a node of another protocol version.
  explicit CanRobot(CanRobotConfig config);
  ~CanRobot() override;

  // --- commands ---
  CheckedCommand checkValves(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                             const std::vector<double>& volts) const override;
  // The hardware has valves only: always rejected (counted as the wrong mode).
  CheckedCommand checkForces(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                             const std::vector<double>& newtons) const override;
  // Counts and stores as SimulatedRobot, and sends the affected groups at once (a group sent
  // less than kMinGroupInterval ago goes out as soon as that much time has passed).
  CommandResult applyValves(const CheckedCommand& checked) override;
  CommandResult applyForces(const CheckedCommand& checked) override;

  // --- one cycle ---
  void step() override;
  bool waitForInput(double seconds) override;
  bool drivenByInput() const override { return true; }
  unsigned takeFresh() override;

  // --- safety ---
  void estop() override;
  void setEstopInput(bool held) override;
  bool release(std::string* why) override;
  bool recover(std::string* why) override;
  const SafetyStatus& safety() const override { return safety_; }
  const Counters& counters() const override { return counters_; }
  const SafetyEvents& safetyEvents() const override { return events_; }
  // SafetyEvent of this robot: e-stop: index = the node whose button or e-stop frame caused it
  // (0 = the host's own input), -1 = operator. Fault: index = bus (kBus), stream identifier
  // (kStream: the CAN identifier of the stream, e.g. 0x150 = pressure of sensor board 2,
  // channels 0..3), node number (kHeartbeat, kBoard); cylinder = the cylinder concerned, if any.
  std::string describe(const SafetyEvent& event) const override;
  std::size_t neverCommanded() const override { return never_commanded_; }
  double takeCommandAgeMax() override { return std::exchange(command_age_max_, 0.0); }
  bool everCommanded(std::size_t cylinder) const override { return last_command_clock_[cylinder] != kNeverCommanded; }

  bool simulated() const override { return false; }

  // --- outputs ---
  const Signals& sensed() const override { return sensed_; }
  const Signals& truth() const override { return sensed_; }
  const std::vector<double>& appliedCommand() const override { return applied_command_; }

  // --- model and configuration ---
  double clock() const override;
  double timestep() const override { return config_.timestep; }
  ActuationMode mode() const override { return ActuationMode::kPneumatic; }
  double watchdogTimeout() const override { return config_.watchdog_timeout; }
  double supplyPressure() const override { return config_.supply_pressure; }
  const std::string& modelPath() const override { return config_.model_path; }
  const mjModel* model() const override { return model_.get(); }
  const mjData* data() const override { return data_.get(); }
  const std::vector<std::string>& jointNames() const override { return joint_names_; }
  const std::vector<std::string>& cylinderNames() const override { return actuators_.names(); }
  const std::vector<description::Cylinder>& cylinders() const override { return cylinders_; }
  // The touch sensors the palm reads (mapping.touch), a subset of the model's.
  const std::vector<std::string>& touchNames() const override { return mapping_.touch; }
  void addDiagnostics(DiagnosticValues* values) const override;

  const CanRobotConfig& config() const { return config_; }
  const can::Mapping& mapping() const { return mapping_; }
  const can::Calibration& calibration() const { return calibration_; }

 private:
  static constexpr double kNeverCommanded = -std::numeric_limits<double>::infinity();
  static constexpr double kNever = -std::numeric_limits<double>::infinity();

  // Why a bus is down (kUp: it is not).
  enum class BusDown : std::uint8_t { kUp, kHungUp, kBusOff, kWriteError, kReadError };
  struct Bus {
    std::string name, endpoint;
    std::optional<can::CanTransport> transport;
    BusDown down = BusDown::kUp;
    int error = 0;  // errno of a write or read error
    std::uint8_t heartbeat_seq = 0, estop_seq = 0;
    can::TransportCounters previous;  // summed counters of the transports replaced by recover()
    std::array<std::uint64_t, static_cast<int>(can::DecodeError::kBadVersion) + 1> decode_errors{};  // by error
    std::uint64_t unexpected = 0;  // valid frames nobody here should send (unmapped, other bus, host ids)
    std::uint64_t recoveries = 0;
    bool reported = false;  // its being down has been latched as a fault
  };
  // One received stream: one CAN identifier of a palm or sensor board data frame.
  struct Stream {
    std::uint32_t id = 0;
    int bus = 0;
    can::FrameType type = can::FrameType::kUnknown;
    int sample = -1;        // index into samples_
    std::uint32_t bit = 0;  // this stream's bit in its sample's mask
    double period = 0;
    double last = kNever;   // clock of the last accepted frame
    can::SequenceTracker sequence;
    std::array<double, can::kPackedFields> values{};  // latest accepted (supply: values[0])
    std::uint8_t no_reading = 0;  // bit k: mapped field k was "no reading" in the last sample
  };
  // One sample set assembled from several streams with one sequence number: the palm's joint
  // groups, its touch groups, or one sensor board's pressure, length (and supply) frames.
  enum class SampleKind : std::uint8_t { kJoints, kTouch, kBoard };
  struct Sample {
    SampleKind kind = SampleKind::kJoints;
    int bus = 0;
    std::uint8_t board = 0;
    std::uint32_t full = 0, mask = 0;  // streams of the set; streams seen with `seq`
    std::uint8_t seq = 0;
    bool collecting = false;
    bool have_previous = false;  // a complete sample before (finite differences)
    std::uint8_t previous_seq = 0;
    std::uint64_t complete = 0;  // complete samples so far
    bool fresh = false;          // complete since the last takeFresh()
    std::vector<int> cylinders;  // kBoard: the cylinders the board reads
    bool supply = false;         // kBoard: it reads the supply pressure too
  };
  struct Node {
    bool expected = false;
    int bus = -1;
    double last_heartbeat = kNever;
    can::NodeState state = can::NodeState::kBoot;
    std::uint8_t flags = 0;
    int bad_version = -1;           // the version of its last heartbeat if not ours
    bool button_held = false;       // e-stop frame (button) or heartbeat flag
    bool commanded = false;         // valve board: a group sent since the last release
    double first_command = kNever;  // valve board: when that was
    can::SequenceTracker heartbeats;
    std::uint64_t faults_reported = 0;
  };
  struct ValveGroup {
    int bus = 0;
    std::uint8_t board = 0, group = 0, count = 0;
    std::array<int, can::kValveChannelsPerFrame> cylinder{{-1, -1, -1}};
    bool commanded = false;  // a channel commanded since start / release
    bool pending = false;    // a new command waits for the minimum interval
    double last_sent = kNever;
    std::uint8_t seq = 0;
  };
  // What a fault event was about beyond SafetyEvent's fields, kept for describe().
  enum class FaultKind : std::uint8_t {
    kNone, kBusHungUp, kBusOff, kBusWriteError, kBusReadError, kStreamSilent, kNoReading, kHeartbeatMissing,
    kBadVersion, kFaultFrame, kBoardSafe, kNodeFault
  };
  struct FaultDetail {
    std::uint64_t sequence = 0;
    FaultKind kind = FaultKind::kNone;
    int code = 0;      // fault frame code, errno, the version seen, the node state; no reading: the joint
    int channel = -1;  // fault frame channel, the node's flags; no reading: the field (0..3)
    double value = 0;  // seconds silent / missing; fault frame detail
  };

  void startUp();
  void openBuses();
  void buildTables();

  // Receiving.
  void receive(double t);
  void handleFrame(int bus, const can::CanFrame& frame, double t);
  void handleData(int bus, int stream, const can::CanFrame& frame, double t);
  void handleHeartbeat(int bus, const can::CanFrame& frame, double t);
  void completeSample(int sample);
  void applyJoints(Sample& s);
  void applyTouch(Sample& s);
  void applyBoard(Sample& s);

  // Safety.
  void checkSafety(double t);
  std::string persistingCause() const;  // empty when none (allocates: release() only)
  bool streamSilent(const Stream& s, double t) const { return t - s.last > config_.silent_periods * s.period + 1e-9; }
  void discountStall(double t);  // a stall of this thread is not silence of the buses
  double last_step_ = kNever;
  std::uint64_t stalls_discounted_ = 0;
  bool heartbeatMissing(const Node& n, double t) const { return t - n.last_heartbeat > kHeartbeatTimeout + 1e-9; }
  void enterSafeState(SafeCause cause, can::EstopCause estop_cause, int index = -1, int cylinder = -1,
                      FaultSource source = FaultSource::kNone, const FaultDetail* detail = nullptr);
  void fault(FaultSource source, int index, int cylinder, const FaultDetail& detail);
  void noReading(const Stream& stream, int field, int cylinder, int joint);
  void checkNodeState(int node, double t);
  void markBusDown(int bus, BusDown why, int error);
  void latchBusFaults();
  std::string faultText(const SafetyEvent& event, const FaultDetail* detail) const;
  std::string streamName(std::uint32_t id) const;
  std::string nodeName(int node) const;
  std::string busName(int bus) const;

  // Sending.
  void sendDue(double t);
  void send(int bus, const can::CanFrame& frame);
  void sendHeartbeat(int bus);
  void sendHeartbeats();
  void sendEstop(int bus, can::EstopAction action, can::EstopCause cause);
  void sendEstops(can::EstopAction action, can::EstopCause cause);
  void sendGroup(int group, double t);
  CommandResult acceptCommand(const CheckedCommand& checked, double t);

  void updateKinematics(double t);

  CanRobotConfig config_;
  can::Mapping mapping_;
  can::Calibration calibration_;
  double origin_ = 0;  // now() at construction: clock() = now() - origin_

  ModelPtr model_;
  DataPtr data_;
  NameIndex actuators_;
  std::vector<description::Cylinder> cylinders_;
  std::vector<std::string> joint_names_;
  std::vector<int> joint_qpos_;
  ValueLimits valve_limits_;

  std::vector<Bus> buses_;
  std::unique_ptr<std::atomic<int>[]> poll_fds_;  // per bus, -1 while down: waitForInput()
  std::vector<Stream> streams_;
  std::array<std::int16_t, 0x800> stream_of_id_{};  // CAN identifier -> stream, -1 none
  std::vector<Sample> samples_;
  int joint_sample_ = -1, touch_sample_ = -1;
  std::array<Node, 64> nodes_{};
  std::vector<int> expected_nodes_;
  std::array<std::array<std::int16_t, can::kMaxSensorChannels>, can::kMaxBoards> cylinder_at_{};  // -1 none
  std::vector<ValveGroup> groups_;
  std::vector<int> group_of_cylinder_;  // index into groups_
  std::vector<int> touched_groups_;  // applyValves scratch (reserved)
  std::vector<can::CanFrame> rx_;    // receive buffer (sized once)

  // Per cylinder / joint: the sensed values' finite-difference state.
  std::vector<double> previous_length_, previous_joint_;

  double next_cycle_ = 0, next_heartbeat_ = 0, next_estop_repeat_ = 0;
  bool started_ = false;  // start-up done: from now on a bad heartbeat is a fault, not an error
  bool startup_release_sent_ = false;
  bool bus_news_ = false;  // a bus went down since latchBusFaults()
  bool kinematics_due_ = false;
  double last_kinematics_ = kNever;
  bool host_estop_input_ = false;
  can::EstopCause latched_cause_ = can::EstopCause::kOperator;
  std::uint64_t recover_calls_ = 0;

  std::vector<double> command_, applied_command_, last_command_clock_;
  std::size_t never_commanded_ = 0;
  double command_age_max_ = 0;  // takeCommandAgeMax
  Signals sensed_;
  SafetyStatus safety_;
  Counters counters_;
  SafetyEvents events_;

  // The details of the latest fault events, for describe() on other threads.
  mutable std::mutex details_mutex_;
  std::array<FaultDetail, 16> details_{};
};

}  // namespace adroit::driver
