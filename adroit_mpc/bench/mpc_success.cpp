// Behaviour MPC success over randomised trials (issue: catch >= 80 %, relocation within 3 cm
// >= 80 %, typing >= 90 % of keys, in pneumatic mode; pneumatic >= 0.9 x force mode), iLQG
// against predictive sampling, synergies on / off, force against pneumatic mode, on identical
// trials. A program, not a test.
//
//   mpc_success [--trials N] [--tasks catch,relocate,type] [--variants ilqg,sampling,cem,cem_pneumatic,nosyn,pneumatic,pneumatic_open,as_planned,nocomp,coldfd,fullfd,pneumatic_fullfd]
//               [--out DIR] [--seed S] [--only-trial K] [--fixed-latency S] [--latency-sweep S,S,...]
//               [--dt S] [--horizon S] [--skip K] [--tension-step-weight W] [--sensed] [--feedback-scale F] [--contact M,S] [--events]
//               [--idle S]
//               [--compensation on|off|task] [--set [task.]key=number]... [--pool ilqg_key=number]...
//               [--object-mass KG] [--object-scale S] [--drop-height MIN,MAX] [--drop-offset M]
//               [--sensor-noise F] [--keys N] [--key-set DIGITS] [--sweep NAME=v1,v2,...]...
//
// --compensation: latency compensation (latency_compensation.h: plan from the state the running
// policy is predicted to reach when the plan takes over, at the planning latency: the fixed one,
// else the median of the trial's last nine), as the node's ~latency_compensation; default: the
// task's hint (type on). Variant nocomp is iLQG without it whatever the setting: its baseline.
// Variant coldfd is iLQG with every finite-difference nudge solved from the knot's warm start
// (mjd_transitionFD's) instead of the nominal step's solution (PlannerSettings::fd_warmstart,
// on by default): its baseline.
// Variants fullfd and pneumatic_fullfd are iLQG (force, pneumatic mode) on the derivative path
// before issue 38: every knot of the skip pattern evaluated at every optimise, one nudge per
// control (PlannerSettings::derivative_max_age 0, fd_force_space off): the baselines of the
// reused derivatives and of B through the generalised forces.
// The table's "start" column says how far each plan's starting state was from the state when it
// took over (joint RMS, median): the prediction's error, or without it the measured state's age.
//
// --dt, --horizon, --skip override the task's planner_dt, horizon and derivative_skip hints
// (defaults: config/tasks/<task>.yaml, else config/mpc.yaml's).
// --tension-step-weight W: PlannerSettings::tension_step_weight (the cost of a tension step
// from one knot to the next; 0: the plans before it). Pneumatic variants print each finger
// group's largest reference step per knot and its 99th percentile ("max step", "p99 step") beside
// the force tracking.
// --contact M,S: the planning model's contact margin and softness [m] (defaults: planning_model.h;
// typing 0.001, 0.001 as the node).
// --sensed: the planner and the policy see the driver's sensed signals (sensor realism: noise,
// quantisation, delays) instead of the true state, as the node does.
// --feedback-scale F: the fraction of the policy's feedback gains applied, in [0, 1] (the
// node's ~feedback_scale; default: the task's feedback_scale hint, else 1).
// --latency-sweep: iLQG on every task again with each fixed planning latency (simulated
// s per optimisation instead of the measured wall time): how fast the planner must be.
// Variant as_planned (diagnostic): iLQG in force mode against a simulation that runs the
// planning MJCF (Table 6.1 armature and springs, pruned contacts, the planning keypad) in its
// 2 ms steps: what the same planner does when its model is right, i.e. how much of a task's
// shortfall is model mismatch rather than the cost or the planner.
// --only-trial K: of the N seeded trials, run trial K alone (its traces and states are written);
//   each trial gets a new simulated robot (sensor noise from its seed, nothing left over from
//   the trial before), so with --fixed-latency this is exactly trial K of the full run.
// --events: print each trial's task events (phase, relocation stage, keys) with their time.
// --idle S: typing only: the hand rests over the keys S seconds, closed loop, before the
//   sequence is given; keys registered meanwhile are typed unasked (printed, CSV `unasked`).
// --set [task.]key=number: a task parameter (weight, threshold) over config/tasks/<task>.yaml, for
// tuning without a rebuild (the --latency-sweep runs use it too). Without "task." the key must be
// a number parameter of every task that runs. Refused: keys no task has, and keys that would
// change nothing here (the planner hints: --horizon, --dt, --skip, --feedback-scale,
// --compensation set those; object_mass / object_radius, which no task reads: --object-mass,
// --object-scale).
//
// What the tasks were not tuned on (success/robustness.h; defaults: what they were tuned on):
// --object-mass KG, --object-scale S: the object (bottle, ball) in the simulated world and in
//   the planning model alike (scaleObjectBody; S scales its geoms, inertia ~ S^2);
// --drop-height MIN,MAX (or H): the release height above the catch goal / relocation hold
//   (0.04,0.09); --drop-offset M: the sideways range +-M in x and y (0.015);
// --sensor-noise F: every noise std of the driver's sensors times F (read by the planner with
//   --sensed, and by the pools in pneumatic variants; refused when nothing reads them);
// --keys N, --key-set DIGITS: typing sequences of N keys drawn from DIGITS (10, 0123456789).
// An option is refused when no task that runs would feel it. --sweep NAME=v1,v2,... (NAME: an
// option above with '_' for '-', drop_height takes one height per value) runs the tasks and
// variants once per value instead of the run above, prints a table per value and one across
// the values, writes DIR/success_sweep.csv and ends with a RESULT line per task, variant and
// value (success in %: trials, typing: keys right; target 90).
// Typing reports its presses: every registered press, and the wrong ones (a key other than the
// one expected next, a wrong key later backspaced included: keys right forgives it);
// RESULT type_<variant>_wrong_press_percent (target <= 10 %), DIR/success_presses.csv.
// --pool ilqg_key=number: a setting of the pools' iLQG (names of IlqgParams, setIlqgParam),
// over config/pools.yaml's (iterations 1, the rest IlqgParams' defaults).
//
// Closed loop in emulated real time, ROS-free, against the simulation driver's core
// (adroit_driver::SimulatedRobot: the physical scene in 2 ms steps, the pneumatic plant,
// sensors, watchdog). Variants ilqg, sampling, cem, nosyn drive it in force mode (the policy's
// tendon forces every step); pneumatic (cem_pneumatic: CEM) is iLQG with the plan's tensions over the horizon
// sent to a pool of every cylinder (adroit_pneumatics::CylinderPool, iLQG pressure control
// at 200 Hz on the sensed pressures, config/pools.yaml settings, identified models), whose
// valve commands drive the plant, as the node does in mode:=pneumatic. The pools' CPU time
// is not charged to the planner (they run beside it). The planner plans on the planning
// model from the true simulated state. The closed loop is the node's own (adroit_mpc::MpcRunner,
// mpc_runner.h) in emulated real time: a plan whose planOnce took c seconds of wall time on this
// machine takes over c seconds of simulated time after the state it started from, and the
// previous policy runs in between (what the node's planner thread does against a driver
// running in real time, with the cores to itself). The planner optimises ten times
// before the trial starts, then runs closed loop for 0.3 s with the object held at its start
// (the MPC runs before the object is released; the pools pressurise the cylinders).
//
// Trials (seeded; every variant sees the same ones, paired: trial k runs under each variant in
// turn before trial k + 1, so a change of the machine's speed falls on all variants alike):
//   catch     bottle released 4-9 cm above the goal, +-1.5 cm sideways; 2.5 s; success: it
//             never falls below the palm (z >= 0.2 m) and ends within 3 cm of the goal;
//   relocate  (thesis 6.5: relocation starts as a dynamic stabilisation) the ball released
//             4-9 cm above the hold position in the palm-up hand, +-1.5 cm sideways; the goal,
//             at least 5 cm from the hold position (x +-8, y +-6, z -10..0 cm), given 1 s
//             later (setGoal, as a user would);
//             4 s; success: the ball ends within 3 cm of the goal (the program prints how far
//             the goals are from the hold: what staying put would score). The goals are in free
//             air, so a ball there is in the hand. (A height threshold, once part of it, counted
//             the arm's dip as it takes the ball's impact, or a ball resting at a low goal, as a
//             drop.) The CSV has the lowest height and, from the goal on, the farthest distance
//             of the ball from the grasp site;
//   type      a random 10-digit sequence; until typed or 1.5 s per key; keys correct = keys
//             typed correctly (auto-correction allowed), speed = correct keys per minute;
//             presses and wrong presses (TypeTask::presses, wrongPresses).
//
// Writes DIR/success_trials.csv (one row per trial), DIR/success_traces.csv (the first trial
// of each task and variant, error over time) and plots them with plot_success.py into
// DIR/success_<task>.png, and DIR/states_<task>_<variant>.csv (the first trial's joint
// positions, for render_states); pneumatic variants also DIR/forces_<task>_<variant>.csv (the
// first trial's planned and sensed tension per cylinder at the pools' ticks) and print the
// force tracking per group next to the plant's floor (adroit_pneumatics ForceTrackingAudit).
// Ends with RESULT lines (DESIGN.md section 5).
#include <adroit_core/command_line.h>
#include <adroit_core/mujoco_model.h>
#include <adroit_core/run_program.h>
#include <adroit_core/timing_stats.h>
#include <adroit_description/cylinders.h>
#include <adroit_description/scenes.h>
#include <adroit_driver/simulated_robot.h>
#include <adroit_pneumatics/params_io.h>
#include <adroit_pneumatics/plant.h>
#include <adroit_pneumatics/pool.h>
#include <adroit_pneumatics/tracking_floor.h>
#include <adroit_mpc/mpc_runner.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/planning_model.h>
#include <adroit_mpc/synergies.h>
#include <adroit_mpc/task.h>
#include <adroit_mpc/task_params.h>
#include <adroit_mpc/type_task.h>

