// Commands and services. The safety path (commands, e-stop input and service, release,
// pause) runs on its own queue and thread; /step, /reset and /set_object_pose run on the
// default queue and never hold the robot while they wait.
#include <chrono>

#include "robot_driver.h"

namespace adroit::driver {

// ---------------------------------------------------------------------------- commands (safety queue)

namespace {
bool validCommand(const CommandResult& result) {
  return result.verdict == CommandVerdict::kAccepted || result.verdict == CommandVerdict::kClamped;
}
}  // namespace

void RobotDriver::reportCommand(const char* topic, const CommandResult& result) {
  if (result.applied) return;
  if (!validCommand(result)) {
    ROS_ERROR_THROTTLE(1.0, "%s: %s rejected: %s", name_, topic, result.error.c_str());
    return;
  }
  // A valid command while the safe state holds is expected (the senders keep running until
  // release; at shutdown their last commands land here): said once per safe-state episode.
  if (!warned_ignored_while_safe_.exchange(true))
    ROS_WARN("%s: %s and further commands ignored until /adroit/estop_release: %s", name_, topic,
             result.error.c_str());
}

void RobotDriver::onValveCommand(const adroit_msgs::ValveCommand::ConstPtr& msg) {
  // Addressing and values are checked before the robot is locked; under the lock only the
  // checked values are copied in.
  const CheckedCommand checked = robot_->checkValves(msg->name, msg->index, msg->volts);
  CommandResult result;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    result = robot_->applyValves(checked);
    // The hardware sends the valve frames from applyValves: the command acts now.
    if (result.applied && robot_->drivenByInput() && msg->header.stamp > applied_command_stamp_) {
      applied_command_stamp_ = latency_stamp_ = msg->header.stamp;
      latency_applied_ = ros::Time(ros::WallTime::now().toSec());
      latency_due_ = true;
    }
  }
  reportCommand("valve_command", result);
  if (validCommand(result)) noteCommandStamp(msg->header.stamp);
}

void RobotDriver::onForceCommand(const adroit_msgs::TendonForceCommand::ConstPtr& msg) {
  const CheckedCommand checked = robot_->checkForces(msg->name, msg->index, msg->force);
  CommandResult result;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    result = robot_->applyForces(checked);
  }
  reportCommand("tendon_force_command", result);
  if (validCommand(result)) noteCommandStamp(msg->header.stamp);
}

void RobotDriver::onBaseTarget(const geometry_msgs::PoseStamped::ConstPtr& msg) {
  std::string error;
  bool ok = msg->header.frame_id.empty() || msg->header.frame_id == "world";
  if (!ok) {
    error = "frame '" + msg->header.frame_id + "' is not 'world' (transform the mocap stream first)";
  } else {
    const auto& p = msg->pose.position;
    const auto& q = msg->pose.orientation;
    std::lock_guard<PiMutex> lock(robot_mutex_);
    ok = robot_->setBaseTarget({p.x, p.y, p.z}, {q.w, q.x, q.y, q.z}, &error);
  }
  if (ok) {
    ++base_targets_;
    return;
  }
  ++base_targets_rejected_;
  ROS_ERROR_THROTTLE(1.0, "%s: hand_base/target rejected: %s", name_, error.c_str());
}

void RobotDriver::noteCommandStamp(const ros::Time& stamp) {
  std::lock_guard<std::mutex> lock(control_mutex_);
  if (stamp <= last_command_stamp_) return;
  last_command_stamp_ = stamp;
  control_cv_.notify_all();
}

void RobotDriver::cancelSteps(const char* why) {
  std::lock_guard<std::mutex> lock(control_mutex_);
  if (pending_steps_ == 0) return;
  pending_steps_ = 0;
  step_interruption_ = why;
  ++step_cancellations_;
  control_cv_.notify_all();
}

