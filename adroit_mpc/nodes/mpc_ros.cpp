// Set-up, the planner thread, the control thread and the lockstep loop (see mpc_ros.h).
#include <adroit_msgs/Step.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <std_srvs/SetBool.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "adroit_core/scheduling.h"
#include "adroit_mpc/planning_model.h"
#include "adroit_mpc/synergies.h"
#include "mpc_ros.h"

namespace adroit::mpc_node {

namespace {

const char* const kTipSites[] = {"S_fftip", "S_mftip", "S_rftip", "S_lftip", "S_thtip"};

void sizeSnapshot(StateSnapshot& s, const mjModel* m) {
  s.qpos.assign(m->qpos0, m->qpos0 + m->nq);
  s.qvel.assign(m->nv, 0.0);
  s.act.assign(m->na, 0.0);
}

// Table 6.3: contacts seen coming 10 mm ahead with 5 mm softness for the object tasks; the
// keypad needs both at 1 mm (keys 6 mm apart in travel).
adroit_mpc::PlanningModelSettings planningSettings(const MpcParams& p) {
  adroit_mpc::PlanningModelSettings s;
  s.timestep = p.settings.dt;
  s.min_tension = p.min_tension;
  if (p.task == "type") s.contact_margin = 0.001, s.contact_softness = 0.001;
  return s;
}

}  // namespace

MpcNode::MpcNode(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh),
      pnh_(pnh),
      rejections_({"joint_states_length", "joint_states_nonfinite", "joint_states_missing_joint",
                   "odom_nonfinite", "odom_quaternion", "odom_frame", "goal", "task_name", "task_command"}) {
  params_ = readParams(pnh_);
  try {
    model_ = adroit_mpc::loadPlanningModel(params_.model_file, planningSettings(params_));
  } catch (const std::exception& e) {
    throw ParameterError("bad parameter " + pnh_.resolveName(pnh_.hasParam("model_file") ? "model_file" : "scene") +
                         ": " + e.what());
  }
  const mjModel* m = model_.get();
  tables_ = std::make_unique<ModelTables>(m);
  synergy_dims_ = params_.settings.synergies ? adroit_mpc::Synergies::kCount : 0;
  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] == mjJNT_HINGE || m->jnt_type[j] == mjJNT_SLIDE) hinge_joints_.push_back(j);
  }
  if (const auto j = tables_->joints.find("object_root"); j && m->jnt_type[*j] == mjJNT_FREE) {
    object_qpos_ = m->jnt_qposadr[*j];
    object_dof_ = m->jnt_dofadr[*j];
  }
  actuator_names_ = tables_->actuators.names();
  for (const char* site : kTipSites) {
    if (const auto s = tables_->sites.find(site)) tip_sites_.push_back(*s);
  }
  if (const auto b = tables_->bodies.find("object")) object_body_ = *b;

  for (StateSnapshot* s : {&incoming_, &plan_state_, &control_state_}) sizeSnapshot(*s, m);
  planner_state_.qpos = incoming_.qpos;
  planner_state_.qvel = incoming_.qvel;
  planner_state_.act = incoming_.act;
  marker_data_ = makeData(m);

  std::string why;
  std::unique_ptr<adroit_mpc::Task> task = buildTask(params_.task, &why);
  if (!task) throw ParameterError("bad parameter " + pnh_.resolveName("task") + ": " + why);
  task_name_ = params_.task;
  runner_ = std::make_unique<adroit_mpc::MpcRunner>(m, adroit_mpc::makePlanner(params_.planner), std::move(task),
                                                    params_.settings, runnerSettings());

  ctrl_.assign(m->nu, 0.0);
  force_msg_.index.resize(m->nu);
  for (int i = 0; i < m->nu; ++i) force_msg_.index[i] = static_cast<std::uint16_t>(i);
  force_msg_.force.assign(m->nu, 0.0);
  reference_msg_.name = actuator_names_;
  reference_msg_.dt = params_.settings.dt;
  const int max_knots = static_cast<int>(std::ceil(2.0 / params_.settings.dt)) + 2;  // the reconfigure limit
  reference_msg_.force.reserve(static_cast<std::size_t>(max_knots) * m->nu);
  reference_values_.assign(static_cast<std::size_t>(max_knots) * m->nu, 0.0);

  ros::NodeHandle mpc(nh_, "/adroit/mpc");
  force_pub_ = nh_.advertise<adroit_msgs::TendonForceCommand>("/adroit/tendon_force_command", 10);
  reference_pub_ = nh_.advertise<adroit_msgs::ForceReference>("/adroit/force_reference", 10);
  diag_pub_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 10);
  marker_pub_ = mpc.advertise<visualization_msgs::MarkerArray>("markers", 2);
  typed_pub_ = mpc.advertise<std_msgs::String>("typed", 20);
  events_pub_ = mpc.advertise<std_msgs::String>("events", 20);
  services_.push_back(mpc.advertiseService("set_task", &MpcNode::onSetTask, this));
  services_.push_back(mpc.advertiseService("release", &MpcNode::onRelease, this));
  goal_sub_ = mpc.subscribe("goal", 5, &MpcNode::onGoal, this);
  type_sub_ = mpc.subscribe("type", 5, &MpcNode::onType, this);

  // States on their own queue (started in start()).
  ros::NodeHandle state_nh(nh_);
  state_nh.setCallbackQueue(state_queue_.queue());
  joint_sub_ = state_nh.subscribe("/adroit/joint_states", 10, &MpcNode::onJointState, this,
                                  ros::TransportHints().tcpNoDelay());
  if (object_qpos_ >= 0)
    odom_sub_ = state_nh.subscribe("/adroit/object/odom", 10, &MpcNode::onOdometry, this,
                                   ros::TransportHints().tcpNoDelay());

  if (params_.lockstep) {
    step_client_ = nh_.serviceClient<adroit_msgs::Step>("/adroit/step");
    pause_client_ = nh_.serviceClient<std_srvs::SetBool>("/adroit/pause");
  }
  setupGoalMarker();
  // Dynamic reconfigure starts from the running task's weights and the horizon.
  {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    pnh_.setParam("horizon", params_.settings.horizon);
    for (const auto& w : runner_->task().weightNames()) pnh_.setParam(w, runner_->task().weight(w));
  }
  reconfigure_ = std::make_unique<dynamic_reconfigure::Server<Config>>(reconfigure_mutex_, pnh_);
  reconfigure_->setCallback([this](Config& config, uint32_t level) { onReconfigure(config, level); });
  reconfigure_ready_ = true;
  syncReconfigure();

  if (params_.marker_rate > 0)
    marker_timer_ = nh_.createWallTimer(ros::WallDuration(1.0 / params_.marker_rate), &MpcNode::onMarkerTimer, this);
  diag_timer_ = nh_.createWallTimer(ros::WallDuration(params_.diagnostics_period), &MpcNode::onDiagnostics, this);
}