#include "success/robustness.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace adroit_mpc;
namespace pneumatics = adroit::pneumatics;

namespace {

// Optimisations before the trial starts: the MPC runs while the object is held (0.5 s at
// ~50 ms per iteration).
constexpr int kWarmupIterations = 10;
// Closed loop with the object held at its start before it is let go (s of simulated time).
constexpr double kPreRoll = 0.3;
// Relocation: the goal is given this long after the release, this far from the hold at least.
constexpr double kRelocateGoalDelay = 1.0;
constexpr double kRelocateMinDistance = 0.05;

struct Variant {
  std::string name, planner;
  bool synergies;
  bool pneumatic = false;  // valve commands from the pools tracking the plan (else tendon forces)
  bool open_loop_reference = false;  // pneumatic: the plan's tensions on each new plan only
  bool world_as_planned = false;  // the simulation runs the planning MJCF (diagnostic, see --variants)
  bool compensate = true;  // plan from the state predicted at the expected latency (latency_compensation.h)
  bool fd_warmstart = true;  // finite-difference nudges solved from the nominal's solution (fd_derivatives.h)
  bool cheap_derivatives = true;  // reused across optimisations, B through the forces (fd_derivatives.h)
};

struct TrialSpec {
  int index = 0;
  Eigen::Vector3d object_start = Eigen::Vector3d::Zero();
  Eigen::Vector3d goal = Eigen::Vector3d::Zero();
  std::string keys;
};

struct TrialResult {
  bool success = false;
  double final_error = 0, lowest_z = 0, duration = 0, plan_ms_median = 0;
  // Table 6.2's split of an optimisation, ms, median over the trial's plans: rollout,
  // derivatives, cost derivatives, backward pass, line search.
  std::array<double, 5> phase_ms_median{};
  // Joints (hinge and slide) of the state each plan started from against the state when it took
  // over, RMS, median over the plans: the prediction's error with latency compensation, the
  // measured state's staleness without.
  double start_error_median = 0;
  double farthest_from_grasp = 0;  // relocation, from the goal on: object centre to S_grasp (m)
  int keys_correct = 0, keys_total = 0, diverged = 0;
  int unasked = 0;  // typing with --idle: keys registered before the sequence was given
  int presses = 0, wrong_presses = 0;  // typing, from the sequence on (TypeTask::presses, wrongPresses)
  std::vector<std::pair<double, double>> trace;  // (t, error)
  std::vector<std::vector<double>> qpos_trace;   // qpos at the trace times (for render_states)
};

std::string sceneOf(const std::string& task) {
  return task == "catch" ? "bottle" : task == "relocate" ? "ball" : "keypad";
}

// The drop options scale the same draws whatever their values, so trial k of one drop is
// trial k of another but for the drop (and the defaults give the trials as they always were);
// the typing options draw other sequences.
std::vector<TrialSpec> makeTrials(const std::string& task, int n, unsigned seed, const success::World& world) {
  const double side = world.drop_offset, height = world.drop_center, spread = world.drop_half;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  const TaskParams defaults = defaultTaskParams(task);
  std::vector<TrialSpec> trials(n);
  for (int i = 0; i < n; ++i) {
    TrialSpec& s = trials[i];
    s.index = i;
    if (task == "catch") {
      const Eigen::Vector3d goal = paramVector3(task, defaults, "goal_position");
      s.goal = goal;
      s.object_start = goal + Eigen::Vector3d(side * u(rng), side * u(rng), height + spread * u(rng));
    } else if (task == "relocate") {
      const Eigen::Vector3d hold = paramVector3(task, defaults, "hold_position");
      s.object_start = hold + Eigen::Vector3d(side * u(rng), side * u(rng), height + spread * u(rng));
      Eigen::Vector3d offset;
      do {  // beyond the success radius of the hold by at least 2 cm
        offset = Eigen::Vector3d(0.08 * u(rng), 0.06 * u(rng), -0.05 + 0.05 * u(rng));
      } while (offset.norm() < kRelocateMinDistance);
      s.goal = hold + offset;
    } else {
      std::uniform_int_distribution<int> digit(0, static_cast<int>(world.key_set.size()) - 1);
      for (int k = 0; k < world.keys; ++k) s.keys.push_back(world.key_set[digit(rng)]);
    }
  }
  return trials;
}

// The largest steady pressure a cylinder of this type reaches at the pools' command limit
// (the seal leak included; one cylinder alone barely sags the supply), locked at mid-stroke,
// Pa absolute.
double steadyMaxPressure(const std::string& type) {
  pneumatics::PlantOptions o;
  o.area_spread = o.offset_spread = 0;
  pneumatics::PneumaticPlant plant({pneumatics::cylinderSpec(type)}, {}, 1, o);
  const double full = pneumatics::IlqgParams{}.u_max, travel = 0.5 * plant.spec(0).stroke, rate = 0;
  for (int k = 0; k < 2500; ++k) plant.step(0.002, &full, &travel, &rate);  // 5 s
  return plant.pressure()[0];
}

// Physical bound of pneumatic relocation: the shoulder's gravity torque at the start pose
// against what its flexor cylinder can hold at the pools' command limit.
void printShoulderBound(const std::string& scene_file) {
  adroit::ModelPtr model = adroit::loadModelFile(scene_file).model;
  adroit::DataPtr data = adroit::makeData(model.get());
  const mjModel* m = model.get();
  mjData* d = data.get();
  const int key = mj_name2id(m, mjOBJ_KEY, "rest");
  const int joint = mj_name2id(m, mjOBJ_JOINT, "ARJ2"), flexor = mj_name2id(m, mjOBJ_ACTUATOR, "A_ARJ2_flex");
  if (key < 0 || joint < 0 || flexor < 0) return;
  mju_copy(d->qpos, m->key_qpos + key * m->nq, m->nq);
  mj_forward(m, d);
  const int dof = m->jnt_dofadr[joint];
  const double gravity = std::abs(d->qfrc_bias[dof]);               // zero velocity: gravity only
  const double arm = std::abs(d->actuator_moment[flexor * m->nv + dof]);  // tendon moment arm [m]
  const double nominal = m->actuator_ctrlrange[2 * flexor + 1];     // force mode's limit [N]
  std::string type;
  for (const auto& c : adroit::description::cylinderTable(m))
    if (c.actuator == flexor) type = c.type;
  const pneumatics::CylinderSpec spec = pneumatics::cylinderSpec(type);
  const double steady = (steadyMaxPressure(type) - pneumatics::constants::kAtmosphere) * spec.bore_area;
  std::printf("relocate, pneumatic: the shoulder (ARJ2) holds the arm at rest against %.1f N m of gravity; its\n"
              "  flexor gives %.1f N m at the force-mode limit (%.0f N) and at most %.1f N m in pneumatic mode (%.0f N:\n"
              "  the %s's steady pressure at the pools' %.1f V command limit, leak included). Holding the arm takes\n"
              "  %.0f %% of the force-mode torque and %.0f %% of the pneumatic one.\n",
              gravity, nominal * arm, nominal, steady * arm, steady, type.c_str(), pneumatics::IlqgParams{}.u_max,
              100 * gravity / (nominal * arm), 100 * gravity / (steady * arm));
}

class TrialRunner {
 public:
  // contact_margin / contact_softness >= 0 override the planning model's (--contact M,S).
  // world: the object's mass and size in both worlds and the sensors' noise (the drop and the
  // keys are the trials', makeTrials).
  TrialRunner(const std::string& task, const Variant& variant, const PlannerSettings& overrides,
              const success::World& world, double contact_margin = -1, double contact_softness = -1)
      : task_name_(task), variant_(variant), settings_(overrides) {
    const TaskParams defaults = defaultTaskParams(task);
    if (settings_.horizon <= 0) settings_.horizon = paramNumber(task, defaults, "horizon", 0.01, 5);
    if (settings_.dt <= 0) settings_.dt = paramNumber(task, defaults, "planner_dt", 1e-4, 0.1);
    if (settings_.derivative_skip <= 0)  // the task's hint, else the node's default (config/mpc.yaml)
      settings_.derivative_skip = defaults.numbers.count("derivative_skip")
                                      ? static_cast<int>(paramNumber(task, defaults, "derivative_skip", 1, 100))
                                      : PlannerSettings{}.derivative_skip;
    feedback_scale_ = defaults.numbers.count("feedback_scale") ? paramNumber(task, defaults, "feedback_scale", 0, 1)
                                                                : 1.0;
    compensation_ = defaults.numbers.count("latency_compensation") &&
                    paramNumber(task, defaults, "latency_compensation", 0, 1) > 0.5;
    settings_.synergies = variant.synergies;
    settings_.fd_warmstart = variant.fd_warmstart;
    if (!variant.cheap_derivatives) settings_.derivative_max_age = 0, settings_.fd_force_space = false;
    PlanningModelSettings ms;
    ms.timestep = settings_.dt;
    if (task == "type") ms.contact_margin = 0.001, ms.contact_softness = 0.001;  // as the node
    if (contact_margin >= 0) ms.contact_margin = contact_margin;
    if (contact_softness >= 0) ms.contact_softness = contact_softness;
    const bool changed_object = task != "type" && (world.object_mass > 0 || world.object_scale != 1);
    if (changed_object) ms.object_mass = world.object_mass, ms.object_size_scale = world.object_scale;
    const std::string share = descriptionShareDir();
    plan_model_ = loadPlanningModel(adroit::description::sceneFile(share, sceneOf(task), true), ms);
    observe_ = adroit::makeData(plan_model_.get());

    // The simulation driver's ROS-free core: physics, the pneumatic plant, sensors, safety.
    adroit::driver::SimConfig config;
    config.model_path = adroit::description::sceneFile(share, sceneOf(task), variant.world_as_planned);
    config.mode = variant.pneumatic ? adroit::driver::ActuationMode::kPneumatic : adroit::driver::ActuationMode::kForce;
    config.initial_keyframe = "rest";
    if (changed_object) {  // the same object in the world the robot is in
      object_scene_ = std::make_unique<success::ObjectVariantScene>(config.model_path, world.object_mass,
                                                                     world.object_scale);
      config.model_path = object_scene_->path();
    }
    success::scaleSensorNoise(world.sensor_noise, config.sensors);
    robot_config_ = config;
    robot_ = std::make_unique<adroit::driver::SimulatedRobot>(config);
    const mjModel* m = robot_->model();
    for (int i = 0; i < m->nu; ++i) all_actuators_.push_back(static_cast<std::uint16_t>(i));
    ctrl_.assign(m->nu, 0.0);
    reference_.assign(static_cast<std::size_t>(kMaxReferenceSamples) * m->nu, 0.0);
    object_body_ = mj_name2id(m, mjOBJ_BODY, "object");
    grasp_site_ = mj_name2id(m, mjOBJ_SITE, "S_grasp");
    duration_ = task == "catch" ? 2.5 : task == "relocate" ? kRelocateGoalDelay + 3.0 : 15.0;
    if (variant.pneumatic) {
      // The pools as config/pools.yaml runs them: every cylinder with its identified model.
      const std::string pneumatics_share = packageShareDir("adroit_pneumatics", "config/pools.yaml");
      const auto models = pneumatics::loadParameterSet(pneumatics_share + "/config/parametric_default.yaml");
      for (const auto& c : robot_->cylinders())
        pool_cylinders_.push_back(
            {c.name, c.bore_area, pneumatics::deadVolume(c.type, c.bore_diameter), models.forCylinder(c.name)});
      pool_options_.controller = "ilqg";
      std::vector<std::string> groups;
      for (const auto& c : robot_->cylinders()) {
        pneumatics::CylinderSpec spec = pneumatics::cylinderSpec(c.type);
        spec.dead_volume = pneumatics::deadVolume(c.type, c.bore_diameter);
        audited_.push_back({pneumatics::trackingGroup(c.name), spec});
        groups.push_back(audited_.back().group);
      }
      // From a valve command to the sensed tension seeing it: the tube delay, then the
      // pressure sensor's delay.
      audit_dead_time_ = pneumatics::PlantOptions{}.tube_delay + (config.sensors.enabled ? config.sensors.cylinder_delay : 0);
      preview_audit_ = std::make_unique<pneumatics::PreviewAudit>(groups, std::vector<double>(kPreviewLeads.begin(), kPreviewLeads.end()));
      step_audit_ = std::make_unique<pneumatics::ReferenceStepAudit>(groups);
    }
  }

