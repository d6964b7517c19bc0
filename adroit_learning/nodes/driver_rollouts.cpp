#include "driver_rollouts.h"

#include <adroit_core/scheduling.h>
#include <adroit_learning/sim_rollouts.h>
#include <adroit_msgs/Reset.h>
#include <adroit_msgs/Step.h>
#include <std_srvs/SetBool.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>
#include <utility>

namespace adroit::learning_node {

namespace {

// States of the last physics steps count as "after" a step ending at t: the actuator and
// object streams run at every second physics step.
constexpr double kStampSlack = 0.0045;
// Physics steps after a reset, on the hold command: every stream has published the reset
// state by then (SimRollouts settles the same way).
constexpr int kSettleSteps = 2;
// Realtime: how often the keep-alive re-sends the hold command between rollouts (the driver's
// command watchdog trips after 50 ms without a command).
constexpr double kKeepAlivePeriod = 0.01;
// Below the driver's command path (adroit_ros/realtime.h) and the trainer's roscpp threads,
// which write what it publishes; above everything under normal scheduling.
constexpr int kKeepAlivePriority = 10;
// A one-shot service call that fails in transport is tried this often in all.
constexpr int kCallAttempts = 3;

// A one-shot (non-persistent) roscpp call now and then fails in transport on a loaded machine
// (ros_comm #1976: the server's close is seen before its answer is read; CI once lost a
// rollout to it). Pause and reset are idempotent, so such a failure is retried; an answer,
// success or refusal, is final.
template <class Service>
bool callRetryingTransport(ros::ServiceClient& client, Service& service) {
  for (int attempt = 1; attempt <= kCallAttempts; ++attempt) {
    if (client.call(service)) return true;
    if (attempt < kCallAttempts) client.waitForExistence(ros::Duration(0.5));
  }
  return false;
}

}  // namespace

DriverConnection::DriverConnection(ros::NodeHandle& nh, const std::string& ns, double timeout, Pacing pacing,
                                   std::vector<std::string> touch)
    : ns_(ns), timeout_(timeout), touch_names_(std::move(touch)), pacing_(pacing) {
  ros::NodeHandle d(nh, ns);
  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay();
  joints_sub_ = d.subscribe("joint_states", 20, &DriverConnection::onJoints, this, hints);
  actuators_sub_ = d.subscribe("actuator_states", 20, &DriverConnection::onActuators, this, hints);
  odom_sub_ = d.subscribe("object/odom", 20, &DriverConnection::onOdometry, this, hints);
  safe_sub_ = d.subscribe("safe_state", 1, &DriverConnection::onSafeState, this);
  if (!touch_names_.empty()) touch_sub_ = d.subscribe("touch", 20, &DriverConnection::onTouch, this, hints);
  valve_pub_ = d.advertise<adroit_msgs::ValveCommand>("valve_command", 10);
  // Only the lockstep step service (called every control step) keeps its connection open.
  // Destroying a persistent client can race in roscpp (ros_comm #1989: a dropped connection's
  // mutex used after its destruction), the likely cause of the one "boost::lock_error" crash
  // seen at the end of a realtime job; resets and pauses come once per rollout, where a new
  // connection costs a few milliseconds.
  step_client_ = d.serviceClient<adroit_msgs::Step>("step", pacing_ == Pacing::kLockstep);
  reset_client_ = d.serviceClient<adroit_msgs::Reset>("reset");
  pause_client_ = d.serviceClient<std_srvs::SetBool>("pause");
  if (pacing_ == Pacing::kRealtime) keep_alive_ = std::thread(&DriverConnection::keepAlive, this);
}

DriverConnection::~DriverConnection() {
  // First stop the callbacks: another spinner thread may be inside one, and the members it
  // writes (the latest messages, the mutex) are destroyed before the subscribers would be.
  // shutdown() waits for a callback in progress (ASan: heap-use-after-free of the latest
  // actuator state when execute_policy ended while states still arrived).
  for (ros::Subscriber* s : {&joints_sub_, &actuators_sub_, &odom_sub_, &safe_sub_, &touch_sub_}) s->shutdown();
  // Realtime: when the keep-alive ends the driver's command watchdog takes it to its safe
  // state, as it must on hardware. A simulation driver is paused instead (its watchdog runs on
  // its clock), and the next job starts it again.
  if (pacing_ == Pacing::kRealtime && holding_.load()) {
    std_srvs::SetBool pause;
    pause.request.data = true;
    if (!pause_client_.exists() || !pause_client_.call(pause) || !pause.response.success)
      ROS_WARN("adroit_learning: driver %s cannot be paused: without the trainer's commands its watchdog takes it to "
               "its safe state",
               ns_.c_str());
  }
  {
    std::lock_guard<PiMutex> lock(command_mutex_);
    stop_.store(true);
  }
  command_cv_.notify_all();
  if (keep_alive_.joinable()) keep_alive_.join();
}

// Its own thread on wall time, so a stalled callback queue or a long update never starves it;
// under SCHED_FIFO where permitted (it sleeps between periods), so neither does a busy machine.
// It publishes every command of the realtime pacing: a new one at once, then again after each
// period without one.
void DriverConnection::keepAlive() {
  std::string why;
  if (!enterFifo(kKeepAlivePriority, &why))
    ROS_WARN_ONCE("adroit_learning: keep-alive thread under normal scheduling (%s): on a busy machine the driver's "
                  "command watchdog may trip",
                  why.c_str());
  const auto period = std::chrono::duration<double>(kKeepAlivePeriod);
  std::unique_lock<PiMutex> lock(command_mutex_);
  while (!stop_.load()) {
    command_cv_.wait_for(lock, period, [&] { return send_now_ || stop_.load(); });
    send_now_ = false;
    if (stop_.load() || hold_volts_.empty()) continue;  // nothing to hold before the streams are up
    if (!holding_.load()) {
      const double age = std::chrono::duration<double>(std::chrono::steady_clock::now() - last_send_).count();
      if (age <= repeat_for_) {
        publish(latest_volts_);  // the rollout's latest command, freshly stamped
        continue;
      }
      holding_.store(true);  // the rollout stalled: hold rather than repeat a stale command
      ++stalls_;
    }
    publish(hold_volts_);
  }
}

void DriverConnection::holdAt(std::vector<double> volts) {
  {
    std::lock_guard<PiMutex> lock(command_mutex_);
    hold_volts_ = std::move(volts);
    holding_.store(true);
    send_now_ = true;
  }
  command_cv_.notify_one();
}

void DriverConnection::onJoints(const sensor_msgs::JointState::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  joints_ = msg;
  cv_.notify_all();
}
void DriverConnection::onActuators(const adroit_msgs::ActuatorStates::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  actuators_ = msg;
  cv_.notify_all();
}
void DriverConnection::onOdometry(const nav_msgs::Odometry::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  odom_ = msg;
  cv_.notify_all();
}
void DriverConnection::onTouch(const adroit_msgs::Touch::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  touch_ = msg;
}
void DriverConnection::onSafeState(const std_msgs::Bool::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  safe_state_ = msg->data;
  cv_.notify_all();  // a wait for states ends: a driver in its safe state after a fault publishes none
}

bool DriverConnection::safe(std::string& error) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!safe_state_) return true;
  error = "driver " + ns_ + " is in its safe state (e-stop, watchdog or fault); release it with " + ns_ +
          "/estop_release once it is safe";
  return false;
}

