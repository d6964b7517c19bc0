// The robot thread: steps the robot, paced at real time (states due at origin + k dt, wall)
// or in lockstep (as fast as possible, or a requested number of steps while paused), or, for
// a robot driven by its input (the hardware), as soon as input arrives; and queues each
// step's outputs for the publisher thread. After start-up it allocates
// nothing and logs nothing; the only lock it can meet held by another thread is
// robot_mutex_ (priority inheritance), whose other holders copy a few numbers.
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include "adroit_core/scheduling.h"
#include "robot_driver.h"

namespace adroit::driver {

namespace {
using SteadyClock = std::chrono::steady_clock;
}  // namespace

bool RobotDriver::enterRealtimeScheduling(int priority, const char* parameter) {
  std::string error;
  if (!enterFifo(priority, &error)) {
    ROS_WARN("%s: ~%s %d: SCHED_FIFO not permitted (%s); stepping with normal scheduling "
             "(grant an rtprio limit or CAP_SYS_NICE, or set ~%s: 0)", name_, parameter, priority, error.c_str(),
             parameter);
    return false;
  }
  fifo_priority_ = priority;
  ROS_INFO("%s: %s thread under SCHED_FIFO, priority %d", name_, robot_->drivenByInput() ? "robot" : "simulation",
           priority);
  return true;
}

void RobotDriver::leaveRealtimeScheduling(const char* why) {
  leaveFifo();
  fifo_priority_ = 0;
  ROS_WARN("%s: leaving SCHED_FIFO: %s", name_, why);
}

void RobotDriver::raiseLockstepWeight() {
  if (params_.lockstep_nice == 0) return;
  if (std::thread::hardware_concurrency() < 2) {
    ROS_WARN("%s: one CPU: ~lockstep_nice not applied, so that the other nodes keep a share of it", name_);
    return;
  }
  // Linux: a thread id as PRIO_PROCESS sets the nice value of that thread alone.
  if (setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), params_.lockstep_nice) != 0) {
    ROS_WARN("%s: ~lockstep_nice %d not permitted (%s); stepping at the default weight "
             "(grant a nice limit or CAP_SYS_NICE, or set ~lockstep_nice: 0)", name_,
             params_.lockstep_nice, std::strerror(errno));
    return;
  }
  thread_nice_ = params_.lockstep_nice;
}

void RobotDriver::recordStepTiming(double step_seconds, double lateness) {
  // try_lock: diagnostics only swap two objects under this lock, but the simulation thread
  // must never wait for them. Adding stays within the reserved capacity.
  std::unique_lock<std::mutex> lock(stats_mutex_, std::try_to_lock);
  if (!lock.owns_lock() || timing_.step_time.count() >= timing_.step_time.capacity()) {
    if (lock.owns_lock()) ++timing_.dropped;
    return;
  }
  timing_.step_time.add(step_seconds);
  if (lateness >= 0) timing_.lateness.add(lateness);
}

void RobotDriver::runPendingRequest() {
  // A reset or teleport, handed over by a service thread (changeState). It runs here,
  // between two steps, so that no service ever holds the robot while this loop waits.
  std::unique_lock<std::mutex> control(control_mutex_);
  if (!pending_change_ || change_done_ || change_running_) return;
  const auto* change = pending_change_;
  change_running_ = true;
  control.unlock();
  std::string error;
  bool ok;
  {
    std::lock_guard<PiMutex> lock(robot_mutex_);
    ok = (*change)(&error);
  }
  std::uint64_t published = 0;
  if (ok) {  // the new state goes out before the service answers
    publishDue(true, wallSeconds(), true);
    published = queuedBatches();
  }
  control.lock();
  change_ok_ = ok;
  change_error_ = error;
  change_published_ = published;
  change_running_ = false;
  change_done_ = true;
  control_cv_.notify_all();
}

