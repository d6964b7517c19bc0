// mpc_success's closed loop: one variant of one task against the simulation driver's ROS-free
// core (adroit_driver::SimulatedRobot) in emulated real time, through the node's MpcRunner,
// with the pools (adroit_pneumatics::CylinderPool) between the plan and the valves in the
// pneumatic variants; a trial at a time (see the top of mpc_success.cpp).
#pragma once

#include "robustness.h"
#include "trial.h"

#include <adroit_core/mujoco_model.h>
#include <adroit_core/timing_stats.h>
#include <adroit_driver/simulated_robot.h>
#include <adroit_mpc/mpc_runner.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/task.h>
#include <adroit_pneumatics/pool.h>
#include <adroit_pneumatics/tracking_floor.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace success {

class TrialRunner {
 public:
  // contact_margin / contact_softness >= 0 override the planning model's (--contact M,S).
  // world: the object's mass and size in both worlds and the sensors' noise (the drop and the
  // keys are the trials', makeTrials).
  TrialRunner(const std::string& task, const Variant& variant, const adroit_mpc::PlannerSettings& overrides,
              const success::World& world, double contact_margin = -1, double contact_softness = -1);

  TrialResult run(const TrialSpec& spec);

 private:
  // One trial's timeline and what has happened so far.
  struct Progress {
    double release = 0, sequence = 0, end = 0;  // simulated s: object let go, keys given, trial over
    bool goal_given = false, sequence_given = false;
    std::vector<double> plan_seconds, start_errors;
    std::array<std::vector<double>, 5> phases;
  };

  // The plan's tensions over its horizon as the node sends them to the pools
  // (/adroit/force_reference): knots from the plan's start, in the robot's clock.
  struct Reference {
    double t0 = 0, dt = 0;
    std::size_t steps = 0;
    std::vector<double> force;
  };

  // A new robot per trial: its sensor noise restarts from the seed and no command, valve
  // state or watchdog state of the previous trial carries over, so a trial's outcome does
  // not depend on the trials before it (--only-trial K reproduces trial K of a run).
  void resetWorld(const TrialSpec& spec);

  std::unique_ptr<adroit_mpc::Task> makeTrialTask(const TrialSpec& spec, bool idle_first) const;

  // The node's closed loop (adroit_mpc/mpc_runner.h) in emulated real time: a plan takes over
  // its latency after the state it started from (the wall time of planOnce, or
  // --fixed-latency), and the running policy carries the world on meanwhile.
  std::unique_ptr<adroit_mpc::MpcRunner> makeRunner(std::unique_ptr<adroit_mpc::Task> task);

  void closedLoop(const TrialSpec& spec, Progress& p, TrialResult& r);

  // As a user would: the relocation goal once the ball is held, the keys after --idle.
  void giveCommands(const TrialSpec& spec, Progress& p, TrialResult& r);

  void recordPlan(const adroit_mpc::PlanOutcome& plan, Progress& p, TrialResult& r) const;

  // The plan's starting state against the world when the plan takes over.
  void recordStartError(Progress& p, const std::vector<double>& plan_qpos) const;

  // The control side takes the new plan over once the world's clock has reached its time.
  void takeOver(Reference& fresh_reference);

  void score(const TrialSpec& spec, const Progress& p, TrialResult& r);

  double taskError(const mjModel* m, const mjData* d);

  void takeReference(const adroit_mpc::Trajectory& plan, double plan_time, Reference& out) const;

  void sendReference(const Reference& ref);
  Reference sent_;  // the last reference sent (open-loop variant)
  Reference active_reference_;  // open-loop variant: the running plan's

  // The task's progress on the true state, between plans (typing registers keys at the
  // control rate); planOnce observes it on each plan's state too (noteEvents).
  void observeState(const adroit_mpc::PlannerState& s);

  void noteEvents(double t, const std::vector<adroit_mpc::TaskEvent>& events);

  // One driver step (2 ms). The runner's control side first takes a plan over whose time has
  // come. Force mode: the policy's tensions every step. Pneumatic mode: the pools tick at
  // 200 Hz on the sensed actuator state and command the valves. Without a usable policy (none
  // yet, or one older than its horizon) nothing is sent, as by the node.
  // hold_object: keep the object at this position, at rest (pre-roll).
  void stepOnce(TrialResult& r, const Eigen::Vector3d* hold_object);

  // The pools' 200 Hz tick: a reference from the policy (or the open-loop plan), the sensed
  // actuator state, the valve commands.
  void poolTick();

