// Publication: the simulation thread queues each step's outputs in a preallocated ring; the
// publisher thread fills the messages, serialises and sends them (and /clock, tf, markers).
#include <boost/make_shared.hpp>


#include <chrono>

#include <rosgraph_msgs/Clock.h>

#include "adroit_core/scheduling.h"
#include "object_odometry.h"
#include "robot_driver.h"

namespace adroit::driver {

void RobotDriver::publishDue(bool all, double wall_now, bool flush) {
  std::uint64_t slot_index;
  {
    std::unique_lock<std::mutex> lock(publish_mutex_);
    published_cv_.wait(lock, [this] { return queued_batches_ - published_batches_ < kRingSize || !running_; });
    if (!running_ && !all) return;
    slot_index = queued_batches_;
  }
  // The slot is this thread's until queued_batches_ moves past it; its vectors keep their
  // size, so the copies below allocate nothing.
  Batch& batch = ring_[slot_index % kRingSize];
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    const std::uint64_t k = robot_->counters().steps;
    // A faulted physics state may hold NaN: such a state is never published (the safe
    // state and the fault are reported through diagnostics and /adroit/safe_state).
    const bool finite = robot_->sensedIsFinite();
    if (!finite) nonfinite_suppressed_.fetch_add(1, std::memory_order_relaxed);
    batch.all = all;
    batch.clock = params_.use_sim_time && !all;
    if (robot_->drivenByInput()) {  // each output when a new sample of it is in
      const unsigned due = all ? ~0u : fresh_;
      fresh_ = 0;
      batch.joints = finite && (due & Robot::kJoints);
      batch.actuators = finite && (due & Robot::kActuators);
      batch.touch = finite && (due & Robot::kTouch);
      batch.object = finite && robot_->hasObject() && (due & Robot::kObject);
      batch.base = false;
    } else {
      batch.joints = finite && (all || k % joint_every_ == 0);
      batch.actuators = finite && (all || k % actuator_every_ == 0);
      batch.touch = finite && (all || k % touch_every_ == 0);
      batch.object = finite && robot_->hasObject() && (all || k % object_every_ == 0);
      batch.base = finite && robot_->hasFreeBase() && (all || k % object_every_ == 0);
    }
    batch.latency = latency_due_ && !all;
    if (batch.latency) {
      batch.command_stamp = latency_stamp_;
      batch.command_applied = latency_applied_;
      latency_due_ = false;
    }
    batch.sim_clock = robot_->clock();
    batch.stamp = stamp();
    if (batch.joints || batch.actuators || batch.touch || batch.object || batch.base) batch.signals = robot_->sensed();
    if (batch.actuators) batch.command = robot_->appliedCommand();
    batch.markers = false;
    if (params_.marker_rate > 0 && markers_wanted_.load(std::memory_order_relaxed) &&
        (all || wall_now - last_marker_wall_ >= 1.0 / params_.marker_rate)) {
      takeMarkerSnapshot();
      last_marker_wall_ = wall_now;
      batch.markers = true;
    }
  }
  bool wake = false;
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    ++queued_batches_;
    // Lockstep: waking the publisher costs more than handing it a batch; a polling
    // publisher finds the batch by itself (see kPollPeriod). The order does not change.
    wake = publisher_idle_ ||
           (publisher_polling_ && (flush || queued_batches_ - published_batches_ >= kRingSize / 2));
  }
  if (wake) work_cv_.notify_one();
}

void RobotDriver::flushPublication() {
  bool wake;
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    wake = (publisher_idle_ || publisher_polling_) && queued_batches_ > published_batches_;
  }
  if (wake) work_cv_.notify_one();
}

std::uint64_t RobotDriver::queuedBatches() {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  return queued_batches_;
}

void RobotDriver::waitForPublication(std::uint64_t batches) {
  // Bounded wait: a stopping driver must not hang the service thread.
  std::unique_lock<std::mutex> lock(publish_mutex_);
  published_cv_.wait_for(lock, std::chrono::seconds(2), [&] { return published_batches_ >= batches || !running_; });
}

