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
#include <utility>
#include <vector>

#include "adroit_core/model_tables.h"
#include "adroit_core/mujoco_model.h"
#include "adroit_description/cylinders.h"
#include "adroit_driver/command_check.h"
#include "adroit_driver/robot.h"
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

class SimulatedRobot final : public Robot {
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
                             const std::vector<double>& volts) const override;
  CheckedCommand checkForces(const std::vector<std::string>& names, const std::vector<std::uint16_t>& indices,
                             const std::vector<double>& newtons) const override;
  CommandResult applyValves(const CheckedCommand& checked) override;
  CommandResult applyForces(const CheckedCommand& checked) override;

  // --- one physics step (config.timestep) ---
  void step() override;

  // --- safety ---
  void estop() override;               // software e-stop: latch the safe state
  void setEstopInput(bool held) override;  // the physical button; held latches the safe state
  // Leaves the safe state unless a cause persists (input held, physics still faulting) override;
  // on refusal returns false and says why.
  bool release(std::string* why) override;
  const SafetyStatus& safety() const override { return safety_; }
  const Counters& counters() const override { return counters_; }
  const SafetyEvents& safetyEvents() const override { return events_; }
  // One line for an event, e.g. "watchdog: 'A_FFJ3_flex' not commanded for 0.05 s (clock
  // 12.3 s)". Reads only the model's names, which never change: callable from any thread.
  std::string describe(const SafetyEvent& event) const override;
  // Cylinders without an accepted command since start or the last release: the watchdog
  // does not watch them (a pool that never started leaves them at idle). O(1).
  std::size_t neverCommanded() const override { return never_commanded_; }
  double takeCommandAgeMax() override { return std::exchange(command_age_max_, 0.0); }
  bool everCommanded(std::size_t cylinder) const override { return last_command_clock_[cylinder] != kNeverCommanded; }

  // --- state ---
  SimState state() const;
  // Throws std::invalid_argument when sizes do not match this model.
  void setState(const SimState& state);
  // Model default (keyframe 0 if present), or a named keyframe. Pressures atmospheric.
  bool resetToKeyframe(const std::string& keyframe, std::string* error) override;
  // Full state: empty qpos = model default, empty qvel = zeros, empty pressure = atmospheric.
  // Refused (with the joint's name and value) when a limited hinge/slide joint is outside
  // its range by more than config().reset_range_margin of it, a free or ball joint's
  // quaternion is not of unit norm, a free joint is farther than config().max_reset_distance
  // from the origin, or a velocity exceeds config().max_reset_velocity: such states would
  // only fault in the next step.
  bool resetToState(const std::vector<double>& qpos, const std::vector<double>& qvel,
                    const std::vector<double>& pressure, std::string* error) override;
  // World-frame pose (quaternion w x y z, normalised here) and velocity of the free object.
  // Refused beyond config().max_reset_distance from the origin or with a velocity component
  // above config().max_reset_velocity.
  bool setObjectPose(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                     const std::array<double, 3>& linear, const std::array<double, 3>& angular,
                     std::string* error) override;

  // Teleop scenes (free hand base welded to the mocap body hand_base_target): the pose the
  // base is to follow, in the world frame (quaternion w x y z, normalised here). The mocap
  // body moves towards it at most config().max_base_speed / max_base_angular_speed. Refused
  // (false, *error) without a free base, with NaN/Inf, a zero quaternion, or beyond
  // config().max_reset_distance from the origin. Allocates nothing unless refused.
  bool setBaseTarget(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                     std::string* error) override;
  bool hasFreeBase() const override { return base_mocap_ >= 0; }
  const char* baseFrame() const override { return base_frame_; }  // the base body's name (tf child frame)
  // --- outputs ---
  const Signals& sensed() const override { return sensors_.sensed(); }
  // Whether every value of sensed() is finite (a faulted plant can make them NaN); no
  // allocation, a pass over a few hundred values.
  bool sensedIsFinite() const override { return allFinite(sensors_.sensed()); }
  const Signals& truth() const override { return truth_; }
  const std::vector<double>& appliedCommand() const override { return applied_command_; }  // volts or N

  // --- model information ---
  double clock() const override { return clock_; }
  double timestep() const override { return config_.timestep; }
  const SimConfig& config() const { return config_; }
  const mjModel* model() const override { return model_.get(); }
  const mjData* data() const override { return data_.get(); }
  const std::vector<std::string>& jointNames() const override { return joint_names_; }
  const std::vector<std::string>& cylinderNames() const override { return actuators_.names(); }
  const std::vector<description::Cylinder>& cylinders() const override { return cylinders_; }
  const std::vector<std::string>& touchNames() const override { return touch_names_; }
  bool hasObject() const override { return object_body_ >= 0; }
  int objectBody() const override { return object_body_; }
  const pneumatics::PneumaticPlant* plant() const { return plant_.get(); }
  bool simulated() const override { return true; }
  ActuationMode mode() const override { return config_.mode; }
  double watchdogTimeout() const override { return config_.watchdog_timeout; }
  double supplyPressure() const override { return config_.supply_pressure; }
  const std::string& modelPath() const override { return config_.model_path; }

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
  double command_age_max_ = 0;  // takeCommandAgeMax
  std::vector<double> travel_, travel_rate_;
  Signals truth_;
  SensorPipeline sensors_;

  SafetyStatus safety_;
  Counters counters_;
  SafetyEvents events_;
};

}  // namespace adroit::driver