MpcNode::~MpcNode() { stop(); }

void MpcNode::start() {
  running_ = true;
  // The states' whole path under SCHED_FIFO above the control loop (adroit_ros/realtime.h): in
  // force mode a state that arrives late stops the commands and trips the driver's watchdog.
  const int input_priority = params_.control_priority > 0 ? params_.control_priority + 2 : 0;
  state_queue_.start(input_priority);
  if (input_priority > 0) {
    std::string error;
    if (!rosutil::fifoRosThreads(input_priority, &error))
      ROS_WARN("adroit_mpc: roscpp's threads keep normal scheduling (%s): on a busy machine states may arrive late",
               error.c_str());
  }
  default_spinner_ = std::make_unique<ros::AsyncSpinner>(1);
  default_spinner_->start();
  if (params_.lockstep) {
    planner_thread_ = std::thread(&MpcNode::lockstepLoop, this);
  } else {
    planner_thread_ = std::thread(&MpcNode::plannerLoop, this);
    control_thread_ = std::thread(&MpcNode::controlLoop, this);
  }
  ROS_INFO("adroit_mpc: task %s, planner %s, %s mode%s, horizon %.3f s at dt %.4f s, derivatives every %d knot(s), "
           "%d iteration(s), synergies %s, model %s",
           task_name_.c_str(), params_.planner.c_str(), params_.force_mode ? "force" : "pneumatic",
           params_.lockstep ? " (lockstep)" : "", params_.settings.horizon, params_.settings.dt,
           params_.settings.derivative_skip, params_.settings.iterations, synergy_dims_ > 0 ? "on" : "off",
           params_.model_file.c_str());
}