  TrialResult run(const TrialSpec& spec) {
    resetWorld(spec);
    // --idle: the hand rests over the keys that long, closed loop, before the sequence comes.
    const bool idle_first = task_name_ == "type" && idle_ > 0;
    keys_registered_ = 0;
    runner_ = makeRunner(makeTrialTask(spec, idle_first));
    TrialResult r;
    force_trace_.clear();
    r.lowest_z = 1e9;
    // Before the trial: optimisations with the world frozen, then a pre-roll in closed loop
    // with the object held at its start (the pools pressurise the cylinders to the plan's
    // tensions; a real hand is already holding its posture when the object is let go).
    Progress p;
    p.sequence_given = !idle_first;
    p.release = robot_->data()->time + kPreRoll;
    p.sequence = p.release + (idle_first ? idle_ : 0.0);
    p.end = p.sequence + (task_name_ == "type" ? 1.5 * spec.keys.size() + 0.5 : duration_);
    closedLoop(spec, p, r);
    score(spec, p, r);
    return r;
  }

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
  void resetWorld(const TrialSpec& spec) {
    std::string why;
    robot_ = std::make_unique<adroit::driver::SimulatedRobot>(robot_config_);
    if (!robot_->resetToKeyframe("rest", &why)) throw std::runtime_error("reset: " + why);
    const bool has_object = task_name_ == "catch" || task_name_ == "relocate";
    if (has_object && !robot_->setObjectPose({spec.object_start.x(), spec.object_start.y(), spec.object_start.z()},
                                             {1, 0, 0, 0}, {0, 0, 0}, {0, 0, 0}, &why))
      throw std::runtime_error("object pose: " + why);
    if (variant_.pneumatic) {
      pool_ = std::make_unique<pneumatics::CylinderPool>(pool_cylinders_, robot_->cylinderNames(), pool_options_);
      if (!force_audit_)  // the pools' command limit is known by now (setPoolParams)
        force_audit_ = std::make_unique<pneumatics::ForceTrackingAudit>(audited_, pool_options_.ilqg.u_max, audit_dead_time_);
      force_audit_->start(robot_->sensed().pressure);
      last_floor_time_ = robot_->clock();
    }
    next_tick_ = robot_->clock();
  }

  std::unique_ptr<Task> makeTrialTask(const TrialSpec& spec, bool idle_first) const {
    TaskParams params;
    for (const auto& [key, value] : param_overrides_) params.numbers[key] = value;
    if (task_name_ == "catch") params.vectors["goal_position"] = {spec.goal.x(), spec.goal.y(), spec.goal.z()};
    auto task = makeTask(task_name_, params);
    task->bind(plan_model_.get(), variant_.synergies ? Synergies::kCount : 0);
    std::string why;
    if (!idle_first && !spec.keys.empty() && !task->setSequence(spec.keys, &why)) throw std::runtime_error(why);
    return task;
  }

  // The node's closed loop (adroit_mpc/mpc_runner.h) in emulated real time: a plan takes over
  // its latency after the state it started from (the wall time of planOnce, or
  // --fixed-latency), and the running policy carries the world on meanwhile.
  std::unique_ptr<MpcRunner> makeRunner(std::unique_ptr<Task> task) {
    RunnerSettings rs;
    rs.timing = PlanTiming::kEmulated;
    rs.fixed_latency = fixed_latency_;
    rs.latency_compensation = variant_.compensate && compensation_;
    rs.feedback_scale = feedback_scale_;
    rs.on_events = [this](double t, const std::vector<TaskEvent>& events) { noteEvents(t, events); };
    return std::make_unique<MpcRunner>(plan_model_.get(), makePlanner(variant_.planner), std::move(task), settings_,
                                       std::move(rs));
  }

  void closedLoop(const TrialSpec& spec, Progress& p, TrialResult& r) {
    const mjData* d = robot_->data();
    Reference fresh_reference;  // open-loop variant: the plan's tensions, sent when it takes over
    int warmup = kWarmupIterations;
    while (d->time < p.end) {
      // The state the optimisation starts from; the task's progress observed on it.
      plan_input_.time = d->time;
      measure(plan_input_.qpos, plan_input_.qvel);
      plan_input_.act.assign(d->act, d->act + robot_->model()->na);
      giveCommands(spec, p, r);
      const PlanOutcome plan = runner_->planOnce(plan_input_, warmup > 0);
      recordPlan(plan, p, r);
      if (plan.published && variant_.open_loop_reference)
        takeReference(runner_->planner().bestTrajectory(), runner_->planState().time, fresh_reference);
      if (warmup > 0) {  // before the release: the world waits, and the plan takes over at once
        --warmup;
        takeOver(fresh_reference);
        continue;
      }
      // The previous policy runs while this optimisation computes.
      const double plan_end = plan_input_.time + plan.latency;
      while (d->time < plan_end && d->time < p.end) {
        stepOnce(r, d->time < p.release ? &spec.object_start : nullptr);
        if (p.goal_given && grasp_site_ >= 0 && object_body_ >= 0) {
          const Eigen::Map<const Eigen::Vector3d> object(d->xpos + 3 * object_body_), grasp(d->site_xpos + 3 * grasp_site_);
          r.farthest_from_grasp = std::max(r.farthest_from_grasp, (object - grasp).norm());
        }
      }
      if (plan.published && d->time >= p.release) recordStartError(p, runner_->planState().qpos);
      takeOver(fresh_reference);
      if (task_name_ == "type" && p.sequence_given && taskError(plan_model_.get(), observe_.get()) == 0) break;
    }
  }

  // As a user would: the relocation goal once the ball is held, the keys after --idle.
  void giveCommands(const TrialSpec& spec, Progress& p, TrialResult& r) {
    const double t = robot_->data()->time;
    std::string why;
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    if (task_name_ == "relocate" && !p.goal_given && t >= p.release + kRelocateGoalDelay) {
      p.goal_given = true;
      if (!runner_->task().setGoal(spec.goal, Eigen::Quaterniond::Identity(), &why))
        throw std::runtime_error("goal: " + why);
    }
    if (!p.sequence_given && t >= p.sequence) {
      p.sequence_given = true;
      r.unasked = keys_registered_;
      if (!runner_->task().setSequence(spec.keys, &why)) throw std::runtime_error(why);
    }
  }

  void recordPlan(const PlanOutcome& plan, Progress& p, TrialResult& r) const {
    const OptimizeReport& report = plan.report;
    const std::array<double, 5> split{report.rollout, report.derivatives, report.cost, report.backward,
                                      report.line_search};
    for (std::size_t k = 0; k < p.phases.size(); ++k) p.phases[k].push_back(split[k]);
    p.plan_seconds.push_back(plan.latency);
    if (!plan.published) ++r.diverged;
  }

  // The plan's starting state against the world when the plan takes over.
  void recordStartError(Progress& p, const std::vector<double>& plan_qpos) const {
    p.start_errors.push_back(jointDistance(plan_qpos));
  }

  // The control side takes the new plan over once the world's clock has reached its time.
  void takeOver(Reference& fresh_reference) {
    if (!runner_->updatePolicy(robot_->data()->time) || !variant_.open_loop_reference) return;
    std::swap(active_reference_, fresh_reference);
    sendReference(active_reference_);
  }