void RobotDriver::publishLoop() {
  // Real time: the states leave at their deadlines only if this thread runs when woken, so
  // it runs under SCHED_FIFO just below the simulation thread (it sleeps between states;
  // the simulation thread's start-up says whether SCHED_FIFO is permitted at all).
  if (params_.realtime && params_.realtime_priority > 1 && enterFifo(params_.realtime_priority - 1, nullptr))
    publisher_fifo_priority_ = params_.realtime_priority - 1;
  bool streaming = false;  // batches keep coming: look again by itself
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(publish_mutex_);
      const auto ready = [this] { return published_batches_ < queued_batches_ || !publisher_running_; };
      if (streaming && !ready()) {
        publisher_polling_ = true;
        streaming = work_cv_.wait_for(lock, kPollPeriod, ready);
        publisher_polling_ = false;
      }
      if (!ready()) {  // nothing for a poll period: sleep until woken
        publisher_idle_ = true;
        work_cv_.wait(lock, ready);
        publisher_idle_ = false;
      }
      if (published_batches_ == queued_batches_) return;  // stopping and drained
    }
    publishQueued();
    streaming = true;
  }
}

void RobotDriver::publishQueued() {
  std::uint64_t first, end;
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    first = published_batches_;
    end = queued_batches_;  // everything queued: one wake-up for many steps
  }
  if (first == end) return;
  // One /clock for the chunk, with its newest time, ahead of the chunk's messages: a stamp
  // still never arrives ahead of the clock. Publishing every step's clock would cost every
  // sim-time node of the graph a message per step (see README).
  for (std::uint64_t i = end; i-- > first;) {
    if (ring_[i % kRingSize].clock) {
      publishClock(ring_[i % kRingSize].sim_clock);
      break;
    }
  }
  for (std::uint64_t i = first; i < end; ++i) publishBatch(ring_[i % kRingSize]);
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    published_batches_ = end;
  }
  published_cv_.notify_all();  // room for the simulation thread; services waiting for a republish
}

void RobotDriver::publishClock(double sim_clock) {
  // By shared pointer: this node's own /clock subscription (roscpp subscribes every node to
  // /clock under /use_sim_time) then gets the message directly, without a serialisation.
  auto clock = boost::make_shared<rosgraph_msgs::Clock>();
  clock->clock = ros::Time(sim_clock);
  clock_pub_.publish(clock);
}

void RobotDriver::publishBatch(const Batch& batch) {
  fillMessages(batch);
  if (batch.joints) {
    joint_pub_.publish(joint_msg_);
    if (collect_joint_intervals_.load(std::memory_order_relaxed)) {
      const double wall_now = wallSeconds();
      std::lock_guard<std::mutex> lock(intervals_mutex_);
      if (!batch.all && last_joint_wall_ > 0) joint_intervals_.push_back(wall_now - last_joint_wall_);
      last_joint_wall_ = batch.all ? -1 : wall_now;
    }
  }
  if (batch.actuators) actuator_pub_.publish(actuator_msg_);
  if (batch.touch) touch_pub_.publish(touch_msg_);
  if (batch.object) {
    odom_pub_.publish(odom_msg_);
    tf_->sendTransform(object_tf_);
  }
  if (batch.base) tf_->sendTransform(base_tf_);
  if (batch.latency) latency_pub_.publish(latency_msg_);
  if (batch.markers) publishMarkers();
}

void RobotDriver::fillMessages(const Batch& batch) {
  const Signals& s = batch.signals;
  if (batch.joints) {
    joint_msg_.header.stamp = batch.stamp;
    joint_msg_.position = s.joint_position;
    joint_msg_.velocity = s.joint_velocity;
    joint_msg_.effort = s.joint_effort;
  }
  if (batch.actuators) {
    actuator_msg_.header.stamp = batch.stamp;
    actuator_msg_.pressure = s.pressure;
    actuator_msg_.length = s.length;
    actuator_msg_.length_rate = s.length_rate;
    actuator_msg_.force = s.tension;
    actuator_msg_.command = batch.command;
    actuator_msg_.supply_pressure = s.supply_pressure;
  }
  if (batch.touch) {
    touch_msg_.header.stamp = batch.stamp;
    touch_msg_.force = s.touch;
  }
  if (batch.object) {
    odom_msg_.header.stamp = batch.stamp;
    fillObjectOdometry(s.object, &odom_msg_, &object_tf_);
  }
  if (batch.base) {
    const auto& b = s.base;
    base_tf_.header.stamp = batch.stamp;
    auto& t = base_tf_.transform;
    t.translation.x = b[0], t.translation.y = b[1], t.translation.z = b[2];
    t.rotation.w = b[3], t.rotation.x = b[4], t.rotation.y = b[5], t.rotation.z = b[6];
  }
  if (batch.latency) {
    latency_msg_.header.stamp = batch.command_stamp;
    latency_msg_.applied = batch.command_applied;
    latency_msg_.latency = (batch.command_applied - batch.command_stamp).toSec();
  }
}

}  // namespace adroit::driver