void RobotDriver::onEstopInput(const std_msgs::Bool::ConstPtr& msg) {
  bool pressed;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    pressed = msg->data && !robot_->safety().estop_input;
    if (msg->data != robot_->safety().estop_input) ++estop_input_changes_;
    // Cancelled under the robot lock: no step starts between the latch and the cancel.
    if (pressed) cancelSteps("cancelled by the e-stop input");
    robot_->setEstopInput(msg->data);
  }
  if (pressed) {
    // A bouncing contact toggles at kHz: one line a second, with the count.
    ROS_WARN_THROTTLE(1.0, "%s: e-stop input held: safe state (%lu input changes so far)", name_,
                      static_cast<unsigned long>(estop_input_changes_.load()));
  }
  publishSafeStateIfChanged();
}

bool RobotDriver::onEstop(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  double clock;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    // Cancelled under the robot lock: after the latch at most the step the simulation
    // thread had already begun waiting for the lock runs.
    cancelSteps("cancelled by /adroit/estop");
    robot_->estop();
    clock = robot_->clock();
  }
  ROS_WARN_THROTTLE(1.0, "%s: e-stop: supply exhausted, every valve open to exhaust (latched)", name_);
  publishSafeStateIfChanged();
  res.success = true;
  res.message = std::string("e-stop latched at ") + (robot_->simulated() ? "simulated time " : "robot clock ") +
                std::to_string(clock) + " s";
  return true;
}

bool RobotDriver::onRelease(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    res.success = robot_->release(&res.message);
  }
  if (res.success) {
    warned_ignored_while_safe_ = false;
    released_wall_ = wallSeconds();
    ROS_INFO("%s: safe state %s", name_, res.message.c_str());
  } else {
    ROS_WARN("%s: release %s", name_, res.message.c_str());
  }
  publishSafeStateIfChanged();
  return true;
}

bool RobotDriver::onRecover(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    res.success = robot_->recover(&res.message);
  }
  if (res.success) ROS_INFO("%s: recover: %s", name_, res.message.c_str());
  else ROS_WARN("%s: recover failed: %s", name_, res.message.c_str());
  return true;
}

bool RobotDriver::onPause(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res) {
  if (!robot_->simulated()) {  // a real robot cannot stop time: it always runs
    res.success = !req.data;
    res.message = req.data ? "a real robot cannot be paused (use /adroit/estop to stop it)" : "running";
    return true;
  }
  std::lock_guard<std::mutex> lock(control_mutex_);
  paused_ = req.data;
  if (pending_steps_ > 0) {  // a running /step ends here, unsuccessful
    pending_steps_ = 0;
    step_interruption_ = req.data ? "cancelled by /adroit/pause" : "cancelled: the simulation was resumed";
    ++step_cancellations_;
  }
  control_cv_.notify_all();
  res.success = true;
  res.message = paused_ ? "paused" : "running";
  return true;
}

// ---------------------------------------------------------------------------- services (default queue)