  void score(const TrialSpec& spec, const Progress& p, TrialResult& r) {
    const mjModel* m = robot_->model();
    const mjData* d = robot_->data();
    r.duration = d->time - p.sequence;
    r.plan_ms_median = 1e3 * adroit::percentile(p.plan_seconds, 50);
    for (std::size_t k = 0; k < p.phases.size(); ++k) r.phase_ms_median[k] = 1e3 * adroit::percentile(p.phases[k], 50);
    r.start_error_median = p.start_errors.empty() ? 0 : adroit::percentile(p.start_errors, 50);
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    if (task_name_ == "type") {
      auto& type = static_cast<TypeTask&>(runner_->task());
      r.keys_total = static_cast<int>(spec.keys.size());
      r.keys_correct = type.typedCorrectly();
      r.presses = type.presses();
      r.wrong_presses = type.wrongPresses();
      r.final_error = r.keys_total - r.keys_correct;
      r.success = r.keys_correct == r.keys_total;
    } else {
      r.final_error = runner_->task().error(m, d);
      r.success = r.final_error <= 0.03 && (task_name_ != "catch" || r.lowest_z >= 0.2);
    }
    if (robot_->safety().safe_state) r.success = false;  // a watchdog trip or fault ends the trial badly
  }

  double taskError(const mjModel* m, const mjData* d) {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    return runner_->task().error(m, d);
  }

  void takeReference(const Trajectory& plan, double plan_time, Reference& out) const {
    const std::size_t knots = std::min(plan.ctrl.size(), plan.times.size());
    const std::size_t nu = all_actuators_.size();
    out.t0 = robot_->clock() + (plan.times.empty() ? 0 : plan.times[0] - plan_time);
    out.dt = settings_.dt;
    out.steps = knots;
    out.force.resize(knots * nu);
    for (std::size_t k = 0; k < knots; ++k)
      for (std::size_t j = 0; j < nu; ++j) out.force[k * nu + j] = std::max(0.0, plan.ctrl[k][j]);
  }

  void sendReference(const Reference& ref) {
    if (!pool_ || ref.steps == 0) return;
    const auto verdict = pool_->setReference(robot_->clock(), ref.t0, ref.dt, ref.steps, robot_->cylinderNames(),
                                             ref.force);
    if (!verdict.ok()) throw std::runtime_error("pool rejected the plan's reference: " + verdict.detail);
    sent_ = ref;
  }
  Reference sent_;  // the last reference sent (open-loop variant)
  Reference active_reference_;  // open-loop variant: the running plan's

  // The task's progress on the true state, between plans (typing registers keys at the
  // control rate); planOnce observes it on each plan's state too (noteEvents).
  void observeState(const PlannerState& s) {
    const mjModel* pm = plan_model_.get();
    mjData* o = observe_.get();
    o->time = s.time;
    mju_copy(o->qpos, s.qpos.data(), pm->nq);
    mju_copy(o->qvel, s.qvel.data(), pm->nv);
    if (pm->na) mju_copy(o->act, s.act.data(), pm->na);
    mj_forward(pm, o);
    std::vector<TaskEvent> events;
    {
      std::lock_guard<std::mutex> lock(runner_->taskMutex());
      events = runner_->task().observe(pm, o, s.time);
    }
    noteEvents(s.time, events);
  }

  void noteEvents(double t, const std::vector<TaskEvent>& events) {
    for (const auto& e : events) {
      keys_registered_ += e.kind == "key";
      if (print_events_) std::printf("  t %.3f %s %s\n", t, e.kind.c_str(), e.detail.c_str());
    }
  }

  // One driver step (2 ms). The runner's control side first takes a plan over whose time has
  // come. Force mode: the policy's tensions every step. Pneumatic mode: the pools tick at
  // 200 Hz on the sensed actuator state and command the valves. Without a usable policy (none
  // yet, or one older than its horizon) nothing is sent, as by the node.
  // hold_object: keep the object at this position, at rest (pre-roll).
  void stepOnce(TrialResult& r, const Eigen::Vector3d* hold_object) {
    const mjModel* m = robot_->model();
    const mjData* d = robot_->data();
    measure(qpos_, qvel_);
    runner_->updatePolicy(d->time);
    if (!variant_.pneumatic) {
      if (runner_->action(d->time, qpos_.data(), qvel_.data(), d->act, ctrl_.data())) {
        for (double& u : ctrl_) u = std::max(0.0, u);
        robot_->commandForces({}, all_actuators_, ctrl_);
      }
    } else if (robot_->clock() + 1e-9 >= next_tick_) {
      next_tick_ += kPoolPeriod;
      poolTick();
    }
    if (hold_object) {
      std::string why;
      robot_->setObjectPose({hold_object->x(), hold_object->y(), hold_object->z()}, {1, 0, 0, 0}, {0, 0, 0},
                            {0, 0, 0}, &why);
    }
    robot_->step();
    if (hold_object) return;
    if (task_name_ == "type") {  // key presses are registered at the control rate, as the node does
      if (++steps_since_observe_ >= 3) {
        steps_since_observe_ = 0;
        PlannerState s;
        s.time = d->time;
        s.qpos.assign(d->qpos, d->qpos + m->nq);
        s.qvel.assign(d->qvel, d->qvel + m->nv);
        s.act.assign(d->act, d->act + m->na);
        observeState(s);
      }
    } else if (object_body_ >= 0) {
      r.lowest_z = std::min(r.lowest_z, d->xpos[3 * object_body_ + 2]);
    }
    if (d->time >= next_trace_) {
      next_trace_ = d->time + 0.02;
      r.trace.emplace_back(d->time, task_name_ == "type" ? taskError(plan_model_.get(), observe_.get()) : taskError(m, d));
      r.qpos_trace.emplace_back(d->qpos, d->qpos + m->nq);
    }
  }

  // The pools' 200 Hz tick: a reference from the policy (or the open-loop plan), the sensed
  // actuator state, the valve commands.
  void poolTick() {
    const mjModel* m = robot_->model();
    const mjData* d = robot_->data();
    const auto& sensed = robot_->sensed();
    const double now = robot_->clock();
    if (!variant_.open_loop_reference) {
      // As the node's control loop in pneumatic mode: the policy with feedback on the
      // current state, over the rest of its horizon, at the pools' rate.
      const int samples = runner_->reference(d->time, qpos_.data(), qvel_.data(), d->act, kMaxReferenceSamples,
                                             reference_.data());
      if (samples > 0) {
        const double dt = runner_->policy().policy.dt;
        const auto verdict = pool_->setReference(now, now, dt, samples, robot_->cylinderNames(),
                                                 positive(reference_, samples * m->nu));
        if (!verdict.ok()) throw std::runtime_error("pool rejected the policy's reference: " + verdict.detail);
        preview_audit_->addReference(now, dt, static_cast<std::size_t>(samples),
                                     {reference_.begin(), reference_.begin() + samples * m->nu});
        step_audit_->addReference(static_cast<std::size_t>(samples), reference_.data(),
                                  static_cast<std::size_t>(samples * m->nu));
        recordForceTracking(sensed);
      }
    } else if (runner_->hasPolicy() && sent_.steps > 0) {  // the last plan's tensions, interpolated at now
      const std::size_t nu = all_actuators_.size();
      const double x = std::clamp((now - sent_.t0) / sent_.dt, 0.0, static_cast<double>(sent_.steps - 1));
      const auto k0 = static_cast<std::size_t>(x), k1 = std::min(k0 + 1, sent_.steps - 1);
      for (std::size_t j = 0; j < nu; ++j)
        reference_[j] = sent_.force[k0 * nu + j] + (x - k0) * (sent_.force[k1 * nu + j] - sent_.force[k0 * nu + j]);
      recordForceTracking(sensed);
    }
    const auto verdict = pool_->setState(now, now, robot_->cylinderNames(), sensed.pressure, sensed.length,
                                         sensed.length_rate, sensed.supply_pressure);
    if (!verdict.ok()) throw std::runtime_error("pool rejected the actuator state: " + verdict.detail);
    adroit::Stopwatch pool_clock;
    const std::vector<double>& volts = pool_->update(now);
    pool_seconds_.push_back(pool_clock.elapsed());
    robot_->commandValves(pool_->names(), {}, volts);
  }

