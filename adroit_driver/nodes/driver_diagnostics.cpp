// Diagnostics (default queue, ~diagnostics_period) and the safety monitor (safety queue,
// 20 Hz): each e-stop, watchdog trip and fault logged once with its cause, /adroit/safe_state
// on change, and whether anyone listens to the markers.
#include <chrono>

#include <diagnostic_msgs/DiagnosticStatus.h>

#include "adroit_ros/diagnostics.h"
#include "robot_driver.h"

namespace adroit::driver {

namespace {

// What the operator does after a fault, naming only services this robot obeys: the
// simulation resets; the hardware refuses /adroit/reset (a bus that went down needs
// /adroit/recover, anything else its cause cleared on the robot).
const char* faultRemedy(bool simulated) {
  return simulated ? "call /adroit/reset, then /adroit/estop_release"
                   : "clear its cause (/adroit/recover reopens a bus that is down), then /adroit/estop_release";
}

}  // namespace

void RobotDriver::publishSafeStateIfChanged() {
  bool safe;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    safe = robot_->safety().safe_state;
  }
  // Called from the safety queue and, once, from the constructor: never concurrently.
  if (safe_published_once_ && safe == last_safe_published_) return;
  safe_published_once_ = true;
  last_safe_published_ = safe;
  std_msgs::Bool msg;
  msg.data = safe;
  safe_pub_.publish(msg);
}

void RobotDriver::onSafetyMonitor(const ros::WallTimerEvent&) {
  markers_wanted_ = marker_pub_.getNumSubscribers() > 0;
  SafetyEvents events;
  Counters counters;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);  // plain data: no allocation under the lock
    events = robot_->safetyEvents();
    counters = robot_->counters();
  }
  // Each kind's latest event once; events of a kind that came and went between two looks
  // (20 Hz) are counted, not lost.
  const auto report = [&](std::uint64_t now, std::uint64_t& seen, const SafetyEvent& latest, const char* what) {
    if (now == seen) return;
    const std::uint64_t missed = now - seen - 1;
    seen = now;
    if (missed > 0)
      ROS_WARN("%s: safe state: %s (%lu more %s events before it)", name_, robot_->describe(latest).c_str(),
               static_cast<unsigned long>(missed), what);
    else
      ROS_WARN("%s: safe state: %s", name_, robot_->describe(latest).c_str());
  };
  report(counters.watchdog_trips, logged_.watchdog_trips, events.watchdog, "watchdog");
  if (counters.faults != logged_.faults) {  // a fault is an error, not a warning
    ROS_ERROR("%s: safe state: %s; %s", name_, robot_->describe(events.fault).c_str(),
              faultRemedy(robot_->simulated()));
    logged_.faults = counters.faults;
  }
  logged_.estops = counters.estops;  // e-stops are logged where they arrive (sim_services.cpp)
  publishSafeStateIfChanged();
}