 public:
  void resetTrace() { next_trace_ = 0; }
  // The trial's states as render_states reads them: time, one column per hinge / slide joint,
  // <free joint>:x|y|z|qw|qx|qy|qz.
  // Pneumatic variants: the last trial's planned and sensed tension per cylinder at the pools'
  // ticks (columns time, <cylinder>:plan..., <cylinder>:sensed...).
  void writeForces(const std::string& path) const;
  void writeStates(const std::string& path, const TrialResult& r) const;
  // >= 0: every optimisation takes this long in simulated time (instead of its wall time).
  void setFixedLatency(double seconds) { fixed_latency_ = seconds; }
  // Print the task's events (phases, relocation stages, keys) as observe() reports them.
  void setPrintEvents(bool on) { print_events_ = on; }
  void setIdle(double seconds) { idle_ = seconds; }
  // Task parameters (numbers: weights, thresholds) over the task's defaults.
  void setParams(const std::map<std::string, double>& numbers) { param_overrides_ = numbers; }
  void setPoolParams(const adroit::pneumatics::IlqgParams& p) {
    p.validate();
    pool_options_.ilqg = p;
  }
  // The planner and the policy see the driver's sensed signals (noise, quantisation, delays)
  // instead of the true state, as the node does.
  void setSensed(bool sensed) { sensed_ = sensed; }
  void setFeedbackScale(double scale) { feedback_scale_ = scale; }
  void setCompensation(bool on) { compensation_ = on; }

 private:
  // RMS over the hinge and slide joints of qpos (planning model layout) against the simulation now.
  double jointDistance(const std::vector<double>& qpos) const;

  // The state the controller sees: the true one, or (sensed_) the true one with every 1-DOF
  // joint and the free object replaced by what the driver's sensors report.
  void measure(std::vector<double>& qpos, std::vector<double>& qvel) const;

  bool sensed_ = false;
  double feedback_scale_ = 1.0;  // the node's ~feedback_scale (the task's hint unless set)
  std::vector<double> qpos_, qvel_;
  static constexpr double kPoolPeriod = 0.005;  // s, the pools' 200 Hz (config/pools.yaml)
  static constexpr int kMaxReferenceSamples = 256;
  // The first n values with negatives clamped to 0 (tendons only pull), in force_.
  const std::vector<double>& positive(const std::vector<double>& values, std::size_t n);
  // Sensed tension against the plan's tension now (the reference's first sample), per group
  // of cylinders, as the demo reports it, next to the floors of ForceTrackingAudit.
  void recordForceTracking(const adroit::driver::Signals& sensed);
  std::vector<std::vector<double>> force_trace_;  // this trial: time, planned, sensed and per-tick floor tensions
  std::vector<double> reference_, force_;
  std::vector<double> pool_seconds_;  // wall time of each pool tick (all cylinders)
  std::vector<adroit::pneumatics::ForceTrackingAudit::Cylinder> audited_;  // pneumatic variants
  std::unique_ptr<adroit::pneumatics::ForceTrackingAudit> force_audit_;
  std::unique_ptr<adroit::pneumatics::PreviewAudit> preview_audit_;  // policy reference only: given at the tick, from it
  std::unique_ptr<adroit::pneumatics::ReferenceStepAudit> step_audit_;  // the references' steps per knot, every trial
  double audit_dead_time_ = 0;  // s
  std::vector<double> volume_, volume_rate_;
  double last_floor_time_ = 0;

 public:
  // Median wall time of a pool tick so far [s] (0 in force mode): the CPU the pools need.
  std::size_t cylinders() const { return robot_->cylinderNames().size(); }
  double poolTickMedian() const { return pool_seconds_.empty() ? 0 : adroit::percentile(pool_seconds_, 50); }
  static double poolPeriod() { return kPoolPeriod; }
  // Pneumatic variants: force tracking per group over every trial so far.
  std::map<std::string, adroit::pneumatics::ForceTrackingAudit::Group> forceTracking() const;
  // Pneumatic variant: per group, the preview's RMSE at each of kPreviewLeads (empty if none).
  std::map<std::string, std::vector<double>> previewError() const;
  double auditDeadTime() const { return audit_dead_time_; }
  // Pneumatic variants: the policy references' tension steps per knot (null in force mode).
  const adroit::pneumatics::ReferenceStepAudit* stepAudit() const { return step_audit_.get(); }
  static constexpr std::array<double, 3> kPreviewLeads = {0.005, 0.01, 0.02};  // s

 private:
  std::string task_name_;
  Variant variant_;
  adroit_mpc::PlannerSettings settings_;
  adroit::ModelPtr plan_model_;
  bool compensation_ = false;  // the task's hint unless --compensation
  adroit::DataPtr observe_;
  std::unique_ptr<adroit_mpc::MpcRunner> runner_;  // this trial's closed loop
  adroit_mpc::PlannerState plan_input_;            // the state each plan starts from
  std::unique_ptr<success::ObjectVariantScene> object_scene_;  // --object-mass / --object-scale
  adroit::driver::SimConfig robot_config_;
  std::unique_ptr<adroit::driver::SimulatedRobot> robot_;
  std::vector<std::uint16_t> all_actuators_;
  std::vector<double> ctrl_;
  std::vector<adroit::pneumatics::PoolCylinder> pool_cylinders_;
  adroit::pneumatics::PoolOptions pool_options_;
  std::unique_ptr<adroit::pneumatics::CylinderPool> pool_;
  double next_tick_ = 0;
  int object_body_ = -1, grasp_site_ = -1;
  double duration_ = 0, next_trace_ = 0, fixed_latency_ = -1;
  int steps_since_observe_ = 0;
  bool print_events_ = false;
  double idle_ = 0;          // typing: s at rest before the sequence (--idle)
  int keys_registered_ = 0;  // key events of the trial so far
  std::map<std::string, double> param_overrides_;
};

}  // namespace success