void MpcNode::stop() {
  running_ = false;
  if (planner_thread_.joinable()) planner_thread_.join();
  if (control_thread_.joinable()) control_thread_.join();
  if (default_spinner_) default_spinner_->stop();
  state_queue_.stop();
}

// --- planner thread ------------------------------------------------------------------------

adroit_mpc::RunnerSettings MpcNode::runnerSettings() {
  adroit_mpc::RunnerSettings r;
  r.timing = adroit_mpc::PlanTiming::kRealTime;  // a plan is acted on from its publication
  r.clock = [this] { return nodeTime(ros::Time::now()); };  // the robot's clock: latency from a state's stamp
  r.latency_compensation = params_.latency_compensation;
  r.feedback_scale = params_.feedback_scale;
  r.on_events = [this](double, const std::vector<adroit_mpc::TaskEvent>& events) { publishEvents(events); };
  return r;
}

bool MpcNode::planOnce(const StateSnapshot& state) {
  planner_state_.time = state.time;
  std::copy(state.qpos.begin(), state.qpos.end(), planner_state_.qpos.begin());
  std::copy(state.qvel.begin(), state.qvel.end(), planner_state_.qvel.begin());
  std::copy(state.act.begin(), state.act.end(), planner_state_.act.begin());
  if (!runner_->planOnce(planner_state_).published) {
    ROS_WARN_THROTTLE(1.0, "adroit_mpc: solve diverged (non-finite cost); plan reset to the warm start, not published");
    return false;
  }
  if (markers_wanted_.load(std::memory_order_relaxed)) takeMarkerSnapshot();
  return true;
}

void MpcNode::enterOptimiserThread() {
  // Only the optimiser runs at ~nice: roscpp's threads and the state queue keep their weight,
  // so a busy optimiser never delays the joint states whose silence stops the MPC (at nice 19
  // for the whole node they arrived 0.1 s late whenever the machine was busy, and the driver's
  // watchdog took the robot to its safe state). The planner is re-initialised here so that its
  // worker threads are started by this thread and inherit the value.
  if (params_.nice > 0) {
    std::string error;
    if (!adroit::setThreadNice(params_.nice, &error)) ROS_WARN("adroit_mpc: ~nice %d: %s", params_.nice, error.c_str());
  }
  runner_->initializePlanner();
}

