// The simulated ADROIT robot, ROS-free: MuJoCo model/data, the pneumatic plant (one
// cylinder per tendon actuator), the sensor pipeline and the safety state (command
// watchdog, e-stop latch, fault latch, rejected-command counters).
//
// Time: clock() is monotonic (steps x timestep since construction). Resets and state
// restores change the physics state and MuJoCo's own time, never clock(), so downstream
// consumers never see time jump back.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "adroit_core/model_tables.h"
#include "adroit_core/mujoco_model.h"
#include "adroit_description/cylinders.h"
#include "adroit_driver/command_check.h"
#include "adroit_driver/sensor_pipeline.h"
#include "adroit_driver/sim_config.h"
#include "adroit_pneumatics/plant.h"

namespace adroit::driver {

// Everything needed to continue a simulation exactly: physics, pressures (with the plant's
// tube-delay line), sensors (filters, delay lines, random generators) and the commands.
// Safety state and clock() are deliberately not part of it: restoring a state must not
// clear an e-stop, and time never goes back.
struct SimState {
  // Complete copy of MuJoCo's data: restoring it replays bit for bit (MuJoCo carries
  // solver and integrator intermediates between steps that the arrays below do not hold).
  std::shared_ptr<const mjData> physics;
  double physics_time = 0;
  std::vector<double> qpos, qvel, act, qacc_warmstart;
  pneumatics::PlantState plant;  // empty pressure vector in force mode
  std::vector<double> command;   // volts (pneumatic) or newtons (force), per cylinder
  SensorPipeline sensors;
  double sensors_clock = 0;  // clock() when captured (the sensors' delay lines use it)
};

enum class SafeCause { kNone = 0, kEstop = 1, kWatchdog = 2, kFault = 4 };

// What a fault found not finite (or, for qpos/qvel/qacc, also beyond MuJoCo's mjMAXVAL).
enum class FaultSource { kNone, kQpos, kQvel, kQacc, kCommand, kPressure, kTension };

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

class SimulatedRobot {
 public:
  // Throws ModelLoadError (MuJoCo's message and the path) or std::invalid_argument.
  explicit SimulatedRobot(const SimConfig& config);

  // --- commands (addressing and validation: command_check.h) ---
  // Accepted commands allocate nothing (only a rejection formats its error text).
  CommandResult commandValves(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                              const std::vector<double>& volts);
  CommandResult commandForces(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                              const std::vector<double>& newtons);
  // The same in two halves, for a caller with threads: check*() reads only what never
  // changes (names, limits, mode), so it may run on the caller's thread without holding
  // the robot (it allocates the result); apply*() then counts and applies under the
  // caller's lock. apply*() takes only what check*() of this robot returned.
  CheckedCommand checkValves(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                             const std::vector<double>& volts) const;
  CheckedCommand checkForces(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                             const std::vector<double>& newtons) const;
  CommandResult applyValves(const CheckedCommand& checked);
  CommandResult applyForces(const CheckedCommand& checked);

  // --- one physics step (config.timestep) ---
  void step();

  // --- safety ---
  void estop();                        // software e-stop: latch the safe state
  void setEstopInput(bool held);       // the physical button; held latches the safe state
  // Leaves the safe state unless a cause persists (input held, physics still faulting);
  // on refusal returns false and says why.
  bool release(std::string* why);
  const SafetyStatus& safety() const { return safety_; }
  const Counters& counters() const { return counters_; }
  const SafetyEvents& safetyEvents() const { return events_; }
  // One line for an event, e.g. "watchdog: 'A_FFJ3_flex' not commanded for 0.05 s (clock
  // 12.3 s)". Reads only the model's names, which never change: callable from any thread.
  std::string describe(const SafetyEvent& event) const;
  // Cylinders without an accepted command since start or the last release: the watchdog
  // does not watch them (a pool that never started leaves them at idle). O(1).
  std::size_t neverCommanded() const { return never_commanded_; }
  bool everCommanded(std::size_t cylinder) const { return last_command_clock_[cylinder] != kNeverCommanded; }

  // --- state ---
  SimState state() const;
  // Throws std::invalid_argument when sizes do not match this model.
  void setState(const SimState& state);
  // Model default (keyframe 0 if present), or a named keyframe. Pressures atmospheric.
  bool resetToKeyframe(const std::string& keyframe, std::string* error);
  // Full state: empty qpos = model default, empty qvel = zeros, empty pressure = atmospheric.
  // Refused (with the joint's name and value) when a limited hinge/slide joint is outside
  // its range by more than config().reset_range_margin of it, a free or ball joint's
  // quaternion is not of unit norm, a free joint is farther than config().max_reset_distance
  // from the origin, or a velocity exceeds config().max_reset_velocity: such states would
  // only fault in the next step.
  bool resetToState(const std::vector<double>& qpos, const std::vector<double>& qvel,
                    const std::vector<double>& pressure, std::string* error);
  // World-frame pose (quaternion w x y z, normalised here) and velocity of the free object.
  // Refused beyond config().max_reset_distance from the origin or with a velocity component
  // above config().max_reset_velocity.
  bool setObjectPose(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                     const std::array<double, 3>& linear, const std::array<double, 3>& angular, std::string* error);