void RobotDriver::loop() {
  const double dt = robot_->timestep();
  // Real time: state k is published at origin + k dt (wall); computing it happens before.
  auto origin = SteadyClock::now();
  double origin_clock = 0;
  bool resync = true;
  // A SCHED_FIFO thread that never sleeps would starve its core: after this many deadlines
  // missed in a row (the machine cannot step this scene in real time) it returns to normal
  // scheduling.
  constexpr int kMaxMissedInRow = 250;
  sim_thread_id_ = syscall(SYS_gettid);
  bool fifo = params_.realtime && params_.physics_priority > 0 &&
              enterRealtimeScheduling(params_.physics_priority, "physics_priority");
  if (!params_.realtime) raiseLockstepWeight();
  int missed_in_row = 0;
  while (running_) {
    runPendingRequest();
    bool requested = false, last_requested = false;
    ros::Time newest_command;
    {
      std::unique_lock<std::mutex> lock(control_mutex_);
      const auto change_waiting = [this] { return pending_change_ && !change_done_; };
      if (change_waiting()) continue;
      if (paused_ && pending_steps_ == 0) {
        lock.unlock();
        flushPublication();  // nothing follows for a while: what is queued goes out now
        lock.lock();
        if (paused_ && pending_steps_ == 0 && !change_waiting())
          control_cv_.wait_for(lock, std::chrono::milliseconds(50));
        resync = true;
        missed_in_row = 0;
        continue;
      }
      requested = paused_ && pending_steps_ > 0;
      last_requested = requested && pending_steps_ == 1;
      newest_command = last_command_stamp_;
    }
    const auto compute_start = SteadyClock::now();
    // A command with a new stamp acts from this step on: note when the step starts.
    const bool new_command = newest_command > applied_command_stamp_;
    const double wall_start = new_command && !params_.use_sim_time ? ros::WallTime::now().toSec() : 0.0;
    double clock_after;
    {
      std::lock_guard<PiMutex> lock(robot_mutex_);
      if (resync) {
        origin = compute_start + std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(dt));
        origin_clock = robot_->clock();
        wall_offset_ = std::max(wall_offset_, ros::WallTime::now().toSec() + dt - origin_clock);
        resync = false;
      }
      robot_->step();
      clock_after = robot_->clock();
      steps_done_.store(robot_->counters().steps, std::memory_order_relaxed);
    }
    const auto compute_end = SteadyClock::now();
    if (new_command) {
      // The first step acting on a command with a new stamp (read before the step: a command
      // noted during it counts for the next one, so the latency is never under-reported). It
      // acts from the start of the step's interval: in sim time that clock; in real time the
      // interval's scheduled start, or the wall time the step began if that was later.
      applied_command_stamp_ = latency_stamp_ = newest_command;
      const double clock_before = clock_after - dt;
      latency_applied_ = params_.use_sim_time ? ros::Time(clock_before)
                                               : ros::Time(std::max(wall_offset_ + clock_before, wall_start));
      latency_due_ = true;
    }
    double lateness = -1;  // publication after the deadline (s), real time on schedule
    if (params_.realtime && !requested) {
      auto deadline = origin + std::chrono::duration_cast<SteadyClock::duration>(
                                   std::chrono::duration<double>(clock_after - origin_clock - dt));
      const double late = std::chrono::duration<double>(compute_end - deadline).count();
      bool count_miss = false;
      if (late > params_.max_lag) {
        // Far behind (machine overloaded, debugger): restart the schedule from now rather
        // than running fast to catch up.
        resync = true;
      } else if (late > 0) {
        count_miss = true;
      } else {
        missed_in_row = -1;
        std::this_thread::sleep_until(deadline);
      }
      if (resync || count_miss) {
        std::unique_lock<std::mutex> lock(stats_mutex_, std::try_to_lock);
        if (lock.owns_lock()) ++(resync ? timing_.resyncs : timing_.deadline_misses);
      }
      if (++missed_in_row >= kMaxMissedInRow && fifo) {
        leaveRealtimeScheduling("the simulation cannot keep real time (250 deadlines missed in a row)");
        fifo = false;
      }
      if (!resync) lateness = std::max(0.0, std::chrono::duration<double>(SteadyClock::now() - deadline).count());
    }
    // Lockstep: the publisher is woken for a few steps at a time (see kPollPeriod), and at
    // once after the last requested step. Real time: at every state's deadline.
    const double step_seconds = std::chrono::duration<double>(compute_end - compute_start).count();
    publishDue(false, wallSeconds(), params_.realtime || last_requested);
    recordStepTiming(step_seconds, lateness);
    if (requested) {
      std::lock_guard<std::mutex> lock(control_mutex_);
      if (pending_steps_ > 0 && --pending_steps_ == 0) control_cv_.notify_all();
    }
  }
}

// The hardware: the robot thread waits on the buses (not holding the robot) and steps as
// soon as frames arrive, so a sensor sample is published without waiting for a tick; it also
// steps at least every timestep, so the watchdogs run while the buses are silent.
void RobotDriver::inputLoop() {
  const auto dt = std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(robot_->timestep()));
  sim_thread_id_ = syscall(SYS_gettid);
  // It sleeps in ppoll: FIFO is safe. The robot's I/O is the safety path: the top priority.
  if (params_.realtime_priority > 0) enterRealtimeScheduling(params_.realtime_priority, "realtime_priority");
  auto next_tick = SteadyClock::now() + dt;
  while (running_) {
    const auto now = SteadyClock::now();
    if (now < next_tick) robot_->waitForInput(std::chrono::duration<double>(next_tick - now).count());
    const auto compute_start = SteadyClock::now();
    if (compute_start >= next_tick) {
      next_tick += dt;
      if (next_tick < compute_start) next_tick = compute_start + dt;  // far behind: no burst of ticks
    }
    runPendingRequest();  // a reset or teleport request: the robot refuses it, but answers
    unsigned fresh;
    {
      std::lock_guard<PiMutex> lock(robot_mutex_);
      robot_->step();
      fresh = robot_->takeFresh();
      fresh_ |= fresh;
      steps_done_.store(robot_->counters().steps, std::memory_order_relaxed);
    }
    const double step_seconds = std::chrono::duration<double>(SteadyClock::now() - compute_start).count();
    if (fresh != 0 || latency_due_) publishDue(false, wallSeconds(), true);
    recordStepTiming(step_seconds, -1);
  }
}

}  // namespace adroit::driver
