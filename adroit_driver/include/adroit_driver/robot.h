// The robot interface of the driver, ROS-free: what the driver's ROS wrapper (one for the
// simulation and the hardware, so their ROS interface is the same by construction) needs
// from a robot. SimulatedRobot (MuJoCo + pneumatic plant) and CanRobot (the hardware over
// CAN) implement it.
//
// Threads: the wrapper calls every method with its robot lock held, except the const
// check*() (which read only what never changes) and waitForInput().
//
// Time: clock() is monotonic seconds since construction; it never goes back.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <mujoco/mujoco.h>

#include "adroit_description/cylinders.h"
#include "adroit_driver/command_check.h"
#include "adroit_driver/sensor_pipeline.h"
#include "adroit_driver/sim_config.h"

namespace adroit::driver {

enum class SafeCause { kNone = 0, kEstop = 1, kWatchdog = 2, kFault = 4 };

// Where a fault came from. Simulation: what a step found not finite (or, for qpos/qvel/qacc,
// also beyond MuJoCo's mjMAXVAL). Hardware: a bus, a stream or a board (SafetyEvent::index
// names the bus, stream or board; the robot's describe() says which).
enum class FaultSource {
  kNone, kQpos, kQvel, kQacc, kCommand, kPressure, kTension,
  kBus,        // bus-off, hang-up, or a write that failed (not for a full buffer)
  kStream,     // a sensor stream silent for 3 periods, or "no reading" where one is needed
  kHeartbeat,  // a node's heartbeat missing for 3 periods, or of another protocol version
  kBoard,      // a board reported a fault frame, or went safe on its own
};

// One safety event: an e-stop, a watchdog trip or a fault entering its latch. Plain data,
// recorded by the simulation thread without formatting anything; describe() turns it into
// text on whichever thread logs it.
struct SafetyEvent {
  std::uint64_t sequence = 0;  // Counters::safety_events right after this event; 0 = none yet
  SafeCause cause = SafeCause::kNone;
  double clock = 0;            // clock() when it happened (start of the step for step events)
  int cylinder = -1;           // watchdog: the stalest commanded cylinder; fault of a command,
                               // pressure or tension: that cylinder; else -1
  FaultSource fault = FaultSource::kNone;
  int index = -1;              // fault of qpos/qvel/qacc: the address in that array
};

// The latest event of each kind. Not cleared by release(): a logger that compares
// `last.sequence` with the one it saw last finds each event exactly once (events between
// two looks are counted by Counters::safety_events; only the latest of a kind is kept).
struct SafetyEvents {
  SafetyEvent last;      // any kind
  SafetyEvent estop;
  SafetyEvent watchdog;
  SafetyEvent fault;
};

struct SafetyStatus {
  bool safe_state = false;      // supply exhausted, every valve open to exhaust
  bool estop_latched = false;
  bool estop_input = false;     // the physical e-stop button is held
  bool watchdog_latched = false;
  bool fault_latched = false;
  bool fault_persists = false;  // the last physics step faulted
  bool watchdog_armed = false;  // a command has been received since start / release
  std::string fault;            // description of the fault that entered the latch
};

struct Counters {
  std::uint64_t steps = 0;
  std::uint64_t accepted = 0;
  std::uint64_t clamped = 0;
  std::uint64_t rejected_addressing = 0;  // both/neither, length mismatch, duplicates
  std::uint64_t rejected_name = 0;        // unknown names, indices out of range
  std::uint64_t rejected_not_finite = 0;
  std::uint64_t rejected_range = 0;
  std::uint64_t rejected_wrong_mode = 0;  // valve command in force mode or vice versa
  std::uint64_t ignored_while_safe = 0;   // valid commands ignored while latched
  std::uint64_t watchdog_trips = 0;
  std::uint64_t estops = 0;
  std::uint64_t faults = 0;               // fault events: entries into the fault latch (bad
                                          // qpos/qvel/qacc, non-finite command/pressure/tension)
  std::uint64_t faulted_steps = 0;        // physics steps refused while a fault persists
  std::uint64_t safety_events = 0;        // estops + watchdog_trips + faults: the sequence of SafetyEvent
  std::uint64_t rejected() const {
    return rejected_addressing + rejected_name + rejected_not_finite + rejected_range + rejected_wrong_mode;
  }
};

struct CommandResult {
  CommandVerdict verdict = CommandVerdict::kEmpty;
  bool applied = false;  // false when rejected or ignored while in the safe state
  std::string error;
};

// Counts a checked command as every robot does: a rejection by its reason, a valid command
// while the safe state holds as ignored (latched: commands are not acted on and do not feed
// the watchdog), else accepted (and clamped). `applied` in the result: the caller applies it.
CommandResult countCommand(const CheckedCommand& checked, bool safe_state, Counters* counters);

// Latches a safe-state entry as every robot does: the cause's flag and counter, safe_state,
// and the event (its cause, clock, cylinder, index and fault filled in by the robot) numbered
// and filed as the last event and under its cause. False, with nothing changed, for kNone
// and for a fault while a fault is latched (one event per entry into the latch, not per
// step); then the robot does nothing else either. The fault text is the robot's to write.
bool latchSafeState(SafetyEvent* event, SafetyStatus* safety, Counters* counters, SafetyEvents* events);

// One line of robot-specific diagnostics (key, value), e.g. per-bus frame counters.
using DiagnosticValues = std::vector<std::pair<std::string, std::string>>;

class Robot {
 public:
  virtual ~Robot() = default;