 public:
  void resetTrace() { next_trace_ = 0; }
  // The trial's states as render_states reads them: time, one column per hinge / slide joint,
  // <free joint>:x|y|z|qw|qx|qy|qz.
  // Pneumatic variants: the last trial's planned and sensed tension per cylinder at the pools'
  // ticks (columns time, <cylinder>:plan..., <cylinder>:sensed...).
  void writeForces(const std::string& path) const {
    if (force_trace_.empty()) return;
    std::ofstream out(path);
    out << "time";
    for (const char* kind : {"plan", "sensed", "floor_per_tick"})
      for (const std::string& name : robot_->cylinderNames()) out << "," << name << ":" << kind;
    out << "\n";
    for (const auto& row : force_trace_) {
      for (std::size_t k = 0; k < row.size(); ++k) out << (k ? "," : "") << row[k];
      out << "\n";
    }
  }
  void writeStates(const std::string& path, const TrialResult& r) const {
    const mjModel* m = robot_->model();
    std::ofstream out(path);
    std::vector<int> columns;  // qpos address per column
    out << "time";
    for (int j = 0; j < m->njnt; ++j) {
      const std::string name = mj_id2name(m, mjOBJ_JOINT, j);
      const int adr = m->jnt_qposadr[j];
      if (m->jnt_type[j] == mjJNT_FREE) {
        for (const char* c : {"x", "y", "z", "qw", "qx", "qy", "qz"}) out << "," << name << ":" << c;
        for (int k = 0; k < 7; ++k) columns.push_back(adr + k);
      } else if (m->jnt_type[j] == mjJNT_HINGE || m->jnt_type[j] == mjJNT_SLIDE) {
        out << "," << name;
        columns.push_back(adr);
      }
    }
    out << "\n";
    for (std::size_t i = 0; i < r.trace.size(); ++i) {
      out << r.trace[i].first;
      for (int adr : columns) out << "," << r.qpos_trace[i][adr];
      out << "\n";
    }
  }
  // >= 0: every optimisation takes this long in simulated time (instead of its wall time).
  void setFixedLatency(double seconds) { fixed_latency_ = seconds; }
  // Print the task's events (phases, relocation stages, keys) as observe() reports them.
  void setPrintEvents(bool on) { print_events_ = on; }
  void setIdle(double seconds) { idle_ = seconds; }
  // Task parameters (numbers: weights, thresholds) over the task's defaults.
  void setParams(const std::map<std::string, double>& numbers) { param_overrides_ = numbers; }
  void setPoolParams(const pneumatics::IlqgParams& p) {
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
  double jointDistance(const std::vector<double>& qpos) const {
    const mjModel* m = robot_->model();
    const mjData* d = robot_->data();
    double sum = 0;
    int n = 0;
    for (int j = 0; j < m->njnt; ++j) {
      if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
      const double e = qpos[m->jnt_qposadr[j]] - d->qpos[m->jnt_qposadr[j]];
      sum += e * e;
      ++n;
    }
    return n ? std::sqrt(sum / n) : 0;
  }

  // The state the controller sees: the true one, or (sensed_) the true one with every 1-DOF
  // joint and the free object replaced by what the driver's sensors report.
  void measure(std::vector<double>& qpos, std::vector<double>& qvel) const {
    const mjModel* m = robot_->model();
    const mjData* d = robot_->data();
    qpos.assign(d->qpos, d->qpos + m->nq);
    qvel.assign(d->qvel, d->qvel + m->nv);
    if (!sensed_) return;
    const auto& sensed = robot_->sensed();
    std::size_t k = 0;
    for (int j = 0; j < m->njnt; ++j) {
      if (m->jnt_type[j] == mjJNT_FREE) {
        std::copy(sensed.object.begin(), sensed.object.begin() + 7, qpos.begin() + m->jnt_qposadr[j]);
        std::copy(sensed.object.begin() + 7, sensed.object.end(), qvel.begin() + m->jnt_dofadr[j]);
      } else if (m->jnt_type[j] == mjJNT_HINGE || m->jnt_type[j] == mjJNT_SLIDE) {  // SimulatedRobot's order
        qpos[m->jnt_qposadr[j]] = sensed.joint_position[k];
        qvel[m->jnt_dofadr[j]] = sensed.joint_velocity[k];
        ++k;
      }
    }
  }

  bool sensed_ = false;
  double feedback_scale_ = 1.0;  // the node's ~feedback_scale (the task's hint unless set)
  std::vector<double> qpos_, qvel_;
  static constexpr double kPoolPeriod = 0.005;  // s, the pools' 200 Hz (config/pools.yaml)
  static constexpr int kMaxReferenceSamples = 256;
  // The first n values with negatives clamped to 0 (tendons only pull), in force_.
  const std::vector<double>& positive(const std::vector<double>& values, std::size_t n) {
    force_.resize(n);
    for (std::size_t i = 0; i < n; ++i) force_[i] = std::max(0.0, values[i]);
    return force_;
  }
  // Sensed tension against the plan's tension now (the reference's first sample), per group
  // of cylinders, as the demo reports it, next to the floors of ForceTrackingAudit.
  void recordForceTracking(const adroit::driver::Signals& sensed) {
    const std::vector<double>& tension = sensed.tension;
    const double now = robot_->clock();
    volume_.resize(tension.size());
    volume_rate_.resize(tension.size());
    for (std::size_t j = 0; j < tension.size(); ++j) {
      volume_[j] = pool_cylinders_[j].dead_volume + pool_cylinders_[j].bore_area * std::max(0.0, sensed.length[j]);
      volume_rate_[j] = pool_cylinders_[j].bore_area * sensed.length_rate[j];
    }
    force_audit_->add(now - last_floor_time_, reference_, tension, volume_, volume_rate_, sensed.supply_pressure);
    last_floor_time_ = now;
    preview_audit_->addSample(now, {reference_.begin(), reference_.begin() + tension.size()});
    std::vector<double> row = {now};
    row.insert(row.end(), reference_.begin(), reference_.begin() + tension.size());
    row.insert(row.end(), tension.begin(), tension.end());
    const std::vector<double>& floor = force_audit_->lastPerTickTension();
    row.insert(row.end(), floor.begin(), floor.end());
    force_trace_.push_back(std::move(row));
  }
  std::vector<std::vector<double>> force_trace_;  // this trial: time, planned, sensed and per-tick floor tensions
  std::vector<double> reference_, force_;
  std::vector<double> pool_seconds_;  // wall time of each pool tick (all cylinders)
  std::vector<pneumatics::ForceTrackingAudit::Cylinder> audited_;  // pneumatic variants
  std::unique_ptr<pneumatics::ForceTrackingAudit> force_audit_;
  std::unique_ptr<pneumatics::PreviewAudit> preview_audit_;  // policy reference only: given at the tick, from it
  std::unique_ptr<pneumatics::ReferenceStepAudit> step_audit_;  // the references' steps per knot, every trial
  double audit_dead_time_ = 0;  // s
  std::vector<double> volume_, volume_rate_;
  double last_floor_time_ = 0;

 public:
  // Median wall time of a pool tick so far [s] (0 in force mode): the CPU the pools need.
  std::size_t cylinders() const { return robot_->cylinderNames().size(); }
  double poolTickMedian() const { return pool_seconds_.empty() ? 0 : adroit::percentile(pool_seconds_, 50); }
  static double poolPeriod() { return kPoolPeriod; }
  // Pneumatic variants: force tracking per group over every trial so far.
  std::map<std::string, pneumatics::ForceTrackingAudit::Group> forceTracking() const {
    return force_audit_ ? force_audit_->groups() : std::map<std::string, pneumatics::ForceTrackingAudit::Group>{};
  }
  // Pneumatic variant: per group, the preview's RMSE at each of kPreviewLeads (empty if none).
  std::map<std::string, std::vector<double>> previewError() const {
    return preview_audit_ ? preview_audit_->groups() : std::map<std::string, std::vector<double>>{};
  }
  double auditDeadTime() const { return audit_dead_time_; }
  // Pneumatic variants: the policy references' tension steps per knot (null in force mode).
  const pneumatics::ReferenceStepAudit* stepAudit() const { return step_audit_.get(); }
  static constexpr std::array<double, 3> kPreviewLeads = {0.005, 0.01, 0.02};  // s

 private:
  std::string task_name_;
  Variant variant_;
  PlannerSettings settings_;
  adroit::ModelPtr plan_model_;
  bool compensation_ = false;  // the task's hint unless --compensation
  adroit::DataPtr observe_;
  std::unique_ptr<MpcRunner> runner_;  // this trial's closed loop
  PlannerState plan_input_;             // the state each plan starts from
  std::unique_ptr<success::ObjectVariantScene> object_scene_;  // --object-mass / --object-scale
  adroit::driver::SimConfig robot_config_;
  std::unique_ptr<adroit::driver::SimulatedRobot> robot_;
  std::vector<std::uint16_t> all_actuators_;
  std::vector<double> ctrl_;
  std::vector<pneumatics::PoolCylinder> pool_cylinders_;
  pneumatics::PoolOptions pool_options_;
  std::unique_ptr<pneumatics::CylinderPool> pool_;
  double next_tick_ = 0;
  int object_body_ = -1, grasp_site_ = -1;
  double duration_ = 0, next_trace_ = 0, fixed_latency_ = -1;
  int steps_since_observe_ = 0;
  bool print_events_ = false;
  double idle_ = 0;          // typing: s at rest before the sequence (--idle)
  int keys_registered_ = 0;  // key events of the trial so far
  std::map<std::string, double> param_overrides_;
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) if (!item.empty()) out.push_back(item);
  return out;
}

const std::map<std::string, Variant>& knownVariants() {
  static const std::map<std::string, Variant> known = {
      {"ilqg", {"ilqg", "ilqg", true}},
      {"sampling", {"sampling", "sampling", true}},
      {"cem", {"cem", "cem", true}},
      {"cem_pneumatic", {"cem_pneumatic", "cem", true, true}},
      {"nosyn", {"nosyn", "ilqg", false}},
      {"pneumatic", {"pneumatic", "ilqg", true, true}},
      {"pneumatic_open", {"pneumatic_open", "ilqg", true, true, true}},
      {"as_planned", {"as_planned", "ilqg", true, false, false, true}},
      {"nocomp", {"nocomp", "ilqg", true, false, false, false, false}},
      {"coldfd", {"coldfd", "ilqg", true, false, false, false, true, false}},
      {"fullfd", {"fullfd", "ilqg", true, false, false, false, true, true, false}},
      {"pneumatic_fullfd", {"pneumatic_fullfd", "ilqg", true, true, false, false, true, true, false}}};
  return known;
}

// The command line (see the top of this file).
struct Options {
  int trials = 20;
  unsigned seed = 1;
  int only_trial = -1;  // >= 0: run this trial of the seeded set alone (its traces are written)
  double fixed_latency = -1;
  bool sensed = false;
  double feedback_scale = -1;         // the task's hint
  std::string compensation = "task";  // on | off | task (its hint)
  double contact_margin = -1, contact_softness = -1;  // --contact M,S
  bool print_events = false;
  double idle = 0;                  // --idle S: typing rests that long before its sequence
  success::TaskNumbers params;      // --set [task.]key=number, per task
  pneumatics::IlqgParams pool_ilqg;  // --pool key=value over config/pools.yaml's settings
  bool pool_set = false;             // a --pool was given
  std::vector<std::string> latency_sweep;  // fixed latencies [s] for iLQG on every task
  PlannerSettings overrides;        // horizon, dt, skip <= 0: the task's hints
  std::string out_dir = ".";
  std::vector<std::string> tasks;
  std::vector<Variant> variants;
  success::World world;                // --object-mass ... --key-set
  std::vector<success::Sweep> sweeps;  // --sweep name=v1,v2,...