void MpcNode::plannerLoop() {
  enterOptimiserThread();
  while (running_ && ros::ok()) {
    if (stateAgeWall() > params_.state_timeout || !latestState(plan_state_)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    planOnce(plan_state_);
  }
}

void MpcNode::publishEvents(const std::vector<adroit_mpc::TaskEvent>& events) {
  for (const auto& e : events) {
    std_msgs::String msg;
    msg.data = e.kind + ": " + e.detail;
    events_pub_.publish(msg);
    if (e.kind == "key") {
      msg.data = e.detail;
      typed_pub_.publish(msg);
    }
  }
}

// --- control ---------------------------------------------------------------------------------

bool MpcNode::sendCommand(double t, const StateSnapshot& state) {
  double age = 0;
  // A policy older than its horizon says nothing about now (after a stall): send nothing.
  if (!runner_->usable(t, &age)) return false;
  if (!(params_.force_mode ? sendForces(t, state) : sendPolicyReference(t, state))) return false;
  publishing_ = true;
  runner_->recordPolicyAge(age);
  return true;
}

bool MpcNode::sendForces(double t, const StateSnapshot& state) {
  // False also for a non-finite control: the driver would reject it.
  if (!runner_->action(t, state.qpos.data(), state.qvel.data(), state.act.data(), ctrl_.data())) return false;
  for (std::size_t i = 0; i < ctrl_.size(); ++i) force_msg_.force[i] = std::max(0.0, ctrl_[i]);
  force_msg_.header.stamp = rosTime(t);
  force_pub_.publish(force_msg_);
  commands_sent_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

bool MpcNode::sendPolicyReference(double t, const StateSnapshot& state) {
  // The pools track the future, not just the present (thesis 7.4): the policy from now to its
  // horizon's end, with the feedback on the deviation measured now (PlanPolicy::reference).
  const std::size_t nu = actuator_names_.size();
  const int max_samples = static_cast<int>(reference_values_.size() / nu);
  // 0 also for a non-finite value: the pools would reject it.
  const int samples = runner_->reference(t, state.qpos.data(), state.qvel.data(), state.act.data(), max_samples,
                                         reference_values_.data());
  if (samples == 0) return false;
  const std::size_t n = static_cast<std::size_t>(samples) * nu;
  reference_msg_.header.stamp = rosTime(t);
  reference_msg_.dt = runner_->policy().policy.dt;
  reference_msg_.steps = static_cast<std::uint32_t>(samples);
  reference_msg_.force.resize(n);  // within the reserved capacity: no allocation
  for (std::size_t i = 0; i < n; ++i) reference_msg_.force[i] = std::max(0.0, reference_values_[i]);
  reference_pub_.publish(reference_msg_);
  references_sent_.fetch_add(1, std::memory_order_relaxed);
  return true;
}

void MpcNode::controlLoop() {
  // The optimiser runs at ~nice; the policy must still reach the driver or the pools at the
  // control rate whatever else runs, so this thread (asleep between periods) is SCHED_FIFO.
  if (params_.control_priority > 0) {
    std::string error;
    if (adroit::enterFifo(params_.control_priority, &error))
      ROS_INFO("adroit_mpc: control loop under SCHED_FIFO, priority %d", params_.control_priority);
    else
      ROS_WARN("adroit_mpc: ~control_priority %d: SCHED_FIFO not permitted (%s); the control loop keeps normal "
               "scheduling (grant an rtprio limit or CAP_SYS_NICE, or set ~control_priority: 0)",
               params_.control_priority, error.c_str());
  }
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / params_.control_rate));
  auto next = Clock::now();
  while (running_ && ros::ok()) {
    next += period;
    std::this_thread::sleep_until(next);
    const auto now = Clock::now();
    if (now - next > period) next = now;  // overrun: resynchronise rather than catch up
    if (stateAgeWall() > params_.state_timeout) {
      if (publishing_.exchange(false)) {
        stale_stops_.fetch_add(1, std::memory_order_relaxed);
        ROS_WARN("adroit_mpc: no joint state for %.3f s: stopped publishing (the driver's watchdog takes over)",
                 params_.state_timeout);
      }
      continue;
    }
    runner_->updatePolicy(nodeTime(ros::Time::now()));
    if (!runner_->hasPolicy() || !latestState(control_state_)) continue;
    sendCommand(nodeTime(ros::Time::now()), control_state_);
  }
}

// --- lockstep --------------------------------------------------------------------------------

bool MpcNode::callStep(std::uint32_t steps, double command_time, double* sim_time) {
  adroit_msgs::Step srv;
  srv.request.steps = steps;
  if (command_time >= 0) srv.request.command_stamp = rosTime(command_time);
  if (!step_client_.call(srv) || !srv.response.success) {
    lockstep_failures_.fetch_add(1, std::memory_order_relaxed);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: lockstep: /adroit/step failed: %s", srv.response.message.c_str());
    return false;
  }
  *sim_time = srv.response.sim_time;
  return true;
}