bool DriverConnection::waitForStreams(std::string& error) {
  const auto have = [&] { return joints_ && actuators_; };
  if (pacing_ == Pacing::kRealtime) {
    // Realtime pacing needs a running driver: a paused simulation driver is started (hardware
    // has no pause service). Only once our topics are connected both ways: the hold command
    // below must reach it within its watchdog time after the start.
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_);
    while (joints_sub_.getNumPublishers() == 0 || actuators_sub_.getNumPublishers() == 0 ||
           valve_pub_.getNumSubscribers() == 0) {
      if (ros::WallTime::now() > deadline) {
        error = "driver " + ns_ + ": joint_states / actuator_states / valve_command not connected within " +
                std::to_string(timeout_) + " s";
        return false;
      }
      ros::WallDuration(0.01).sleep();
    }
    std_srvs::SetBool run;
    run.request.data = false;
    if (pause_client_.waitForExistence(ros::Duration(std::min(timeout_, 1.0)))) pause_client_.call(run);
    std::unique_lock<std::mutex> lock(mutex_);
    if (cv_.wait_for(lock, std::chrono::duration<double>(timeout_), have)) {
      // From now on the valves are held (0 V: sealed) until a rollout commands them, so
      // neither the checks before the first reset nor the first update trip the watchdog.
      holdAt(std::vector<double>(actuators_->name.size(), 0.0));
      return true;
    }
    error = "driver " + ns_ + ": no joint_states / actuator_states within " + std::to_string(timeout_) +
            " s (realtime pacing needs a running driver)";
    return false;
  }
  {
    std::unique_lock<std::mutex> lock(mutex_);
    if (cv_.wait_for(lock, std::chrono::duration<double>(std::min(timeout_, 1.0)), have)) return true;
  }
  // A paused (lockstep) driver publishes nothing until stepped: pause and step it once, with
  // no command stamp (no command needed, and none arms its watchdog).
  if (!step_client_.waitForExistence(ros::Duration(timeout_))) {
    error = "driver " + ns_ + ": no step service within " + std::to_string(timeout_) + " s";
    return false;
  }
  // What the step publishes is lost unless our subscriptions are connected first.
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_);
  while (joints_sub_.getNumPublishers() == 0 || actuators_sub_.getNumPublishers() == 0) {
    if (ros::WallTime::now() > deadline) {
      error = "driver " + ns_ + ": joint_states / actuator_states have no publisher";
      return false;
    }
    ros::WallDuration(0.01).sleep();
  }
  std_srvs::SetBool pause;
  pause.request.data = true;
  adroit_msgs::Step step;
  step.request.steps = kSettleSteps;
  if (!callRetryingTransport(pause_client_, pause) || !step_client_.call(step) || !step.response.success) {
    error = "driver " + ns_ + ": could not pause and step it: " + pause.response.message + " " + step.response.message;
    return false;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  if (cv_.wait_for(lock, std::chrono::duration<double>(timeout_), have)) return true;
  error = "driver " + ns_ + ": no joint_states / actuator_states within " + std::to_string(timeout_) + " s" +
          (safe_state_ ? ": it is in its safe state (a physics fault publishes no state; its log says which)" : "");
  return false;
}