bool RobotDriver::onStep(adroit_msgs::Step::Request& req, adroit_msgs::Step::Response& res) {
  std::unique_lock<std::mutex> lock(control_mutex_);
  if (!robot_->simulated()) {
    res.success = false;
    res.message = "step exists only in simulation: this robot is real and runs on wall time";
  } else if (!paused_) {
    res.success = false;
    res.message = "the simulation is running; pause it (/adroit/pause) before stepping";
  } else if (req.steps > kMaxStepsPerRequest) {
    res.success = false;
    res.message = "at most " + std::to_string(kMaxStepsPerRequest) + " steps per request, asked for " +
                  std::to_string(req.steps);
  } else if (!req.command_stamp.isZero() &&
             !control_cv_.wait_for(lock, std::chrono::seconds(2), [&] {
               return last_command_stamp_ >= req.command_stamp || !running_ || !paused_;
             })) {
    // Lockstep: the command for this period travels on its own topic; stepping before it
    // arrived would run the period on the previous command.
    res.success = false;
    res.message = "no valid force or valve command stamped at or after " + std::to_string(req.command_stamp.toSec()) +
                  " s arrived within 2 s (newest " + std::to_string(last_command_stamp_.toSec()) + " s)";
  } else if (!paused_ || !running_) {
    res.success = false;
    res.message = !running_ ? "the driver is stopping" : "the simulation was resumed while waiting for the command";
  } else if (req.steps > 0) {
    const std::uint64_t cancellations = step_cancellations_;
    pending_steps_ += req.steps;
    control_cv_.notify_all();
    // The wait ends when the steps are done, cancelled (pause, e-stop) or the driver stops;
    // the budget (100x slower than real time) only guards against a stalled simulation.
    const double budget = 10.0 + req.steps * robot_->timestep() * 100.0;
    const bool ended = control_cv_.wait_for(lock, std::chrono::duration<double>(budget), [&] {
      return pending_steps_ == 0 || !running_ || step_cancellations_ != cancellations;
    });
    const bool cancelled = step_cancellations_ != cancellations;
    res.success = ended && !cancelled && pending_steps_ == 0 && running_;
    res.message = res.success ? "stepped"
                  : cancelled ? "stepping " + step_interruption_
                  : !running_ ? "stepping interrupted: the driver is stopping"
                              : "stepping timed out";
  } else {
    res.success = true;
    res.message = "nothing to do";
  }
  lock.unlock();
  // Answer once the stepped states are out, so a caller sees them before the reply.
  waitForPublication(queuedBatches());
  std::lock_guard<PiMutex> robot_lock(robot_mutex_);
  res.sim_time = robot_->clock();
  return true;
}

bool RobotDriver::changeState(const std::function<bool(std::string*)>& change, std::string* error) {
  std::unique_lock<std::mutex> lock(control_mutex_);
  control_cv_.wait(lock, [this] { return !pending_change_ || !running_; });  // one change at a time
  if (!running_) return *error = "the driver is stopping", false;
  pending_change_ = &change;
  change_done_ = false;
  control_cv_.notify_all();
  // No time-out: the simulation thread runs the change between two steps (microseconds to
  // a millisecond), and `change` must outlive its use there.
  control_cv_.wait(lock, [this] { return change_done_ || (!running_ && !change_running_); });
  const bool ok = change_done_ && change_ok_;
  *error = change_done_ ? change_error_ : "the driver is stopping";
  const std::uint64_t published = change_published_;
  pending_change_ = nullptr;
  change_done_ = false;
  control_cv_.notify_all();
  lock.unlock();
  // A caller never receives a pre-change message after the answer.
  if (ok) waitForPublication(published);
  return ok;
}

bool RobotDriver::onReset(adroit_msgs::Reset::Request& req, adroit_msgs::Reset::Response& res) {
  const bool arrays = !req.qpos.empty() || !req.qvel.empty() || !req.pressure.empty();
  if (!req.keyframe.empty() && arrays) {
    res.success = false;
    res.message = "give either a keyframe or state arrays, not both";
    return true;
  }
  std::string error;
  res.success = changeState(
      [&](std::string* why) {
        return arrays ? robot_->resetToState(req.qpos, req.qvel, req.pressure, why)
                      : robot_->resetToKeyframe(req.keyframe, why);
      },
      &error);
  res.message = res.success ? "reset" : error;
  if (!res.success) ROS_WARN("%s: reset refused: %s", name_, error.c_str());
  return true;
}

bool RobotDriver::onSetObjectPose(adroit_msgs::SetObjectPose::Request& req, adroit_msgs::SetObjectPose::Response& res) {
  const auto& p = req.pose.position;
  const auto& q = req.pose.orientation;
  const auto& l = req.twist.linear;
  const auto& a = req.twist.angular;
  std::string error;
  res.success = changeState(
      [&](std::string* why) {
        return robot_->setObjectPose({p.x, p.y, p.z}, {q.w, q.x, q.y, q.z}, {l.x, l.y, l.z}, {a.x, a.y, a.z}, why);
      },
      &error);
  res.message = res.success ? "object placed" : error;
  if (!res.success) ROS_WARN("%s: set_object_pose refused: %s", name_, error.c_str());
  return true;
}

}  // namespace adroit::driver