void RobotDriver::onDiagnostics(const ros::WallTimerEvent&) {
  SafetyStatus safety;
  Counters counters;
  double clock, physics_time;
  std::size_t never_commanded;
  double command_age_max;
  std::string never_commanded_names;
  DiagnosticValues robot_values;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    safety = robot_->safety();
    counters = robot_->counters();
    clock = robot_->clock();
    physics_time = robot_->data()->time;
    never_commanded = robot_->neverCommanded();
    command_age_max = robot_->takeCommandAgeMax();
    for (std::size_t i = 0; i < commanded_snapshot_.size(); ++i) commanded_snapshot_[i] = robot_->everCommanded(i);
    robot_->addDiagnostics(&robot_values);  // the hardware's buses and boards (live state: under the lock)
  }
  if (never_commanded > 0) {  // names from the model (constant), built outside the lock
    const auto& names = robot_->cylinderNames();
    std::size_t listed = 0;
    for (std::size_t i = 0; i < names.size() && listed < 8; ++i) {
      if (commanded_snapshot_[i]) continue;
      never_commanded_names += (listed++ ? " " : "") + names[i];
    }
    if (never_commanded > listed) never_commanded_names += " ...";
  }
  bool paused;
  std::uint64_t cancellations;
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    paused = paused_;
    cancellations = step_cancellations_;
  }
  const double wall = wallSeconds();
  double rtf = 0, steps_per_second = 0;
  {
    // Only swaps under the lock; the spare keeps its reserved storage for the next window.
    std::lock_guard<std::mutex> lock(stats_mutex_);
    if (window_wall_ > 0 && wall > window_wall_) {
      rtf = (clock - window_clock_) / (wall - window_wall_);
      steps_per_second = (counters.steps - window_steps_) / (wall - window_wall_);
    }
    window_wall_ = wall;
    window_clock_ = clock;
    window_steps_ = counters.steps;
    std::swap(timing_, timing_spare_);
  }
  StepTiming& window = timing_spare_;  // this window's samples, ours until the next swap
  total_misses_ += window.deadline_misses;
  total_resyncs_ += window.resyncs;

  rosutil::StatusBuilder s(name_, robot_->simulated() ? "simulation" : "hardware");
  s.add("mode", modeName(robot_->mode()));
  s.add("time_mode", robot_->drivenByInput() ? "input-driven" : params_.realtime ? "realtime" : "lockstep");
  s.add("paused", paused);
  s.add("clock", clock);
  s.add("physics_time", physics_time);
  s.add("real_time_factor", rtf);
  s.add("steps_per_second", steps_per_second);
  s.add("step_time", formatSummary(window.step_time.summary(), 1e6, "us"));
  s.add("publication_lateness", formatSummary(window.lateness.summary(), 1e6, "us"));
  s.add("timing_samples_dropped", window.dropped);
  s.add("deadline_misses", total_misses_);
  const int fifo = fifo_priority_, nice = thread_nice_;
  s.add("thread_scheduling", fifo > 0    ? "SCHED_FIFO " + std::to_string(fifo)
                             : nice != 0 ? "normal, nice " + std::to_string(nice)
                                         : std::string("normal"));
  const int publisher_fifo = publisher_fifo_priority_;
  s.add("publisher_scheduling", publisher_fifo > 0 ? "SCHED_FIFO " + std::to_string(publisher_fifo) : std::string("normal"));
  const int safety_fifo = safety_queue_.priority();
  s.add("safety_scheduling", safety_fifo > 0 ? "SCHED_FIFO " + std::to_string(safety_fifo) : std::string("normal"));
  s.add("transport_scheduling",
        transport_fifo_priority_ > 0 ? "SCHED_FIFO " + std::to_string(transport_fifo_priority_.load()) : std::string("normal"));
  s.add("schedule_resyncs", total_resyncs_);
  s.add("safe_state", safety.safe_state);
  s.add("estop_latched", safety.estop_latched);
  s.add("estop_input", safety.estop_input);
  s.add("estop_input_changes", estop_input_changes_.load());
  s.add("watchdog_armed", safety.watchdog_armed);
  s.add("watchdog_latched", safety.watchdog_latched);
  s.add("watchdog_timeout", robot_->watchdogTimeout());
  s.add("never_commanded", never_commanded);
  s.add("command_age_max_ms", command_age_max * 1e3);  // the watchdog's margin over the window
  s.add("never_commanded_names", never_commanded_names);
  s.add("fault_latched", safety.fault_latched);
  s.add("fault_persists", safety.fault_persists);
  s.add("fault", safety.fault);
  s.add("steps", counters.steps);
  s.add("step_requests_cancelled", cancellations);
  s.add("commands_accepted", counters.accepted);
  s.add("commands_clamped", counters.clamped);
  s.add("rejected_total", counters.rejected());
  s.add("rejected_addressing", counters.rejected_addressing);
  s.add("rejected_name", counters.rejected_name);
  s.add("rejected_not_finite", counters.rejected_not_finite);
  s.add("rejected_range", counters.rejected_range);
  s.add("rejected_wrong_mode", counters.rejected_wrong_mode);
  s.add("ignored_while_safe", counters.ignored_while_safe);
  s.add("nonfinite_states_suppressed", nonfinite_suppressed_.load());
  s.add("watchdog_trips", counters.watchdog_trips);
  s.add("estops", counters.estops);
  s.add("faults", counters.faults);
  s.add("faulted_steps", counters.faulted_steps);
  for (const auto& [key, value] : robot_values) s.add(key, value);
  window.step_time.clear();  // keeps the reserved storage
  window.lateness.clear();
  window.deadline_misses = window.resyncs = window.dropped = 0;

  using Status = diagnostic_msgs::DiagnosticStatus;
  if (safety.fault_latched) s.raise(Status::ERROR, "fault latched: " + safety.fault);
  if (safety.safe_state)
    s.raise(Status::WARN, safety.estop_latched ? "safe state: e-stop" : "safe state: command watchdog");
  if (never_commanded > 0 && wall - released_wall_ >= params_.never_commanded_grace)
    s.raise(Status::WARN, std::to_string(never_commanded) + " cylinders never commanded (not watched): " +
                              never_commanded_names);
  s.raise(Status::OK, paused ? "paused" : "running");
  s.publish(diag_pub_);
}

}  // namespace adroit::driver
