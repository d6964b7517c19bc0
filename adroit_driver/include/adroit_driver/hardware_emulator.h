// The robot's electronics on emulated CAN buses, played from the simulation (MuJoCo + the
// pneumatic plant): the palm MCU, every valve board and every sensor board of
// docs/can_protocol.md, each on its bus, with the boards' state machines of section 8 (boot
// safe, release, the 50 ms group watchdog, the 300 ms host heartbeat timeout, e-stop, the
// supply valve on valve board 0) and fault injection for testing the host (CanRobot).
// Each bus is a Unix seqpacket path the host connects to ("unix:<path>", section 11).
// ROS-free: the node adroit_can_emulator (nodes/emulator_node.cpp) is a thin wrapper.
//
// Threads: with `realtime` the emulator runs its own thread that steps the simulation on the
// wall clock; without it the caller advances one step per tick() (deterministic tests).
// snapshot(), the fault-injection setters and setCalibration() may be called from any thread.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "adroit_driver/can_mapping.h"
#include "adroit_driver/can_protocol.h"
#include "adroit_driver/sim_config.h"

namespace adroit::driver::can {

constexpr int kAllBuses = -1;          // fault-injection setters: every bus
constexpr double kMaxInjectedDelay = 1.0;  // s: the delay ring holds this much traffic

// Injections active from start-up (every bus); the setters below change them at run time.
struct FaultInjection {
  double drop_probability = 0;     // an outgoing frame is lost
  double corrupt_probability = 0;  // an outgoing frame is altered so that a strict decoder rejects it
  double delay = 0;                // s, outgoing frames are held back, in [0, kMaxInjectedDelay]
};

struct EmulatorConfig {
  SimConfig sim;                        // pneumatic mode; sensor realism as configured
  std::vector<std::string> bus_paths;   // one listening path per Mapping bus, in Mapping::buses order;
                                        // empty: defaultBusPath() of each
  std::optional<Mapping> mapping;       // default: defaultMapping of the simulated robot's names
  std::optional<Calibration> calibration;  // default: identity (the boards send physical values)
  double joint_rate = 500;              // Hz, palm joint angles
  double touch_rate = 250;              // Hz, palm touch
  double sensor_rate = 250;             // Hz, pressures, lengths and supply of every sensor board
  double heartbeat_rate = 10;           // Hz, every node
  bool realtime = true;                 // false: no thread, the caller steps with tick()
  // SCHED_FIFO priority of the emulator's thread (0: normal scheduling). The boards it plays
  // keep their rates on their own processors; on a shared machine only a real-time thread
  // does (a joint stream 3 periods late is a fault for the driver).
  int realtime_priority = 0;
  std::uint64_t seed = 1;               // fault-injection randomness (drop, corrupt)
  FaultInjection faults;
};

// "/tmp/adroit_can_<bus>": the driver's default "unix:" endpoint of each bus.
std::string defaultBusPath(const std::string& bus);

// Silencing: a whole node, or one stream of a node.
enum class Stream : std::uint8_t { kNode, kJoints, kTouch, kPressure, kLength, kSupply };
struct SilenceTarget {
  Stream stream = Stream::kNode;
  std::uint8_t id = 0;  // kNode: the node number; kPressure/kLength/kSupply: the sensor board
};

struct BoardStatus {
  std::uint8_t node = 0;
  int bus = 0;                        // index into Mapping::buses
  NodeState state = NodeState::kBoot;
  std::uint8_t flags = 0;             // as in its heartbeat (kFlag*)
  std::uint64_t watchdog_trips = 0;   // valve boards: group watchdog trips
  std::uint64_t faults_sent = 0;      // fault frames
};

struct BusStatus {
  std::string name, path;
  bool connected = false;             // a host is connected
  bool bus_off = false;               // injected bus-off: the connection is ignored until the host reconnects
  std::uint64_t connections = 0;      // accepted (a new one replaces the old)
  std::uint64_t frames_sent = 0;      // written to the host
  std::uint64_t frames_received = 0;  // data frames from the host
  std::uint64_t bad_frames = 0;       // rejected by the strict decoder, or not a frame a host sends
  std::uint64_t bad_datagrams = 0;    // not one 16-byte frame, dlc > 8, or an error frame
  std::uint64_t ignored = 0;          // frames read and dropped while bus-off
  std::uint64_t dropped = 0, corrupted = 0, delayed = 0;  // by injection
  std::uint64_t delay_overflow = 0;   // frames lost because the delay ring was full
  std::uint64_t write_full = 0;       // not sent: the host's socket buffer was full
  std::uint64_t write_errors = 0;
  double drop_probability = 0, corrupt_probability = 0, delay = 0;  // current injections
};

struct EmulatorSnapshot {
  double clock = 0;          // s of simulated time
  std::uint64_t steps = 0;
  std::uint64_t overruns = 0;  // real time: steps started more than 50 ms late (the pacing restarted)
  // The physical values last sent (what was encoded, clamped to the frame's range, before the
  // calibration inversion); NaN before the first frame.
  std::vector<double> joint;     // rad, per robot joint (jointNames())
  std::vector<double> touch;     // N, per Mapping::touch
  std::vector<double> pressure;  // Pa absolute, per cylinder (cylinderNames())
  std::vector<double> length;    // m, per cylinder
  double supply_pressure = std::numeric_limits<double>::quiet_NaN();
  // The simulation's truth.
  std::vector<double> truth_joint, truth_pressure, truth_length;
  std::vector<double> volts;     // applied per cylinder by its valve board (-5 V when not operational)
  bool supply_open = false;      // valve board 0 operational
  // The free object as a motion-capture system would report it (sensed: noise, delay);
  // position, quaternion w x y z, linear velocity (world), angular velocity (object frame).
  bool has_object = false;
  std::array<double, 13> object{};
  BoardStatus palm;
  std::vector<BoardStatus> valve_boards, sensor_boards;  // board number order
  std::vector<BusStatus> buses;                          // Mapping::buses order
  std::vector<std::string> injections;                   // active injections, one line each
};

class HardwareEmulator {
 public:
  // Builds the simulation and the boards. Throws std::invalid_argument naming what is wrong
  // (force mode, a mapping or calibration that does not fit the model, a bad rate...) or the
  // simulation's ModelLoadError.
  explicit HardwareEmulator(const EmulatorConfig& config);
  ~HardwareEmulator();  // stop()
  HardwareEmulator(const HardwareEmulator&) = delete;
  HardwareEmulator& operator=(const HardwareEmulator&) = delete;