bool DriverConnection::publishesObject() {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(1.0);
  while (odom_sub_.getNumPublishers() == 0 && ros::WallTime::now() < deadline) ros::WallDuration(0.01).sleep();
  return odom_sub_.getNumPublishers() > 0;
}

std::vector<std::string> DriverConnection::jointNames() {
  std::lock_guard<std::mutex> lock(mutex_);
  return joints_ ? joints_->name : std::vector<std::string>{};
}

std::vector<std::string> DriverConnection::cylinderNames() {
  std::lock_guard<std::mutex> lock(mutex_);
  return actuators_ ? actuators_->name : std::vector<std::string>{};
}

bool DriverConnection::reset(const std::vector<double>& qpos, const std::vector<double>& pressure, double hold_volts,
                             std::string& error) {
  if (!safe(error)) return false;
  if (pacing_ == Pacing::kLockstep) {  // stepping needs a paused driver
    std_srvs::SetBool pause;
    pause.request.data = true;
    if (!callRetryingTransport(pause_client_, pause) || !pause.response.success) {
      error = "driver " + ns_ + ": pause failed: " + pause.response.message;
      return false;
    }
  }
  adroit_msgs::Reset reset;
  reset.request.qpos = qpos;
  reset.request.pressure = pressure;
  const bool called = callRetryingTransport(reset_client_, reset);
  if (called && !reset.response.success && pacing_ == Pacing::kRealtime &&
      reset.response.message.find("only in simulation") != std::string::npos)
    return resetByControl(pressure.size(), hold_volts, error);
  if (!called) {
    error = "driver " + ns_ + ": no answer from " + reset_client_.getService() + " in " +
            std::to_string(kCallAttempts) + " calls";
    return false;
  }
  if (!reset.response.success) {
    error = "driver " + ns_ + ": reset refused: " + reset.response.message;
    return false;
  }
  if (pacing_ == Pacing::kRealtime) {
    reset_floor_ = ros::Time::now();  // states stamped before now may show the old state
    holdAt(std::vector<double>(pressure.size(), hold_volts));
    return true;
  }
  // A few physics steps on the hold command: afterwards every stream shows the reset state,
  // and nothing stamped before the reset counts as fresh.
  reset_floor_ = sim_time_;
  return send(std::vector<double>(pressure.size(), hold_volts), error) && step(kSettleSteps, error);
}

// A real robot cannot be teleported: every cylinder is exhausted for kRealResetSettle, so the
// hand comes to rest in its passive posture, then sealed at the hold command; the rollout
// starts from there (the initial state is measured, not set, as on the thesis's hardware).
bool DriverConnection::resetByControl(std::size_t cylinders, double hold_volts, std::string& error) {
  holdAt(std::vector<double>(cylinders, kExhaustVolts));
  ros::WallDuration(kRealResetSettle).sleep();
  if (!safe(error)) return false;
  holdAt(std::vector<double>(cylinders, hold_volts));
  reset_floor_ = ros::Time::now();
  ++resets_by_control_;
  return true;
}