  bool has(const std::string& variant) const {
    return std::any_of(variants.begin(), variants.end(), [&](const Variant& v) { return v.name == variant; });
  }
  bool poolsRun() const {
    return std::any_of(variants.begin(), variants.end(), [](const Variant& v) { return v.pneumatic; });
  }
  std::map<std::string, double> paramsOf(const std::string& task) const {
    const auto it = params.find(task);
    return it == params.end() ? std::map<std::string, double>{} : it->second;
  }
};

constexpr const char* kUsage =
    "usage: mpc_success [--trials N] [--tasks catch,relocate,type] "
    "[--variants ilqg,sampling,cem,cem_pneumatic,nosyn,pneumatic,pneumatic_open,as_planned,nocomp,coldfd,fullfd,pneumatic_fullfd] [--out DIR] "
    "[--seed S] [--only-trial K] [--fixed-latency S] [--latency-sweep S,S,...] [--dt S] [--horizon S] [--skip K] "
    "[--tension-step-weight W] [--sensed] [--feedback-scale F] [--compensation on|off|task] [--contact M,S] [--events] [--idle S] "
    "[--set [task.]key=number]... [--pool ilqg_key=number]... [--object-mass KG] [--object-scale S] "
    "[--drop-height MIN,MAX] [--drop-offset M] [--sensor-noise F] [--keys N] [--key-set DIGITS] "
    "[--sweep NAME=v1,v2,...]...";

// A "--flag key=number" value; fails naming the flag.
std::pair<std::string, double> keyNumber(adroit::CommandLine& args) {
  const std::string text = args.text();
  const auto equals = text.find('=');
  double value = 0;
  if (equals == std::string::npos || !success::parseNumber(text.substr(equals + 1), &value))
    args.fail(args.flag() + " needs key=number, not '" + text + "'");
  return {text.substr(0, equals), value};
}

// "--object-mass" for the option object_mass.
std::string flagOf(std::string name) {
  std::replace(name.begin(), name.end(), '_', '-');
  return "--" + name;
}

// Variants and tasks by name, --set against the tasks, and options that would change nothing.
void checkOptions(Options& o, adroit::CommandLine& args, const std::string& tasks, const std::string& variants,
                  const std::vector<std::string>& sets) {
  if (o.trials < 1) args.fail("--trials must be at least 1");
  if (o.only_trial >= o.trials)
    args.fail("--only-trial " + std::to_string(o.only_trial) + " needs --trials > " + std::to_string(o.only_trial));
  if (!(o.overrides.tension_step_weight >= 0) || !std::isfinite(o.overrides.tension_step_weight))
    args.fail("--tension-step-weight must be >= 0 and finite");
  if (o.compensation != "task" && o.compensation != "on" && o.compensation != "off")
    args.fail("--compensation must be on, off or task (the task's hint)");
  if (o.feedback_scale != -1 && !(o.feedback_scale >= 0 && o.feedback_scale <= 1))
    args.fail("--feedback-scale must be in [0, 1]");
  for (const auto& v : split(variants)) {
    if (!knownVariants().count(v))
      args.fail("unknown variant '" + v + "' (known: ilqg, sampling, cem, cem_pneumatic, nosyn, pneumatic, "
                "pneumatic_open, as_planned, nocomp, coldfd, fullfd, pneumatic_fullfd)");
    o.variants.push_back(knownVariants().at(v));
  }
  o.tasks = split(tasks);
  for (const auto& t : o.tasks)
    if (t != "catch" && t != "relocate" && t != "type") args.fail("unknown task '" + t + "' (known: catch, relocate, type)");
  if (const std::string why = success::resolveTaskParams(sets, o.tasks, &o.params); !why.empty()) args.fail(why);
  for (const auto& name : success::changedOptions(o.world))
    if (const auto why = success::whyNoEffect(name, o.tasks, o.sensed, o.poolsRun()); !why.empty())
      args.fail(flagOf(name) + " would change nothing: " + why);
  for (const auto& sweep : o.sweeps)
    if (const auto why = success::whyNoEffect(sweep.name, o.tasks, o.sensed, o.poolsRun()); !why.empty())
      args.fail("--sweep " + sweep.name + " would change nothing: " + why);
  if (o.pool_set && !o.poolsRun()) args.fail("--pool would change nothing: no variant runs the pools");
  if (o.idle > 0 && std::find(o.tasks.begin(), o.tasks.end(), "type") == o.tasks.end())
    args.fail("--idle would change nothing: only task type rests over its keys first");
  if (!o.sweeps.empty() && !o.latency_sweep.empty())
    args.fail("--sweep and --latency-sweep: one sweep a run");
}

Options parseOptions(int argc, char** argv) {
  Options o;
  o.pool_ilqg.iterations = 1;  // the pools' settings as config/pools.yaml has them
  o.overrides.horizon = o.overrides.dt = -1;
  o.overrides.derivative_skip = -1;
  std::string tasks = "catch,relocate,type", variants = "ilqg,sampling,nosyn,pneumatic";
  std::vector<std::string> sets;
  adroit::CommandLine args(argc, argv, kUsage);
  const auto world_option = [&](const char* name) {
    if (const std::string why = success::setWorldOption(o.world, name, args.text()); !why.empty())
      args.fail(args.flag() + " " + why);
  };
  while (args.next()) {
    if (args.is("--trials")) o.trials = static_cast<int>(args.integer());
    else if (args.is("--tasks")) tasks = args.text();
    else if (args.is("--variants")) variants = args.text();
    else if (args.is("--out")) o.out_dir = args.text();
    else if (args.is("--seed")) o.seed = static_cast<unsigned>(args.integer());
    else if (args.is("--only-trial")) o.only_trial = static_cast<int>(args.integer());
    else if (args.is("--fixed-latency")) o.fixed_latency = args.number();
    else if (args.is("--latency-sweep")) {
      o.latency_sweep = split(args.text());
      double latency = 0;
      for (const auto& value : o.latency_sweep)
        if (!success::parseNumber(value, &latency) || latency < 0)
          args.fail("--latency-sweep needs latencies >= 0 [s], not '" + value + "'");
    }
    else if (args.is("--sensed")) o.sensed = true;
    else if (args.is("--feedback-scale")) o.feedback_scale = args.number();
    else if (args.is("--compensation")) o.compensation = args.text();
    else if (args.is("--contact")) {
      const auto parts = split(args.text());
      if (parts.size() != 2 || !success::parseNumber(parts[0], &o.contact_margin) ||
          !success::parseNumber(parts[1], &o.contact_softness))
        args.fail("--contact needs MARGIN,SOFTNESS [m]");
    }
    else if (args.is("--dt")) o.overrides.dt = args.number();
    else if (args.is("--horizon")) o.overrides.horizon = args.number();
    else if (args.is("--skip")) o.overrides.derivative_skip = static_cast<int>(args.integer());
    else if (args.is("--tension-step-weight")) o.overrides.tension_step_weight = args.number();
    else if (args.is("--events")) o.print_events = true;
    else if (args.is("--idle")) o.idle = args.number();
    else if (args.is("--set")) sets.push_back(args.text());
    else if (args.is("--pool")) {
      const auto [key, value] = keyNumber(args);
      if (!pneumatics::setIlqgParam(o.pool_ilqg, key, value)) args.fail("--pool: unknown iLQG parameter '" + key + "'");
      o.pool_set = true;
    }
    else if (args.is("--object-mass")) world_option("object_mass");
    else if (args.is("--object-scale")) world_option("object_scale");
    else if (args.is("--drop-height")) world_option("drop_height");
    else if (args.is("--drop-offset")) world_option("drop_offset");
    else if (args.is("--sensor-noise")) world_option("sensor_noise");
    else if (args.is("--keys")) world_option("keys");
    else if (args.is("--key-set")) world_option("key_set");
    else if (args.is("--sweep")) {
      success::Sweep sweep;
      if (const std::string why = success::parseSweep(args.text(), &sweep); !why.empty()) args.fail("--sweep " + why);
      o.sweeps.push_back(sweep);
    }
    else args.unknown();
  }
  checkOptions(o, args, tasks, variants, sets);
  return o;
}

// Per variant of a task, over its trials.
struct Tally {
  int n = 0, ok = 0, diverged = 0, keys_ok = 0, keys_all = 0, unasked = 0, unasked_trials = 0;
  int presses = 0, wrong_presses = 0;
  double error_sum = 0, typing_time = 0;
  std::vector<double> plan_ms, start_errors;
  std::array<std::vector<double>, 5> phase_ms;
  void add(const TrialResult& r) {
    ++n;
    ok += r.success;
    diverged += r.diverged;
    error_sum += r.final_error;
    keys_ok += r.keys_correct;
    keys_all += r.keys_total;
    unasked += r.unasked;
    unasked_trials += r.unasked > 0;
    presses += r.presses;
    wrong_presses += r.wrong_presses;
    typing_time += r.duration;
    plan_ms.push_back(r.plan_ms_median);
    start_errors.push_back(r.start_error_median);
    for (std::size_t k = 0; k < phase_ms.size(); ++k) phase_ms[k].push_back(r.phase_ms_median[k]);
  }
  double successRate() const { return static_cast<double>(ok) / n; }
  double keysRate() const { return keys_all ? static_cast<double>(keys_ok) / keys_all : 0; }
  double keysPerMinute() const { return typing_time > 0 ? 60.0 * keys_ok / typing_time : 0; }
  double wrongPercent() const { return presses ? 100.0 * wrong_presses / presses : 0; }
  // The success figure: trials for the object tasks, keys right for typing.
  double successPercent(const std::string& task) const { return 100 * (task == "type" ? keysRate() : successRate()); }
};

// Where the trials go. The run without --sweep: success_trials.csv (as it always was),
// success_traces.csv and the states (and pool forces) of each task's first trial, and
// success_presses.csv (typing). A sweep: success_sweep.csv, one row per point and trial.
struct Outputs {
  std::string dir;
  std::ofstream trials, traces, presses, sweep;
  std::string point;  // the sweep point of the rows: "name,value"