bool MpcNode::waitForState(double sim_time, StateSnapshot& out) {
  // The driver answers a step once its states are published; they may still be on the wire.
  // Joint states and odometry come on separate connections: both must have caught up. An
  // object stream slower than the joint states never does; then the joints decide, after a
  // grace period, and the run is no longer exactly reproducible (said once).
  const auto start = std::chrono::steady_clock::now();
  const auto deadline = start + std::chrono::seconds(2), grace = start + std::chrono::milliseconds(50);
  while (running_ && ros::ok() && std::chrono::steady_clock::now() < deadline) {
    if (latestState(out) && rosTime(out.time).toSec() >= sim_time - 1e-6) {
      if (object_qpos_ < 0 || rosTime(out.object_time).toSec() >= sim_time - 1e-6) return true;
      if (std::chrono::steady_clock::now() > grace) {
        ROS_WARN_ONCE("adroit_mpc: lockstep: object odometry lags the joint states (driver object_rate below "
                      "joint_state_rate?): planning on the newest odometry, the run is not exactly reproducible");
        return true;
      }
    }
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  return false;
}

void MpcNode::lockstepLoop() {
  enterOptimiserThread();
  const int steps_per_control =
      std::max(1, static_cast<int>(std::lround(1.0 / (params_.control_rate * params_.physics_timestep))));
  while (running_ && ros::ok()) {
    if (!step_client_.waitForExistence(ros::Duration(1.0)) || !pause_client_.waitForExistence(ros::Duration(1.0)))
      continue;
    std_srvs::SetBool pause;
    pause.request.data = true;
    if (!pause_client_.call(pause)) continue;
    break;
  }
  ROS_INFO("adroit_mpc: lockstep: %d physics step(s) of %.4f s per control, %d control(s) per plan",
           steps_per_control, params_.physics_timestep, params_.lockstep_controls_per_plan);
  double sim_time = 0;
  bool have_state = false;
  while (running_ && ros::ok()) {
    if (!have_state) {
      // A state at the current simulated time (a paused driver publishes none by itself).
      have_state = callStep(1, -1, &sim_time) && waitForState(sim_time, plan_state_);
      if (!have_state) {
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
        continue;
      }
    }
    planOnce(plan_state_);
    runner_->updatePolicy(plan_state_.time);  // the world waited: the plan takes over now
    control_state_.time = plan_state_.time;
    control_state_.object_time = plan_state_.object_time;
    control_state_.serial = plan_state_.serial;
    control_state_.qpos = plan_state_.qpos;  // same sizes: copies, no allocation
    control_state_.qvel = plan_state_.qvel;
    control_state_.act = plan_state_.act;
    for (int c = 0; c < params_.lockstep_controls_per_plan && running_; ++c) {
      // The command travels on its own topic: the driver steps once it has arrived.
      // Pneumatic mode: the reference goes to the pools, whose valve commands the driver
      // does not wait for.
      const bool sent = runner_->hasPolicy() && sendCommand(control_state_.time, control_state_);
      const bool wait = sent && params_.force_mode;
      if (!callStep(static_cast<std::uint32_t>(steps_per_control), wait ? control_state_.time : -1, &sim_time) ||
          !waitForState(sim_time, control_state_)) {
        have_state = false;
        publishing_ = false;
        ROS_WARN_THROTTLE(1.0, "adroit_mpc: lockstep: no state after stepping; retrying");
        break;
      }
    }
    if (!have_state) continue;
    plan_state_.time = control_state_.time;
    plan_state_.object_time = control_state_.object_time;
    plan_state_.serial = control_state_.serial;
    plan_state_.qpos = control_state_.qpos;
    plan_state_.qvel = control_state_.qvel;
    plan_state_.act = control_state_.act;
  }
}

}  // namespace adroit::mpc_node