bool DriverConnection::send(const std::vector<double>& volts, std::string& error) {
  (void)error;
  std::unique_lock<PiMutex> lock(command_mutex_);
  if (pacing_ == Pacing::kLockstep) {
    publish(volts);
    return true;
  }
  latest_volts_ = volts;
  holding_.store(false);
  last_send_ = std::chrono::steady_clock::now();
  send_now_ = true;
  lock.unlock();
  command_cv_.notify_one();
  return true;
}

void DriverConnection::hold() {
  if (pacing_ != Pacing::kRealtime) return;
  // At once: the rollout's last command is already a control step old.
  {
    std::lock_guard<PiMutex> lock(command_mutex_);
    holding_.store(true);
    send_now_ = true;
  }
  command_cv_.notify_one();
}

void DriverConnection::publish(const std::vector<double>& volts) {
  command_.index.resize(volts.size());
  for (std::size_t i = 0; i < volts.size(); ++i) command_.index[i] = static_cast<std::uint16_t>(i);
  command_.volts = volts;
  command_.name.clear();
  // Stamps only need to increase: the driver steps once a command at or after the stamp came.
  ros::Time stamp = ros::Time::now();
  if (stamp <= last_stamp_) stamp = last_stamp_ + ros::Duration(0, 1000);
  last_stamp_ = stamp;
  command_.header.stamp = stamp;
  valve_pub_.publish(command_);
}

bool DriverConnection::advance(int steps, double dt, std::string& error) {
  if (pacing_ == Pacing::kLockstep) return step(steps, error);
  {
    std::lock_guard<PiMutex> lock(command_mutex_);
    repeat_for_ = 2.0 * dt;
  }
  next_tick_ += ros::Duration(dt);
  const ros::Duration wait = next_tick_ - ros::Time::now();
  if (wait > ros::Duration(0)) wait.sleep();
  else if (-wait.toSec() > 0.5 * dt) ++late_ticks_;
  return safe(error);
}

bool DriverConnection::step(int steps, std::string& error) {
  adroit_msgs::Step srv;
  srv.request.steps = static_cast<std::uint32_t>(steps);
  srv.request.command_stamp = last_stamp_;
  if (!step_client_.call(srv)) {
    error = "driver " + ns_ + ": step service unavailable";
    return false;
  }
  if (!srv.response.success) {
    error = "driver " + ns_ + ": step failed: " + srv.response.message;
    return false;
  }
  sim_time_ = ros::Time(srv.response.sim_time);
  return safe(error);
}

bool DriverConnection::observe(int t, Observation& obs, std::string& error) {
  if (pacing_ == Pacing::kLockstep) return waitForState(sim_time_ - ros::Duration(kStampSlack), obs, error);
  if (!waitForState(t == 0 ? reset_floor_ : last_observed_ + ros::Duration(0, 1), obs, error)) return false;
  if (t == 0) next_tick_ = ros::Time::now();
  return true;
}

bool DriverConnection::waitForState(ros::Time min_stamp, Observation& obs, std::string& error) {
  if (min_stamp <= reset_floor_) min_stamp = reset_floor_ + ros::Duration(0, 1);
  std::unique_lock<std::mutex> lock(mutex_);
  const auto fresh = [&] {
    return joints_ && actuators_ && joints_->header.stamp >= min_stamp && actuators_->header.stamp >= min_stamp &&
           (odom_sub_.getNumPublishers() == 0 || (odom_ && odom_->header.stamp >= min_stamp));
  };
  cv_.wait_for(lock, std::chrono::duration<double>(timeout_), [&] { return fresh() || safe_state_; });
  if (!fresh()) {
    const auto newest = [](const auto& msg) { return msg ? std::to_string(msg->header.stamp.toSec()) + " s" : "none"; };
    error = "driver " + ns_ + ": no state stamped after " + std::to_string(min_stamp.toSec()) + " s within " +
            std::to_string(timeout_) + " s (newest joint_states " + newest(joints_) + ", actuator_states " +
            newest(actuators_) + ")" +
            (safe_state_ ? ": it is in its safe state (a physics fault publishes no state; its log says which)" : "");
    return false;
  }
  last_observed_ = joints_->header.stamp;
  obs.joint_position = joints_->position;
  obs.joint_velocity = joints_->velocity;
  obs.pressure = actuators_->pressure;
  if (!touchFromMessage(obs.touch, error)) return false;
  if (odom_) {
    // Odometry carries both velocities in the object frame; the state, as the driver's
    // signals, has the linear one in the world frame.
    const auto& p = odom_->pose.pose;
    const double quat[4] = {p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z};
    const auto& v = odom_->twist.twist.linear;
    const auto& w = odom_->twist.twist.angular;
    double rot[9], linear_body[3] = {v.x, v.y, v.z}, linear_world[3];
    mju_quat2Mat(rot, quat);
    mju_rotVecMat(linear_world, linear_body, rot);
    obs.object = {p.position.x, p.position.y, p.position.z, quat[0], quat[1], quat[2], quat[3],
                  linear_world[0], linear_world[1], linear_world[2], w.x, w.y, w.z};
  }
  return true;
}