  // Before start(): one path per bus (std::invalid_argument otherwise).
  void setBusPaths(const std::vector<std::string>& paths);
  // Any time: the sensors' calibration errors the boards reproduce (sizes of the model;
  // finite, non-zero gains). Throws std::invalid_argument.
  void setCalibration(const Calibration& calibration);

  // Listens on every bus path and, in real time, starts the thread. Throws std::runtime_error
  // with one line when a path cannot be listened on. Once.
  void start();
  // Stops the thread, closes the connections and removes the socket files. Idempotent.
  void stop();
  bool started() const;
  // realtime = false: one simulation step with everything that goes with it (accept, read the
  // host's frames, boards, step, send what is due). std::logic_error in real time or before start().
  void tick();

  // Constant after construction.
  const Mapping& mapping() const;
  const std::vector<std::string>& busPaths() const;
  const std::vector<std::string>& jointNames() const;
  const std::vector<std::string>& cylinderNames() const;
  bool hasObject() const;
  double timestep() const;

  EmulatorSnapshot snapshot() const;
  // The thread's scheduling: 1 SCHED_FIFO at config.realtime_priority, -1 refused (normal
  // scheduling), 0 not asked for (priority 0, no thread) or not yet started.
  int realtimeScheduling() const;

  // Fault injection; effective from the next step. std::invalid_argument on a bad argument.
  void setDropProbability(double probability, int bus = kAllBuses);
  void setCorruptProbability(double probability, int bus = kAllBuses);
  void setDelay(double seconds, int bus = kAllBuses);
  void setStuckSensor(std::size_t cylinder, bool stuck);  // pressure and length keep their last values
  void setSilenced(const SilenceTarget& target, bool silenced);
  // An error frame of class bus-off to the host, then no frames either way until it reconnects;
  // the valve boards of that bus go safe (their own bus-off).
  void busOff(int bus = kAllBuses);
  void disconnect(int bus = kAllBuses);  // closes the connection: the host sees a hang-up
  // The node sends a fault frame; a valve board goes to the fault state (until clearFaults()).
  void boardFault(std::uint8_t node, FaultCode code);
  // The node's e-stop input: pressing sends e-stop engage (cause button) on its bus and makes
  // the valve boards there safe; heartbeat flag bit 0 while held; a held input refuses release.
  void setButton(std::uint8_t node, bool held);
  // Every injection off: no drop, corruption, delay, stuck sensor, silence or held button, and
  // boards in the fault state restart (power cycle: safe until the host's release). A bus-off
  // connection stays ignored until the host reconnects.
  void clearFaults();

  // The lab's hand placing the object (a person on the real robot; demos and tests here): the
  // free object's world pose (quaternion w x y z) and velocity, checked and applied as
  // SimulatedRobot::setObjectPose does, by the stepping thread before its next step. In real
  // time it waits for that step (at most `timeout` seconds) and returns its verdict; with
  // realtime = false, or before start(), it applies at once (from the thread that calls tick()).
  // False with a one-line reason: no object in the scene, a bad pose or velocity, no step in time.
  bool placeObject(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                   const std::array<double, 3>& linear, const std::array<double, 3>& angular, std::string* error,
                   double timeout = 0.5);

  // The same by text, as the node's service takes them (adroit_msgs/InjectFault): fault is
  // drop | corrupt | delay | stuck_sensor | silence | bus_off | disconnect | board_fault |
  // button | clear. Targets: a bus name ("" = every bus), a cylinder name, a node ("palm",
  // "valve board 2", "sensor board 1", or a number such as "0x12"), a stream ("joints",
  // "touch", "supply", "pressure board 2", "length board 2"). value: probability, seconds,
  // button 1 held / 0 released, fault code 1..8 (0: internal), stuck_sensor/silence < 0 undo.
  // Returns false with a one-line reason for an unknown fault or target or a bad value.
  bool inject(const std::string& fault, const std::string& target, double value, std::string* message);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace adroit::driver::can