  // --- commands (addressing and validation: command_check.h) ---
  // check*() reads only what never changes (names, limits, mode): callable on any thread
  // without the robot lock. apply*() counts and applies (under the lock); it takes only
  // what check*() of this robot returned. Accepted commands allocate nothing.
  virtual CheckedCommand checkValves(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                                     const std::vector<double>& volts) const = 0;
  virtual CheckedCommand checkForces(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                                     const std::vector<double>& newtons) const = 0;
  virtual CommandResult applyValves(const CheckedCommand& checked) = 0;
  virtual CommandResult applyForces(const CheckedCommand& checked) = 0;

  // --- one cycle ---
  // Simulation: one physics step of timestep(). Hardware: take what arrived on the buses,
  // run the watchdogs, send what is due. Allocates nothing.
  virtual void step() = 0;
  // Hardware: wait (without the robot lock) until input arrives or `seconds` pass; returns
  // whether input arrived. The simulation has none: the wrapper paces it on the clock.
  virtual bool waitForInput(double seconds) { (void)seconds; return false; }
  // Whether the robot's sensor samples arrive on their own (hardware): the wrapper then
  // publishes each output when fresh() says a new sample is in, instead of every n steps.
  virtual bool drivenByInput() const { return false; }
  // Outputs with a new sample since the last call (bits of Output); clears them.
  enum Output : unsigned { kJoints = 1, kActuators = 2, kTouch = 4, kObject = 8 };
  virtual unsigned takeFresh() { return 0; }

  // --- safety (thesis 3.7: the safe state exhausts the supply and opens every valve to
  // exhaust) ---
  virtual void estop() = 0;                   // software e-stop: latch the safe state
  virtual void setEstopInput(bool held) = 0;  // the physical button; held latches the safe state
  // Leaves the safe state unless a cause persists; on refusal returns false and says why.
  virtual bool release(std::string* why) = 0;
  virtual const SafetyStatus& safety() const = 0;
  virtual const Counters& counters() const = 0;
  virtual const SafetyEvents& safetyEvents() const = 0;
  // One line for an event. Reads only what never changes: callable from any thread.
  virtual std::string describe(const SafetyEvent& event) const = 0;
  // Cylinders without an accepted command since start or the last release (unwatched).
  virtual std::size_t neverCommanded() const = 0;
  virtual bool everCommanded(std::size_t cylinder) const = 0;
  // The watchdog's margin: the largest age (s of the robot's clock) its stalest commanded
  // cylinder's command reached at a step since the last call, while armed and not safe (0 if
  // never). The watchdog trips at watchdogTimeout().
  virtual double takeCommandAgeMax() = 0;
  // Hardware: recover a bus that went bus-off or hung up (never automatic). The simulation
  // has no buses.
  virtual bool recover(std::string* why) {
    *why = "this robot has no buses to recover";
    return false;
  }

  // --- state changes: the simulation only (a real robot refuses, saying so) ---
  virtual bool resetToKeyframe(const std::string& keyframe, std::string* error);
  virtual bool resetToState(const std::vector<double>& qpos, const std::vector<double>& qvel,
                            const std::vector<double>& pressure, std::string* error);
  virtual bool setObjectPose(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                             const std::array<double, 3>& linear, const std::array<double, 3>& angular,
                             std::string* error);
  virtual bool setBaseTarget(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                             std::string* error);
  virtual bool simulated() const = 0;  // /step, /reset, set_object_pose, lockstep: simulation only
  virtual bool hasFreeBase() const { return false; }
  virtual const char* baseFrame() const { return ""; }
  virtual bool hasObject() const { return false; }
  virtual int objectBody() const { return -1; }

  // --- outputs ---
  virtual const Signals& sensed() const = 0;
  virtual bool sensedIsFinite() const { return allFinite(sensed()); }
  // What the robot really does: the simulation's ground truth; the hardware's best
  // estimate (its sensed signals).
  virtual const Signals& truth() const = 0;
  virtual const std::vector<double>& appliedCommand() const = 0;  // volts or N, per cylinder

  // --- model and configuration ---
  virtual double clock() const = 0;
  virtual double timestep() const = 0;  // of one step()
  virtual ActuationMode mode() const = 0;
  virtual double watchdogTimeout() const = 0;
  virtual double supplyPressure() const = 0;  // nominal, Pa absolute (markers' colour scale)
  double atmosphericPressure() const { return description::kAtmosphericPressure; }
  virtual const std::string& modelPath() const = 0;
  // The model, and data holding the robot's configuration (simulation: the physics;
  // hardware: the sensed joint angles through forward kinematics): markers and tf use them.
  virtual const mjModel* model() const = 0;
  virtual const mjData* data() const = 0;
  virtual const std::vector<std::string>& jointNames() const = 0;
  virtual const std::vector<std::string>& cylinderNames() const = 0;
  virtual const std::vector<description::Cylinder>& cylinders() const = 0;
  virtual const std::vector<std::string>& touchNames() const = 0;
  // Robot-specific diagnostics (the wrapper adds them to its status at 1 Hz; may allocate).
  virtual void addDiagnostics(DiagnosticValues* values) const { (void)values; }
};

}  // namespace adroit::driver