// The touch sensors of touch_names_ from the newest touch message, by name (a driver may list
// more). None yet, or one missing: the robot cannot give what a touch-reading policy needs.
bool DriverConnection::touchFromMessage(std::vector<double>& touch, std::string& error) const {
  touch.resize(touch_names_.size());
  if (touch_names_.empty()) return true;
  if (!touch_) {
    error = "driver " + ns_ + ": no touch message yet on " + ns_ + "/touch";
    return false;
  }
  for (std::size_t i = 0; i < touch_names_.size(); ++i) {
    const auto it = std::find(touch_->name.begin(), touch_->name.end(), touch_names_[i]);
    if (it == touch_->name.end() || static_cast<std::size_t>(it - touch_->name.begin()) >= touch_->force.size()) {
      error = "driver " + ns_ + ": its touch message has no sensor '" + touch_names_[i] + "'";
      return false;
    }
    touch[i] = touch_->force[it - touch_->name.begin()];
  }
  return true;
}

DriverRollouts::DriverRollouts(ros::NodeHandle& nh, const std::vector<std::string>& namespaces, ModelPtr model,
                               double timeout, Pacing pacing)
    : model_(std::move(model)) {
  std::vector<std::string> model_touch;
  for (int s = 0; s < model_->nsensor; ++s)
    if (model_->sensor_type[s] == mjSENS_TOUCH) model_touch.push_back(mj_id2name(model_.get(), mjOBJ_SENSOR, s));
  for (int i : fingertipTouch(model_touch)) touch_.push_back(model_touch[i]);
  for (const auto& ns : namespaces)
    drivers_.push_back(std::make_unique<DriverConnection>(nh, ns, timeout, pacing, touch_));
  for (auto& d : drivers_) {
    std::string error;
    if (!d->waitForStreams(error)) throw std::runtime_error(error);
    if (joints_.empty()) {
      joints_ = d->jointNames();
      cylinders_ = d->cylinderNames();
    } else if (d->jointNames() != joints_ || d->cylinderNames() != cylinders_) {
      throw std::runtime_error("driver " + d->ns() + " runs another robot than " + drivers_.front()->ns());
    }
  }
  // The drivers must run the task's scene: every joint they report is in the model.
  for (const auto& j : joints_)
    if (mj_name2id(model_.get(), mjOBJ_JOINT, j.c_str()) < 0)
      throw std::runtime_error("driver " + drivers_.front()->ns() + " reports joint '" + j +
                               "', which the task's scene does not have: start the driver with the task's scene");
  if (static_cast<int>(cylinders_.size()) != model_->nu)
    throw std::runtime_error("driver " + drivers_.front()->ns() + " has " + std::to_string(cylinders_.size()) +
                             " cylinders, the task's scene " + std::to_string(model_->nu));
  for (int j = 0; j < model_->njnt; ++j) has_object_ = has_object_ || model_->jnt_type[j] == mjJNT_FREE;
  // The hand and tube scenes share joints and cylinders: the object stream tells them apart.
  for (auto& d : drivers_)
    if (d->publishesObject() != has_object_)
      throw std::runtime_error("driver " + d->ns() + (has_object_ ? " publishes no object odometry, but the task's scene has an object"
                                                                  : " publishes object odometry, but the task's scene has none") +
                               ": start the driver with the task's scene");
}

std::vector<double> DriverRollouts::jointRanges() const { return adroit::jointRanges(model_.get(), joints_); }

ObjectGeometry DriverRollouts::objectGeometry() const { return adroit::objectGeometry(model_.get()); }