  bool open(const std::string& out_dir, bool sweeping) {
    dir = out_dir;
    if (sweeping) {
      sweep.open(dir + "/success_sweep.csv");
      sweep << "sweep,value,task,variant,trial,success,final_error,keys_correct,keys_total,presses,wrong_presses,"
               "unasked,duration,plan_ms\n";
      return static_cast<bool>(sweep);
    }
    trials.open(dir + "/success_trials.csv");
    traces.open(dir + "/success_traces.csv");
    presses.open(dir + "/success_presses.csv");
    trials << "task,variant,trial,success,final_error,lowest_z,farthest_from_grasp,keys_correct,keys_total,duration,"
              "plan_ms,diverged,unasked\n";
    traces << "task,variant,t,error\n";
    presses << "variant,trial,presses,wrong_presses,keys_correct,keys_total,unasked\n";
    return trials && traces && presses;
  }

  void record(const std::string& task, const Variant& variant, const TrialSpec& spec, const TrialResult& r,
              const TrialRunner& runner, bool first) {
    if (sweep.is_open()) {
      sweep << point << "," << task << "," << variant.name << "," << spec.index << "," << r.success << ","
            << r.final_error << "," << r.keys_correct << "," << r.keys_total << "," << r.presses << ","
            << r.wrong_presses << "," << r.unasked << "," << r.duration << "," << r.plan_ms_median << "\n";
      return;
    }
    trials << task << "," << variant.name << "," << spec.index << "," << r.success << "," << r.final_error << ","
           << (r.lowest_z > 1e8 ? 0 : r.lowest_z) << "," << r.farthest_from_grasp << "," << r.keys_correct << ","
           << r.keys_total << "," << r.duration << "," << r.plan_ms_median << "," << r.diverged << "," << r.unasked
           << "\n";
    if (task == "type")
      presses << variant.name << "," << spec.index << "," << r.presses << "," << r.wrong_presses << ","
              << r.keys_correct << "," << r.keys_total << "," << r.unasked << "\n";
    if (!first) return;
    for (const auto& [time, e] : r.trace) traces << task << "," << variant.name << "," << time << "," << e << "\n";
    runner.writeStates(dir + "/states_" + task + "_" + variant.name + ".csv", r);
    runner.writeForces(dir + "/forces_" + task + "_" + variant.name + ".csv");
  }
};

std::unique_ptr<TrialRunner> makeRunner(const std::string& task, const Variant& variant, const Options& o,
                                        const success::World& world) {
  auto runner = std::make_unique<TrialRunner>(task, variant, o.overrides, world, o.contact_margin, o.contact_softness);
  runner->setFixedLatency(o.fixed_latency);
  runner->setSensed(o.sensed);
  if (o.feedback_scale >= 0) runner->setFeedbackScale(o.feedback_scale);
  if (o.compensation != "task") runner->setCompensation(o.compensation == "on");
  runner->setPrintEvents(o.print_events);
  runner->setIdle(o.idle);
  runner->setParams(o.paramsOf(task));
  runner->setPoolParams(o.pool_ilqg);
  return runner;
}

std::vector<TrialSpec> trialsOf(const std::string& task, const Options& o, const success::World& world) {
  auto specs = makeTrials(task, o.trials, o.seed, world);
  if (o.only_trial >= 0) specs = {specs[o.only_trial]};
  return specs;
}

// Relocation's baseline: a ball left at the hold position misses every goal by this much.
void printRelocateBaseline(const std::vector<TrialSpec>& specs, const Options& o) {
  const Eigen::Vector3d hold = paramVector3("relocate", defaultTaskParams("relocate"), "hold_position");
  double nearest = 1e9, farthest = 0;
  for (const auto& spec : specs) {
    nearest = std::min(nearest, (spec.goal - hold).norm());
    farthest = std::max(farthest, (spec.goal - hold).norm());
  }
  std::printf("relocate: goals %.3f-%.3f m from the hold position (a ball left there misses every one)\n", nearest,
              farthest);
  if (o.poolsRun()) printShoulderBound(adroit::description::sceneFile(descriptionShareDir(), "ball", false));
}

void printTableHeader() {
  std::printf("%-9s %-14s %9s %12s %12s %10s %9s %12s\n", "task", "variant", "success", "mean error", "keys/min",
              "plan ms", "diverged", "start [rad]");
}

void printTrialStart(const std::string& task, const Variant& variant, const TrialSpec& spec) {
  if (task == "type")
    std::printf("%s %s trial %d: keys %s\n", task.c_str(), variant.name.c_str(), spec.index, spec.keys.c_str());
  else
    std::printf("%s %s trial %d: object %.3f %.3f %.3f, goal %.3f %.3f %.3f\n", task.c_str(), variant.name.c_str(),
                spec.index, spec.object_start.x(), spec.object_start.y(), spec.object_start.z(), spec.goal.x(),
                spec.goal.y(), spec.goal.z());
}

// The pools' CPU and the force tracking of a pneumatic variant, against the plant's floors.
void printPoolAudit(const TrialRunner& runner) {
  std::printf("%-9s %-14s pools: %.2f ms per 5 ms tick for %zu cylinders (median, one core)\n", "", "",
              1e3 * runner.poolTickMedian(), runner.cylinders());
  std::printf("%-9s %-14s force tracking, sensed vs planned tension, RMSE N (the demo's figure), against\n"
              "%-9s %-14s the floor: a cylinder that learns of each reference at the tick it is given, races at\n"
              "%-9s %-14s the command limit after %.0f ms (tube delay and pressure sensing) and stops on it\n"
              "%-9s %-14s exactly, and per tick: one command per %.0f ms pool tick, chosen with an exact model;\n"
              "%-9s %-14s preview: the reference given 5 / 10 / 20 ms earlier against the one given now\n",
              "", "", "", "", "", "", 1e3 * runner.auditDeadTime(), "", "", 1e3 * TrialRunner::poolPeriod(), "", "");
  std::printf("%-9s %-14s   %-6s %6s %6s %8s %10s %8s %9s %9s %20s\n", "", "", "group", "RMSE", "floor", "per tick",
              "RMSE/tick", "max ref", "max step", "p99 step", "preview 5/10/20 ms");
  const auto preview = runner.previewError();
  for (const auto& [group, f] : runner.forceTracking()) {
    char ahead[64] = "-";
    if (preview.count(group) && preview.at(group).size() == 3 && std::isfinite(preview.at(group)[0]))
      std::snprintf(ahead, sizeof ahead, "%.2f / %.2f / %.2f", preview.at(group)[0], preview.at(group)[1],
                    preview.at(group)[2]);
    const pneumatics::ReferenceStepAudit* steps = runner.stepAudit();
    std::printf("%-9s %-14s   %-6s %6.2f %6.2f %8.2f %10.2f %8.1f %9.1f %9.1f %20s\n", "", "", group.c_str(), f.rmse,
                f.floor, f.per_tick, f.per_tick > 0 ? f.rmse / f.per_tick : 0.0, f.max_reference,
                steps ? steps->largest(group) : 0.0, steps ? steps->percentile99(group) : 0.0, ahead);
  }
}

void printVariant(const std::string& task, const Variant& variant, const Tally& t, const TrialRunner& runner,
                  const Options& o) {
  const std::size_t n = static_cast<std::size_t>(t.n);
  std::printf("%-9s %-14s %5d/%-3zu %12.4f %12s %10.1f %9d %12.3f\n", task.c_str(), variant.name.c_str(), t.ok, n,
              t.error_sum / n,
              task == "type" ? std::to_string(static_cast<int>(std::lround(t.keysPerMinute()))).c_str() : "-",
              adroit::percentile(t.plan_ms, 50), t.diverged, adroit::percentile(t.start_errors, 50));
  std::printf("%-9s %-14s plan ms, table 6.2 split (median over trials): rollout %.1f, derivatives %.1f, cost %.1f, "
              "backward %.1f, line search %.1f\n",
              "", "", adroit::percentile(t.phase_ms[0], 50), adroit::percentile(t.phase_ms[1], 50),
              adroit::percentile(t.phase_ms[2], 50), adroit::percentile(t.phase_ms[3], 50),
              adroit::percentile(t.phase_ms[4], 50));
  if (task == "type")  // a wrong key backspaced still counts as right in keys right, not here
    std::printf("%-9s %-14s presses %d, wrong presses %d (%.1f %%), keys right %d/%d, keys typed unasked %d\n", "",
                "", t.presses, t.wrong_presses, t.wrongPercent(), t.keys_ok, t.keys_all, t.unasked);
  if (task == "type" && o.idle > 0)
    std::printf("%-9s %-14s at rest for %.1f s before each sequence: %d key(s) typed unasked, in %d of %zu trials\n",
                "", "", o.idle, t.unasked, t.unasked_trials, n);
  if (variant.pneumatic) printPoolAudit(runner);
  std::fflush(stdout);
}

// Every variant on the task's trials, paired: trial k runs under every variant before trial
// k + 1 does, so a change in this shared machine's speed during the run falls on all variants
// alike (run in blocks, the variant run last would take all of a slowdown). Prints a row per
// variant; returns the tallies in variant order.
std::vector<Tally> runTask(const std::string& task, const Options& o, const success::World& world, Outputs& out) {
  const auto specs = trialsOf(task, o, world);
  if (task == "relocate") printRelocateBaseline(specs, o);
  std::vector<std::unique_ptr<TrialRunner>> runners;
  for (const auto& variant : o.variants) runners.push_back(makeRunner(task, variant, o, world));
  std::vector<Tally> tallies(o.variants.size());
  for (const auto& spec : specs) {
    for (std::size_t v = 0; v < o.variants.size(); ++v) {
      runners[v]->resetTrace();
      if (o.print_events) printTrialStart(task, o.variants[v], spec);
      const TrialResult r = runners[v]->run(spec);
      if (o.print_events) std::printf("  end: error %.4f m%s\n", r.final_error, r.success ? " (success)" : "");
      tallies[v].add(r);
      out.record(task, o.variants[v], spec, r, *runners[v], &spec == &specs.front());
      std::fflush(stdout);
    }
  }
  for (std::size_t v = 0; v < o.variants.size(); ++v) printVariant(task, o.variants[v], tallies[v], *runners[v], o);
  return tallies;
}

// --latency-sweep: iLQG on every task again at each fixed planning latency.
void runLatencySweep(const Options& o, std::ofstream& trials_csv) {
  for (const auto& task : o.latency_sweep.empty() ? std::vector<std::string>{} : o.tasks) {
    const auto specs = makeTrials(task, o.trials, o.seed, o.world);
    std::printf("\n%s, iLQG, success against a fixed planning latency (simulated s per optimisation):\n",
                task.c_str());
    TrialRunner runner(task, knownVariants().at("ilqg"), o.overrides, o.world, o.contact_margin, o.contact_softness);
    runner.setParams(o.paramsOf(task));
    if (o.compensation != "task") runner.setCompensation(o.compensation == "on");
    if (o.feedback_scale >= 0) runner.setFeedbackScale(o.feedback_scale);
    for (const auto& value : o.latency_sweep) {
      const double latency = std::atof(value.c_str());
      runner.setFixedLatency(latency);
      int ok = 0, keys_ok = 0, keys_all = 0;
      for (const auto& spec : specs) {
        runner.resetTrace();
        const TrialResult r = runner.run(spec);
        ok += r.success;
        keys_ok += r.keys_correct;
        keys_all += r.keys_total;
        trials_csv << task << ",latency_" << value << "," << spec.index << "," << r.success << "," << r.final_error
                   << "," << (r.lowest_z > 1e8 ? 0 : r.lowest_z) << "," << r.farthest_from_grasp << ","
                   << r.keys_correct << "," << r.keys_total << "," << r.duration << "," << 1e3 * latency << ","
                   << r.diverged << "," << r.unasked << "\n";
      }
      if (task == "type")
        std::printf("  latency %5.0f ms: %d/%zu sequences, %d/%d keys\n", 1e3 * latency, ok, specs.size(), keys_ok,
                    keys_all);
      else
        std::printf("  latency %5.0f ms: %d/%zu\n", 1e3 * latency, ok, specs.size());
      std::fflush(stdout);
    }
  }
}

void result(const std::string& name, double value, const char* unit, const char* op, double target) {
  const bool pass = std::strcmp(op, ">=") == 0 ? value >= target : value <= target;
  std::printf("RESULT adroit_mpc/%s %.2f %s target %s %.2f %s\n", name.c_str(), value, unit, op, target,
              pass ? "PASS" : "FAIL");
}

// A figure in percent against a whole-number target ("... 93.3 % target >= 90 PASS").
void resultPercent(const std::string& name, double percent, const char* op, double target) {
  const bool pass = std::strcmp(op, ">=") == 0 ? percent >= target : percent <= target;
  std::printf("RESULT adroit_mpc/%s %.1f %% target %s %g %s\n", name.c_str(), percent, op, target,
              pass ? "PASS" : "FAIL");
}

using TaskTallies = std::map<std::string, std::vector<Tally>>;  // task -> per variant (Options order)

const Tally& tallyOf(const TaskTallies& tallies, const Options& o, const std::string& task, const std::string& name) {
  for (std::size_t v = 0; v < o.variants.size(); ++v)
    if (o.variants[v].name == name) return tallies.at(task)[v];
  throw std::logic_error("no variant " + name);
}

// The RESULT lines of the run without --sweep. The figures are in pneumatic mode (the
// pools tracking the plan); without that variant the force-mode iLQG figures stand in (and say so).
void printResults(const Options& o, const TaskTallies& tallies) {
  const auto ratio = [&](const std::string& task, const std::string& variant) {
    const Tally& t = tallyOf(tallies, o, task, variant);
    return task == "type" ? t.keysRate() : t.successRate();
  };
  const std::string primary = o.has("pneumatic") ? "pneumatic" : o.has("ilqg") ? "ilqg" : "";
  if (!primary.empty()) {
    const std::string suffix = primary == "pneumatic" ? "" : "_force_mode";
    const std::map<std::string, std::pair<std::string, double>> figure = {
        {"catch", {"catch_success_rate", 0.8}}, {"relocate", {"relocate_success_rate", 0.8}},
        {"type", {"typing_keys_correct_rate", 0.9}}};
    for (const auto& task : o.tasks)
      result(figure.at(task).first + suffix, ratio(task, primary), "ratio", ">=", figure.at(task).second);
  }
  if (o.has("as_planned") && o.has("ilqg")) {  // how much of the shortfall is the planning model's
    for (const auto& task : o.tasks)
      std::printf("%s: iLQG %.2f against the physical world, %.2f against a world that is its planning model%s\n",
                  task.c_str(), ratio(task, "ilqg"), ratio(task, "as_planned"),
                  task == "type" ? "" : " (pruned contacts: no oracle for an object task)");
  }
  if (o.has("pneumatic") && o.has("ilqg")) {  // chapter 7's claim: the pools make cylinders force actuators
    for (const auto& task : o.tasks) {
      const double force = ratio(task, "ilqg"), pneumatic = ratio(task, "pneumatic");
      result(task + "_pneumatic_over_force", force > 0 ? pneumatic / force : 0.0, "ratio", ">=", 0.9);
    }
  }
  if (tallies.count("type"))  // issue 38: wrong presses at most 10 % of all presses, in both modes
    for (std::size_t v = 0; v < o.variants.size(); ++v)
      resultPercent("type_" + o.variants[v].name + "_wrong_press_percent", tallies.at("type")[v].wrongPercent(),
                    "<=", 10);
}

void printHeader(const Options& o) {
  std::printf("Behaviour MPC success, %d trial(s) per task, emulated real time on this machine (seed %u)\n", o.trials,
              o.seed);
  if (const std::string world = success::describe(o.world); !world.empty())
    std::printf("world, beyond the tasks' tuning: %s\n", world.c_str());
  std::printf("\n");
}

// The run without --sweep: the table, the CSVs, the plots, the RESULT lines.
int runDefault(const Options& o) {
  Outputs out;
  if (!out.open(o.out_dir, false)) {
    std::fprintf(stderr, "mpc_success: cannot write into %s\n", o.out_dir.c_str());
    return 2;
  }
  printTableHeader();
  TaskTallies tallies;
  for (const auto& task : o.tasks) tallies[task] = runTask(task, o, o.world, out);
  runLatencySweep(o, out.trials);
  out.trials.close();
  out.traces.close();
  out.presses.close();

  // plot_success.py is installed next to this program.
  const std::string script = std::filesystem::read_symlink("/proc/self/exe").parent_path() / "plot_success.py";
  const auto plot = adroit::runProgram({"python3", script, o.out_dir}, adroit::ProgramOptions{});
  if (!plot.ok()) std::printf("\n(plotting failed: %s)\n", plot.describe().c_str());
  else std::printf("\nplots: %s/success_<task>.png\n", o.out_dir.c_str());
  std::printf("\n");
  printResults(o, tallies);
  return 0;
}

// One sweep's success per task and variant across its values, then a RESULT line per point.
struct SweepTable {
  success::Sweep sweep;
  std::vector<TaskTallies> points;  // per value
};

void printSweepTable(const SweepTable& s, const Options& o) {
  std::printf("\nsuccess across %s (%% of trials; type: %% of keys right; wrong presses in brackets)\n",
              s.sweep.name.c_str());
  std::printf("%-9s %-14s", "task", "variant");
  for (const auto& value : s.sweep.values) std::printf(" %16s", value.c_str());
  std::printf("\n");
  for (const auto& task : o.tasks) {
    for (const auto& variant : o.variants) {
      std::printf("%-9s %-14s", task.c_str(), variant.name.c_str());
      for (const auto& point : s.points) {
        const Tally& t = tallyOf(point, o, task, variant.name);
        char cell[40];
        if (task == "type")
          std::snprintf(cell, sizeof cell, "%.0f (%.0f)", t.successPercent(task), t.wrongPercent());
        else
          std::snprintf(cell, sizeof cell, "%.0f", t.successPercent(task));
        std::printf(" %16s", cell);
      }
      std::printf("\n");
    }
  }
}

void printSweepResults(const SweepTable& s, const Options& o) {
  for (std::size_t k = 0; k < s.sweep.values.size(); ++k)
    for (const auto& task : o.tasks)
      for (const auto& variant : o.variants)
        resultPercent(task + "_" + variant.name + "_success_" + s.sweep.name + "_" + s.sweep.values[k],
                      tallyOf(s.points[k], o, task, variant.name).successPercent(task), ">=", 90);
}

// --sweep: the tasks and variants again for each value of each swept option, the rest of the
// world as the command line has it.
int runSweeps(const Options& o) {
  Outputs out;
  if (!out.open(o.out_dir, true)) {
    std::fprintf(stderr, "mpc_success: cannot write into %s\n", o.out_dir.c_str());
    return 2;
  }
  std::vector<SweepTable> tables;
  for (const auto& sweep : o.sweeps) {
    tables.push_back({sweep, {}});
    for (const auto& value : sweep.values) {
      success::World world = o.world;
      success::setWorldOption(world, sweep.name, value);  // checked by parseSweep
      std::printf("\n%s = %s: %s\n", sweep.name.c_str(), value.c_str(), success::describe(world).c_str());
      printTableHeader();
      out.point = sweep.name + "," + value;
      TaskTallies tallies;
      for (const auto& task : o.tasks) tallies[task] = runTask(task, o, world, out);
      tables.back().points.push_back(tallies);
    }
  }
  for (const auto& table : tables) printSweepTable(table, o);
  std::printf("\ntrials: %s/success_sweep.csv\n\n", o.out_dir.c_str());
  for (const auto& table : tables) printSweepResults(table, o);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const Options options = parseOptions(argc, argv);
  printHeader(options);
  return options.sweeps.empty() ? runDefault(options) : runSweeps(options);
}