  // Teleop scenes (free hand base welded to the mocap body hand_base_target): the pose the
  // base is to follow, in the world frame (quaternion w x y z, normalised here). The mocap
  // body moves towards it at most config().max_base_speed / max_base_angular_speed. Refused
  // (false, *error) without a free base, with NaN/Inf, a zero quaternion, or beyond
  // config().max_reset_distance from the origin. Allocates nothing unless refused.
  bool setBaseTarget(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                     std::string* error);
  bool hasFreeBase() const { return base_mocap_ >= 0; }
  const char* baseFrame() const { return base_frame_; }  // the base body's name (tf child frame)
  // --- outputs ---
  const Signals& sensed() const { return sensors_.sensed(); }
  // Whether every value of sensed() is finite (a faulted plant can make them NaN); no
  // allocation, a pass over a few hundred values.
  bool sensedIsFinite() const { return allFinite(sensors_.sensed()); }
  const Signals& truth() const { return truth_; }
  const std::vector<double>& appliedCommand() const { return applied_command_; }  // volts or N

  // --- model information ---
  double clock() const { return clock_; }
  double timestep() const { return config_.timestep; }
  const SimConfig& config() const { return config_; }
  const mjModel* model() const { return model_.get(); }
  const mjData* data() const { return data_.get(); }
  const std::vector<std::string>& jointNames() const { return joint_names_; }
  const std::vector<std::string>& cylinderNames() const { return actuators_.names(); }
  const std::vector<description::Cylinder>& cylinders() const { return cylinders_; }
  const std::vector<std::string>& touchNames() const { return touch_names_; }
  bool hasObject() const { return object_body_ >= 0; }
  int objectBody() const { return object_body_; }
  double atmosphericPressure() const { return description::kAtmosphericPressure; }
  const pneumatics::PneumaticPlant* plant() const { return plant_.get(); }

 private:
  // last_command_clock_ of a cylinder not commanded since start or the last release.
  static constexpr double kNeverCommanded = -std::numeric_limits<double>::infinity();

  // Where a step found a fault (plain data: nothing is formatted unless it latches).
  struct FaultSite {
    FaultSource source = FaultSource::kNone;
    int index = -1;  // qpos/qvel/qacc address, or the cylinder
  };
  void enterSafeState(SafeCause cause, int cylinder = -1, const FaultSite* fault = nullptr);
  bool applyActuation(FaultSite* fault);  // false when a non-finite value would have acted
  bool physicsIsBad(FaultSite* fault) const;
  bool physicsStep(FaultSite* fault);  // false when the step was refused as a fault
  bool checkResetState(const std::vector<double>& qpos, const std::vector<double>& qvel, std::string* error) const;
  std::string jointName(int joint) const;
  std::string faultText(const SafetyEvent& event) const;
  void computeTruth();
  void afterTeleport();  // recompute derived data and restart the sensors
  void moveBaseTarget();  // the mocap body one step towards base_target_ (rate-limited)
  void holdBaseWhereItIs();  // after a reset: the mocap body at the base, no target
  // A world pose as set_object_pose and hand_base/target take it: finite, a quaternion of
  // non-zero norm (returned in *norm), within max_reset_distance. Allocates only on refusal.
  bool checkPose(const std::array<double, 3>& position, const std::array<double, 4>& quaternion, double* norm,
                 std::string* error) const;
  CommandResult acceptCommand(const CheckedCommand& checked);

  SimConfig config_;
  ModelPtr model_;
  DataPtr data_;
  NameIndex actuators_;
  std::vector<description::Cylinder> cylinders_;
  std::unique_ptr<pneumatics::PneumaticPlant> plant_;
  // Teleop scenes: the free joint of the hand base, its mocap body, and the pose it follows.
  int base_qpos_ = -1, base_mocap_ = -1;
  const char* base_frame_ = "";
  std::array<double, 7> base_target_{};
  bool base_target_set_ = false;
  ValueLimits valve_limits_, force_limits_;
  CheckedCommand checked_;    // workspace of checkCommand, reserved: accepting a command does not allocate
  std::vector<char> seen_;

  std::vector<int> joint_ids_;  // 1-DOF joints reported in joint states
  std::vector<std::string> joint_names_;
  std::vector<int> touch_adr_;  // sensordata addresses of touch sensors
  std::vector<std::string> touch_names_;
  int object_body_ = -1, object_qpos_ = -1, object_dof_ = -1;

  double clock_ = 0;
  std::vector<double> command_;          // last accepted command per cylinder
  std::vector<double> applied_command_;  // what acted in the last step (safe state applied)
  std::vector<double> last_command_clock_;  // kNeverCommanded until a command is accepted
  std::size_t never_commanded_ = 0;
  std::vector<double> travel_, travel_rate_;
  Signals truth_;
  SensorPipeline sensors_;

  SafetyStatus safety_;
  Counters counters_;
  SafetyEvents events_;
};

}  // namespace adroit::driver
