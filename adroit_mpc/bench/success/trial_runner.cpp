#include "trial_runner.h"

#include <adroit_core/timing_stats.h>
#include <adroit_description/scenes.h>
#include <adroit_pneumatics/params_io.h>
#include <adroit_pneumatics/plant.h>
#include <adroit_mpc/planning_model.h>
#include <adroit_mpc/synergies.h>
#include <adroit_mpc/task_params.h>
#include <adroit_mpc/type_task.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <stdexcept>
#include <utility>

using namespace adroit_mpc;
namespace pneumatics = adroit::pneumatics;

namespace success {

namespace {

// Optimisations before the trial starts: the MPC runs while the object is held (0.5 s at
// ~50 ms per iteration).
constexpr int kWarmupIterations = 10;
// Closed loop with the object held at its start before it is let go (s of simulated time).
// Relocation in pneumatic mode needs longer: the pools fill the arm's cylinders from
// atmosphere, and after 0.3 s the shoulder (ARJ2) was still sagging 0.28 rad under the arm's
// weight; by 1.5 s it holds its posture, as a running stack does before anything is dropped
// into the hand. (The other scenes have no arm; catch's bottle scene caught 16/20 instead of
// 20/20 on seed 3 in emulated real time with 1.5 s; not examined further.)
constexpr double kPreRoll = 0.3;
constexpr double kArmPreRoll = 1.5;

}  // namespace

TrialRunner::TrialRunner(const std::string& task, const Variant& variant, const PlannerSettings& overrides,
                         const success::World& world, double contact_margin, double contact_softness)
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

TrialResult TrialRunner::run(const TrialSpec& spec) {
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
  const bool arm_to_hold_up = variant_.pneumatic && task_name_ == "relocate";
  p.release = robot_->data()->time + (arm_to_hold_up ? kArmPreRoll : kPreRoll);
  p.sequence = p.release + (idle_first ? idle_ : 0.0);
  p.end = p.sequence + (task_name_ == "type" ? 1.5 * spec.keys.size() + 0.5 : duration_);
  closedLoop(spec, p, r);
  score(spec, p, r);
  return r;
}

void TrialRunner::resetWorld(const TrialSpec& spec) {
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

std::unique_ptr<Task> TrialRunner::makeTrialTask(const TrialSpec& spec, bool idle_first) const {
  TaskParams params;
  for (const auto& [key, value] : param_overrides_) params.numbers[key] = value;
  if (task_name_ == "catch") params.vectors["goal_position"] = {spec.goal.x(), spec.goal.y(), spec.goal.z()};
  auto task = makeTask(task_name_, params);
  task->bind(plan_model_.get(), variant_.synergies ? Synergies::kCount : 0);
  std::string why;
  if (!idle_first && !spec.keys.empty() && !task->setSequence(spec.keys, &why)) throw std::runtime_error(why);
  return task;
}

std::unique_ptr<MpcRunner> TrialRunner::makeRunner(std::unique_ptr<Task> task) {
  RunnerSettings rs;
  rs.timing = PlanTiming::kEmulated;
  rs.fixed_latency = fixed_latency_;
  rs.latency_compensation = variant_.compensate && compensation_;
  rs.feedback_scale = feedback_scale_;
  rs.on_events = [this](double t, const std::vector<TaskEvent>& events) { noteEvents(t, events); };
  return std::make_unique<MpcRunner>(plan_model_.get(), makePlanner(variant_.planner), std::move(task), settings_,
                                     std::move(rs));
}

void TrialRunner::closedLoop(const TrialSpec& spec, Progress& p, TrialResult& r) {
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

void TrialRunner::giveCommands(const TrialSpec& spec, Progress& p, TrialResult& r) {
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

void TrialRunner::recordPlan(const PlanOutcome& plan, Progress& p, TrialResult& r) const {
  const OptimizeReport& report = plan.report;
  const std::array<double, 5> split{report.rollout, report.derivatives, report.cost, report.backward,
                                    report.line_search};
  for (std::size_t k = 0; k < p.phases.size(); ++k) p.phases[k].push_back(split[k]);
  p.plan_seconds.push_back(plan.latency);
  if (!plan.published) ++r.diverged;
}

void TrialRunner::recordStartError(Progress& p, const std::vector<double>& plan_qpos) const {
  p.start_errors.push_back(jointDistance(plan_qpos));
}

void TrialRunner::takeOver(Reference& fresh_reference) {
  if (!runner_->updatePolicy(robot_->data()->time) || !variant_.open_loop_reference) return;
  std::swap(active_reference_, fresh_reference);
  sendReference(active_reference_);
}

void TrialRunner::score(const TrialSpec& spec, const Progress& p, TrialResult& r) {
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

double TrialRunner::taskError(const mjModel* m, const mjData* d) {
  std::lock_guard<std::mutex> lock(runner_->taskMutex());
  return runner_->task().error(m, d);
}

void TrialRunner::takeReference(const Trajectory& plan, double plan_time, Reference& out) const {
  const std::size_t knots = std::min(plan.ctrl.size(), plan.times.size());
  const std::size_t nu = all_actuators_.size();
  out.t0 = robot_->clock() + (plan.times.empty() ? 0 : plan.times[0] - plan_time);
  out.dt = settings_.dt;
  out.steps = knots;
  out.force.resize(knots * nu);
  for (std::size_t k = 0; k < knots; ++k)
    for (std::size_t j = 0; j < nu; ++j) out.force[k * nu + j] = std::max(0.0, plan.ctrl[k][j]);
}

void TrialRunner::sendReference(const Reference& ref) {
  if (!pool_ || ref.steps == 0) return;
  const auto verdict = pool_->setReference(robot_->clock(), ref.t0, ref.dt, ref.steps, robot_->cylinderNames(),
                                           ref.force);
  if (!verdict.ok()) throw std::runtime_error("pool rejected the plan's reference: " + verdict.detail);
  sent_ = ref;
}

void TrialRunner::observeState(const PlannerState& s) {
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

void TrialRunner::noteEvents(double t, const std::vector<TaskEvent>& events) {
  for (const auto& e : events) {
    keys_registered_ += e.kind == "key";
    if (print_events_) std::printf("  t %.3f %s %s\n", t, e.kind.c_str(), e.detail.c_str());
  }
}

void TrialRunner::stepOnce(TrialResult& r, const Eigen::Vector3d* hold_object) {
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

void TrialRunner::poolTick() {
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

void TrialRunner::writeForces(const std::string& path) const {
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

void TrialRunner::writeStates(const std::string& path, const TrialResult& r) const {
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

double TrialRunner::jointDistance(const std::vector<double>& qpos) const {
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

void TrialRunner::measure(std::vector<double>& qpos, std::vector<double>& qvel) const {
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

const std::vector<double>& TrialRunner::positive(const std::vector<double>& values, std::size_t n) {
  force_.resize(n);
  for (std::size_t i = 0; i < n; ++i) force_[i] = std::max(0.0, values[i]);
  return force_;
}

void TrialRunner::recordForceTracking(const adroit::driver::Signals& sensed) {
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

std::map<std::string, pneumatics::ForceTrackingAudit::Group> TrialRunner::forceTracking() const {
  return force_audit_ ? force_audit_->groups() : std::map<std::string, pneumatics::ForceTrackingAudit::Group>{};
}

std::map<std::string, std::vector<double>> TrialRunner::previewError() const {
  return preview_audit_ ? preview_audit_->groups() : std::map<std::string, std::vector<double>>{};
}

}  // namespace success