Eigen::VectorXd DriverRollouts::initialState(const TrainingTask& task, const StateLayout& layout) {
  DriverConnection& d = *drivers_.front();
  std::string error;
  Observation obs;
  if (!d.reset(initialQpos(model_.get(), task, joints_, {}), std::vector<double>(cylinders_.size(), task.initial_pressure),
               task.locked_command, error) ||
      !d.observe(0, obs, error))
    throw std::runtime_error(error);
  Eigen::VectorXd x(layout.nx());
  layout.state(obs, x);
  return x;
}

template <class Act>
RolloutResult DriverRollouts::runOne(DriverConnection& d, const TrainingTask& task, const StateLayout& layout,
                                     const RolloutRequest& request, int steps, Act&& act,
                                     const std::atomic<bool>& cancel) {
  RolloutResult failed;
  failed.error = objectYawProblem(request);
  if (!failed.error.empty()) return failed;
  const std::uint64_t resets_by_control = d.resetsByControl();
  if (!d.reset(initialQpos(model_.get(), task, joints_, request.joint_offset, request.object_yaw_deg),
               std::vector<double>(cylinders_.size(), task.initial_pressure), task.locked_command, failed.error))
    return failed;
  // A real robot is reset by control: nothing places its object, so a requested yaw cannot hold.
  if (request.object_yaw_deg && d.resetsByControl() != resets_by_control) {  // the valves stay held
    failed.error = "driver " + d.ns() + " cannot set the object's yaw (a real robot is reset by control): place the "
                   "object by hand and run without object_yaw_deg";
    return failed;
  }
  const int substeps = static_cast<int>(std::lround(task.control_dt / model_->opt.timestep));
  int t = 0;
  const int late_before = d.lateTicks(), stalls_before = d.stalls();
  RolloutResult result = runControlLoop(
      layout, steps, cancel, std::forward<Act>(act),
      [&](Observation& obs, std::string& error) { return d.observe(t++, obs, error); },
      [&](const std::vector<double>& volts, std::string& error) { return d.send(volts, error); },
      [&](std::string& error) { return d.advance(substeps, task.control_dt, error); });
  d.hold();
  if (d.lateTicks() > late_before)  // realtime: the policy was not evaluated at the control rate throughout
    ROS_WARN("adroit_learning: driver %s: %d of %d control steps of the rollout came more than half a step late",
             d.ns().c_str(), d.lateTicks() - late_before, steps);
  if (d.stalls() > stalls_before)
    ROS_WARN("adroit_learning: driver %s: the rollout sent no command for two control steps %d time(s); the "
             "valves were held meanwhile",
             d.ns().c_str(), d.stalls() - stalls_before);
  return result;
}

template <class Rollout>
std::vector<RolloutResult> DriverRollouts::runOnDrivers(const std::vector<RolloutRequest>& requests,
                                                        Rollout&& rollout) {
  std::vector<RolloutResult> results(requests.size());
  std::vector<std::thread> threads;
  for (std::size_t k = 0; k < drivers_.size(); ++k)
    threads.emplace_back([&, k] {
      for (std::size_t i = k; i < requests.size(); i += drivers_.size()) results[i] = rollout(*drivers_[k], requests[i]);
    });
  for (auto& t : threads) t.join();
  return results;
}

std::vector<RolloutResult> DriverRollouts::run(const TrainingTask& task, const StateLayout& layout,
                                               const LgController& controller,
                                               const std::vector<RolloutRequest>& requests,
                                               const std::atomic<bool>& cancel) {
  return runOnDrivers(requests, [&](DriverConnection& d, const RolloutRequest& request) {
    return runOne(d, task, layout, request, controller.horizon(), controllerAction(controller, request.noise), cancel);
  });
}

std::vector<RolloutResult> DriverRollouts::runPolicy(const TrainingTask& task, const StateLayout& layout,
                                                     const PolicyFactory& make_policy,
                                                     const std::vector<RolloutRequest>& requests, int steps,
                                                     const std::atomic<bool>& cancel) {
  return runOnDrivers(requests, [&](DriverConnection& d, const RolloutRequest& request) {
    RolloutResult failed;
    int rollout_steps = steps;
    std::unique_ptr<Policy> policy = policyForRollout(make_policy, *this, layout, task, rollout_steps, failed.error);
    if (!policy) return failed;
    return runOne(d, task, layout, request, rollout_steps, policyAction(*policy), cancel);
  });
}

}  // namespace adroit::learning_node
