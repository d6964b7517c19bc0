// ROS wrapper of CylinderPool, shared by the pool node (pool_node.cpp) and the nodelet
// (pool_nodelet.cpp): reads and validates the parameters, wires the topics, publishes
// valve commands at ~rate and diagnostics every ~diagnostics_period.
//
// Threads (the 200 Hz tick must never allocate, serialise or wait on another thread):
//  * the input queue (adroit_ros FifoCallbackQueue, under SCHED_FIFO one above the tick, as
//    are roscpp's own threads in the pool node): actuator states and force references,
//    validated by the pool and handed to the tick through lock-free hand-overs. At normal
//    scheduling the states waited 50-100 ms behind busy SCHED_FIFO threads on two cores and
//    the pools exhausted on stale states;
//  * the node's queue (ros::spin in the node, the nodelet's handle): the diagnostics timer;
//  * the tick thread: sleeps until the next period on the ROS clock (so it follows /clock
//    under use_sim_time), runs CylinderPool::update and puts the commands into a
//    preallocated slot (CommandSlot), then wakes the publisher with a semaphore post;
//  * the publisher thread: builds the ValveCommand (by index, resolved once from the
//    actuator-state order) and publishes it; roscpp allocates and serialises here.
// Both run under SCHED_FIFO (~realtime_priority, the publisher one above) when the system
// permits: the driver's watchdog trips when a cylinder goes 50 ms without a command, and at
// normal scheduling a busy node on the same two cores delayed the tick by up to 80 ms.
#include <semaphore.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <chrono>
#include <ctime>
#include <limits>
#include <memory>
#include <stdexcept>
#include <thread>

#include <ros/package.h>
#include <ros/ros.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ForceReference.h>
#include <adroit_msgs/ValveCommand.h>
#include <diagnostic_msgs/DiagnosticArray.h>

#include "adroit_core/pi_mutex.h"
#include "adroit_core/scheduling.h"
#include "adroit_pneumatics/params_io.h"
#include "adroit_pneumatics/pool.h"
#include "adroit_ros/diagnostics.h"
#include "adroit_ros/params.h"
#include "adroit_ros/realtime.h"

namespace adroit::pneumatics {

namespace {

using rosutil::Params;

template <typename Reason>
std::vector<std::string> reasonNames() {
  std::vector<std::string> names;
  for (int r = 1; r < static_cast<int>(Reason::kCount); ++r) names.push_back(rejectReasonName(static_cast<Reason>(r)));
  return names;
}
template <typename Reason>
std::size_t counterIndex(Reason reason) {
  return static_cast<std::size_t>(reason) - 1;  // kNone has no counter
}

PoolOptions readOptions(const Params& p, const ros::NodeHandle& pnh) {
  PoolOptions o;
  o.controller = p.string("controller", "ilqg");
  o.reference_timeout = p.number("reference_timeout", o.reference_timeout);
  o.state_timeout = p.number("state_timeout", o.state_timeout);
  o.stamp_tolerance = p.number("stamp_tolerance", o.stamp_tolerance);
  o.exhaust_volts = p.number("exhaust_volts", o.exhaust_volts);
  o.ilqg.horizon = p.integer("ilqg/horizon", o.ilqg.horizon);
  o.ilqg.dt = p.number("ilqg/dt", o.ilqg.dt);
  o.ilqg.alpha_p = p.number("ilqg/alpha_p", o.ilqg.alpha_p);
  o.ilqg.alpha_u = p.number("ilqg/alpha_u", o.ilqg.alpha_u);
  o.ilqg.alpha_w = p.number("ilqg/alpha_w", o.ilqg.alpha_w);
  o.ilqg.u_min = p.number("ilqg/u_min", o.ilqg.u_min);
  o.ilqg.u_max = p.number("ilqg/u_max", o.ilqg.u_max);
  o.ilqg.iterations = p.integer("ilqg/iterations", o.ilqg.iterations);
  o.ilqg.feedback_fraction = p.number("ilqg/feedback_fraction", o.ilqg.feedback_fraction);
  o.solve_every = p.integer("ilqg/solve_every", o.solve_every);
  o.solve_budget = p.number("ilqg/solve_budget", o.solve_budget);
  o.ilqg.disturbance_gain = p.number("ilqg/disturbance_gain", o.ilqg.disturbance_gain);
  o.ilqg.disturbance_limit = p.number("ilqg/disturbance_limit", o.ilqg.disturbance_limit);
  o.ilqg.u_des_steady_state = p.boolean("ilqg/u_des_steady_state", o.ilqg.u_des_steady_state);
  o.ilqg.measurement_gain = p.number("ilqg/measurement_gain", o.ilqg.measurement_gain);
  o.ilqg.measurement_band = p.number("ilqg/measurement_band", o.ilqg.measurement_band);
  o.ilqg.jump_threshold = p.number("ilqg/jump_threshold", o.ilqg.jump_threshold);
  o.ilqg.jump_iterations = p.integer("ilqg/jump_iterations", o.ilqg.jump_iterations);
  o.pidf.kp = p.number("pidf/kp", o.pidf.kp);
  o.pidf.ki = p.number("pidf/ki", o.pidf.ki);
  o.pidf.kd = p.number("pidf/kd", o.pidf.kd);
  o.pidf.filter_hz = p.number("pidf/filter_hz", o.pidf.filter_hz);
  o.pidf.feedforward = p.boolean("pidf/feedforward", o.pidf.feedforward);
  o.pidf.feedforward_advance = p.number("pidf/feedforward_advance", o.pidf.feedforward_advance);
  o.pidf.u_min = p.number("pidf/u_min", o.pidf.u_min);
  o.pidf.u_max = p.number("pidf/u_max", o.pidf.u_max);
  try {
    o.validate();
  } catch (const std::exception& e) {
    // The options' messages start with the field ("ilqg: horizon ...", "controller: ...").
    throw rosutil::ParameterError("bad parameter " + pnh.getNamespace() + "/" + e.what());
  }
  return o;
}

}  // namespace

class PoolRos {
 public:
  PoolRos(ros::NodeHandle nh, ros::NodeHandle pnh, std::string name)
      : name_(std::move(name)), reference_rejections_(reasonNames<RejectReason>()),
        state_rejections_(reasonNames<StateReject>()) {
    const Params p(pnh);
    p.checkKeys("", {"model_file", "scene", "cylinders", "pool", "group_size", "controller", "params_file", "rate",
                     "reference_timeout", "state_timeout", "stamp_tolerance", "exhaust_volts", "ilqg", "pidf",
                     "diagnostics_period", "realtime_priority", "tick_phase", "tick_on_state"});
    p.checkKeys("ilqg", {"horizon", "dt", "alpha_p", "alpha_u", "alpha_w", "u_min", "u_max", "iterations",
                         "feedback_fraction", "solve_every", "solve_budget", "disturbance_gain", "disturbance_limit",
                         "u_des_steady_state", "measurement_gain", "measurement_band", "jump_threshold",
                         "jump_iterations"});
    p.checkKeys("pidf", {"kp", "ki", "kd", "filter_hz", "feedforward", "feedforward_advance", "u_min", "u_max"});

    // Cylinders: the model is the source of names and bores.
    const std::string model_file = p.modelPath("arm_hand");
    std::vector<description::Cylinder> table;
    try {
      table = loadModelCylinders(model_file);
    } catch (const std::exception& e) {
      p.fail(p.has("model_file") ? "model_file" : "scene", e.what());
    }
    std::vector<std::string> known;
    for (const auto& c : table) known.push_back(c.name);
    std::vector<std::string> mine = p.strings("cylinders");
    if (mine.empty()) {
      if (!p.has("pool")) p.fail("cylinders", "set ~cylinders (list of names) or ~pool (index into the default split)");
      const auto split = defaultPoolSplit(known, p.integer("group_size", 8, 1, 1000));
      mine = split[p.integer("pool", 0, 0, static_cast<int>(split.size()) - 1)];
    } else if (p.has("pool")) {
      p.fail("pool", "give either ~cylinders or ~pool, not both");
    }

    // Parametric models: a malformed YAML names its field (params_io).
    const std::string params_file =
        p.string("params_file", ros::package::getPath("adroit_pneumatics") + "/config/parametric_default.yaml");
    ParameterSet models;
    try {
      models = loadParameterSet(params_file);
    } catch (const std::exception& e) {
      p.fail("params_file", e.what());
    }
    for (const auto& kv : models.cylinders) {
      if (std::find(known.begin(), known.end(), kv.first) == known.end())
        p.fail("params_file", params_file + ": parametric.cylinders." + kv.first + ": not a cylinder of " + model_file);
    }

    std::vector<PoolCylinder> cylinders;
    for (const auto& n : mine) {
      const auto it = std::find_if(table.begin(), table.end(), [&](const auto& c) { return c.name == n; });
      if (it == table.end()) p.fail("cylinders", "unknown cylinder '" + n + "' (not in " + model_file + ")");
      cylinders.push_back({n, it->bore_area, deadVolume(it->type, it->bore_diameter), models.forCylinder(n)});
    }

    const PoolOptions o = readOptions(p, pnh);
    const double rate = p.number("rate", 200.0, 1e-3, 2000.0);
    const double diag_period = p.number("diagnostics_period", 1.0, 1e-3, 3600.0);
    realtime_priority_ = p.integer("realtime_priority", 15, 0, 98);
    tick_phase_ = p.number("tick_phase", 0.0, 0.0, 0.999999);
    tick_on_state_ = p.boolean("tick_on_state", false);
    if (tick_on_state_ && ros::Time::isSimTime())
      p.fail("tick_on_state", "true needs wall time (a driver whose samples arrive on their own: the hardware)");

    pool_ = std::make_unique<CylinderPool>(std::move(cylinders), known, o);
    controller_ = o.controller;
    period_ = ros::Duration(1.0 / rate);
    slot_ = std::make_unique<CommandSlot>(emptyCommand(pool_->size()));
    for (const auto& n : pool_->names()) cylinder_list_ += (cylinder_list_.empty() ? "" : " ") + n;
    if (sem_init(&command_ready_, 0, 0) != 0 || sem_init(&state_ready_, 0, 0) != 0)
      throw std::runtime_error("sem_init failed");

    command_pub_ = nh.advertise<adroit_msgs::ValveCommand>("/adroit/valve_command", 10);
    diag_pub_ = nh.advertise<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 10);
    ros::NodeHandle input(nh);
    input.setCallbackQueue(input_queue_.queue());
    state_sub_ = input.subscribe("/adroit/actuator_states", 10, &PoolRos::onState, this, ros::TransportHints().tcpNoDelay());
    reference_sub_ =
        input.subscribe("/adroit/force_reference", 10, &PoolRos::onReference, this, ros::TransportHints().tcpNoDelay());
    diag_timer_ = nh.createWallTimer(ros::WallDuration(diag_period), &PoolRos::onDiagnostics, this);
    window_start_ = Clock::now();

    running_ = true;
    input_queue_.start(realtime_priority_ > 0 ? realtime_priority_ + 1 : 0);
    if (realtime_priority_ > 0) {
      std::string error;
      transport_fifo_ = rosutil::fifoRosThreads(realtime_priority_ + 1, &error);
      if (!transport_fifo_)
        ROS_WARN("%s: roscpp's threads keep normal scheduling (%s): on a busy machine actuator states may arrive "
                 "late (the pool node, or the manager adroit_pneumatics/pool_manager, runs them under SCHED_FIFO)",
                 name_.c_str(), error.c_str());
    }
    publisher_ = std::thread(&PoolRos::publishLoop, this);
    tick_ = std::thread(&PoolRos::tickLoop, this);
    ROS_INFO("%s: %s pool of %zu cylinders at %.0f Hz: %s", name_.c_str(), controller_.c_str(), pool_->size(), rate,
             cylinder_list_.c_str());
  }

  ~PoolRos() {
    running_ = false;
    input_queue_.stop();
    sem_post(&state_ready_);  // a state-driven tick waits on it
    if (tick_.joinable()) tick_.join();
    sem_post(&command_ready_);
    if (publisher_.joinable()) publisher_.join();
    sem_destroy(&command_ready_);
    sem_destroy(&state_ready_);
  }

 private:
  using Clock = std::chrono::steady_clock;

  // --- callback queue -----------------------------------------------------------------
  void onState(const adroit_msgs::ActuatorStates::ConstPtr& msg) {
    // Freshness is the stamp's business; an unstamped state has none (NaN: rejected).
    const double stamp = msg->header.stamp.isZero() ? std::numeric_limits<double>::quiet_NaN()
                                                     : msg->header.stamp.toSec();
    const StateVerdict v = pool_->setState(ros::Time::now().toSec(), stamp, msg->name, msg->pressure, msg->length,
                                           msg->length_rate, msg->supply_pressure);
    if (v.unknown_names) {
      states_unknown_name_.fetch_add(1, std::memory_order_relaxed);
      ROS_WARN_THROTTLE(5.0, "%s: actuator state names cylinders the model does not have (skipped)", name_.c_str());
    }
    if (v.ok()) {
      states_accepted_.fetch_add(1, std::memory_order_relaxed);
      state_received_ns_.store(Clock::now().time_since_epoch().count(), std::memory_order_relaxed);
      if (tick_on_state_) {
        int pending = 0;  // one wake-up at most: a tick uses the newest state anyway
        if (sem_getvalue(&state_ready_, &pending) == 0 && pending == 0) sem_post(&state_ready_);
      }
    } else {
      state_rejections_.count(counterIndex(v.reason));
      ROS_ERROR_THROTTLE(1.0, "%s: rejected actuator state (%s): %s", name_.c_str(), rejectReasonName(v.reason),
                         v.detail.c_str());
    }
  }

  void onReference(const adroit_msgs::ForceReference::ConstPtr& msg) {
    const double now = ros::Time::now().toSec();
    // An unstamped reference starts now (documented in the README).
    const double t0 = msg->header.stamp.isZero() ? now : msg->header.stamp.toSec();
    const Verdict v = pool_->setReference(now, t0, msg->dt, msg->steps, msg->name, msg->force);
    if (!v.ok()) {
      reference_rejections_.count(counterIndex(v.reason));
      {
        const std::lock_guard<PiMutex> lock(last_reject_mutex_);
        last_reject_ = v.detail;
      }
      ROS_ERROR_THROTTLE(1.0, "%s: rejected force reference (%s): %s", name_.c_str(), rejectReasonName(v.reason),
                         v.detail.c_str());
      return;
    }
    if (v.ignored) {
      ++references_ignored_;
      return;
    }
    ++references_accepted_;
    if (v.clamped_negative) {
      ++references_clamped_negative_;
      ROS_WARN_THROTTLE(5.0, "%s: force reference asks for negative tension; clamped to 0 N", name_.c_str());
    }
  }

  // --- tick thread --------------------------------------------------------------------
  // Waits until `until` on the ROS clock. Under wall time that is one sleep (at most a
  // period, so a stop request waits no longer). Sim time is polled in 0.5 ms wall slices:
  // its rate against wall time is unknown, and the sim clock may stand still (paused).
  bool waitUntil(const ros::Time& until) {
    while (running_.load(std::memory_order_relaxed) && ros::ok()) {
      const ros::Time now = ros::Time::now();
      if (now >= until) return true;
      if (until - now > period_ + period_) return true;  // the clock went back (sim reset)
      const double left = (until - now).toSec();
      const double slice = ros::Time::isSimTime() ? std::min(left, 5e-4) : left;
      std::this_thread::sleep_for(std::chrono::duration<double>(slice));
    }
    return false;
  }

  // SCHED_FIFO for the calling thread at `priority` (0: stay at normal scheduling); the
  // outcome is kept for the diagnostics and said once.
  void enterRealtime(int priority, const char* thread) {
    if (priority <= 0) return;
    std::string error;
    if (enterFifo(priority, &error)) {
      ROS_INFO("%s: %s thread under SCHED_FIFO, priority %d", name_.c_str(), thread, priority);
      return;
    }
    fifo_refused_ = true;
    ROS_WARN_ONCE("%s: ~realtime_priority %d: SCHED_FIFO not permitted (%s); the %s thread keeps normal scheduling "
                  "(grant an rtprio limit or CAP_SYS_NICE, or set ~realtime_priority: 0)",
                  name_.c_str(), priority, error.c_str(), thread);
  }

  // The latest tick time <= now on this pool's grid: multiples of the period on the ROS
  // clock, shifted by ~tick_phase periods. pools.launch gives each pool its own phase, so the
  // pools of a machine re-solve one after another instead of all at once (pneumatics_bench
  // --only pool: aligned vs staggered).
  ros::Time latestTick(const ros::Time& now) const {
    const std::int64_t period = period_.toNSec();
    const std::int64_t offset = static_cast<std::int64_t>(tick_phase_ * static_cast<double>(period));
    const std::int64_t t = static_cast<std::int64_t>(now.toNSec()) - offset;
    ros::Time tick;
    tick.fromNSec(static_cast<std::uint64_t>(t - t % period + offset));
    return tick;
  }

  // ~tick_on_state (the hardware): a tick as soon as a new state is in, so a sensor sample
  // reaches the valves without waiting for the grid (the latency the reflex budget counts);
  // after a period without a state, a tick anyway (the pool's own stale-state handling).
  void stateTickLoop() {
    while (running_ && ros::ok()) {
      timespec deadline;
      clock_gettime(CLOCK_REALTIME, &deadline);
      const std::int64_t ns = deadline.tv_nsec + period_.toNSec();
      deadline.tv_sec += ns / 1000000000;
      deadline.tv_nsec = ns % 1000000000;
      while (sem_timedwait(&state_ready_, &deadline) != 0 && errno == EINTR) {
      }
      if (!running_) break;
      const double now = ros::Time::now().toSec();
      putCommand(*slot_, now, pool_->update(now));
      sem_post(&command_ready_);
    }
  }

  void tickLoop() {
    enterRealtime(realtime_priority_, "tick");
    if (tick_on_state_) return stateTickLoop();
    // Under sim time the clock reads zero until the first /clock.
    while (running_ && ros::ok() && ros::Time::now().isZero()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    ros::Time next = latestTick(ros::Time::now());
    while (running_ && ros::ok()) {
      next += period_;
      if (!waitUntil(next)) break;
      const ros::Time now = ros::Time::now();
      // Late by more than a period (descheduled, or the sim clock jumped ahead), or the
      // clock went back: resynchronise onto the grid rather than run missed ticks back to
      // back or wait.
      if (now - next > period_ || next - now > period_) next = latestTick(now);
      const std::vector<double>& volts = pool_->update(now.toSec());
      putCommand(*slot_, now.toSec(), volts);
      sem_post(&command_ready_);  // never blocks
    }
  }

  // --- publisher thread ---------------------------------------------------------------
  void publishLoop() {
    // Above the ticks (its own and the other pools'): it only hands a finished command to
    // roscpp. One below them, five ticks re-solving on a slowed-down machine kept the
    // publishers from sending for 60 ms and the driver's watchdog tripped.
    enterRealtime(realtime_priority_ > 0 ? realtime_priority_ + 1 : 0, "publisher");
    std::vector<std::uint16_t> index;
    while (running_) {
      timespec deadline;
      clock_gettime(CLOCK_REALTIME, &deadline);
      deadline.tv_nsec += 100000000;  // 100 ms: see running_ soon after a stop request
      if (deadline.tv_nsec >= 1000000000) deadline.tv_sec += 1, deadline.tv_nsec -= 1000000000;
      if (sem_timedwait(&command_ready_, &deadline) != 0 && errno != EINTR) continue;
      if (!slot_->take()) continue;
      const PoolCommand& c = slot_->front();
      // A new message each time: intra-process subscribers (the driver's nodelet) keep it.
      adroit_msgs::ValveCommand::Ptr msg(new adroit_msgs::ValveCommand);
      msg->header.stamp.fromSec(c.stamp);
      if (index.empty() && pool_->valveIndicesResolved())
        for (int i : pool_->valveIndices()) index.push_back(static_cast<std::uint16_t>(i));
      // By index once the actuator-state order is known (the driver then resolves no
      // names); until the first state, by name (these commands are all exhaust anyway).
      if (!index.empty())
        msg->index = index;
      else
        msg->name = pool_->names();
      msg->volts = c.volts;
      command_pub_.publish(msg);
      published_.fetch_add(1, std::memory_order_relaxed);
      const long long received = state_received_ns_.load(std::memory_order_relaxed);
      if (received != 0)
        pool_->recordPolicyLag(
            std::chrono::duration<double>(Clock::now() - Clock::time_point(Clock::duration(received))).count());
    }
  }

  // --- diagnostics (the node's queue) -------------------------------------------------
  void onDiagnostics(const ros::WallTimerEvent&) {
    const auto t = Clock::now();
    const double window = std::chrono::duration<double>(t - window_start_).count();
    window_start_ = t;
    const PoolWindow w = pool_->takeWindow();
    const PoolCounters c = pool_->counters();
    const std::uint64_t rejected = reference_rejections_.total(), states_rejected = state_rejections_.total();
    std::string last_reject;
    {
      const std::lock_guard<PiMutex> lock(last_reject_mutex_);
      last_reject = last_reject_;
    }
    const std::size_t n = pool_->size(), ex = pool_->exhausting();

    rosutil::StatusBuilder s(name_, "adroit_pneumatics pool");
    if (c.nonfinite_commands > last_nonfinite_)
      s.raise(diagnostic_msgs::DiagnosticStatus::ERROR, "controller produced non-finite commands (exhausted)");
    if (ex > 0)
      s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "exhausting " + std::to_string(ex) + "/" + std::to_string(n) +
                                                           " cylinders (no valid reference or state)");
    if (rejected > last_rejected_)
      s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "rejected force references: " + last_reject);
    if (states_rejected > last_states_rejected_)
      s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "rejected actuator states");
    s.raise(diagnostic_msgs::DiagnosticStatus::OK,
            "tracking " + std::to_string(n) + "/" + std::to_string(n) + " cylinders");
    last_nonfinite_ = c.nonfinite_commands;
    last_rejected_ = rejected;
    last_states_rejected_ = states_rejected;

    const std::uint64_t published = published_.load(std::memory_order_relaxed);
    s.add("controller", controller_);
    s.add("cylinders", cylinder_list_);
    s.add("addressing", pool_->valveIndicesResolved() ? "index" : "name");
    s.add("scheduling", realtime_priority_ == 0 ? "normal (~realtime_priority 0)"
                        : fifo_refused_         ? "normal (SCHED_FIFO not permitted)"
                                                : "SCHED_FIFO " + std::to_string(realtime_priority_));
    const int input_fifo = input_queue_.priority();
    s.add("input_scheduling", input_fifo > 0 ? "SCHED_FIFO " + std::to_string(input_fifo) : std::string("normal"));
    s.add("transport_scheduling", transport_fifo_ ? "SCHED_FIFO " + std::to_string(realtime_priority_ + 1)
                                                   : std::string("normal"));
    s.add("publish_rate_hz", window > 0 ? (published - last_published_) / window : 0.0);
    last_published_ = published;
    s.add("ticks", c.ticks);
    s.add("exhausting", ex);
    s.add("solve_time", formatSummary(w.solve, 1e3, "ms"));
    s.add("solve_time_p99_ms", w.solve.p99 * 1e3);
    s.add("policy_lag", formatSummary(w.lag, 1e3, "ms"));
    s.add("policy_lag_p99_ms", w.lag.p99 * 1e3);
    s.add("tracking_rmse_N", w.force_rmse);
    s.add("tracking_rmse_kPa", w.pressure_rmse / 1e3);
    s.add("references_accepted", references_accepted_.load(std::memory_order_relaxed));
    s.add("references_ignored", references_ignored_.load(std::memory_order_relaxed));
    s.add("references_clamped_negative", references_clamped_negative_.load(std::memory_order_relaxed));
    reference_rejections_.addTo(s, "references_rejected");
    s.add("last_rejection", last_reject);
    s.add("reference_timeouts", c.reference_timeouts);
    s.add("states_accepted", states_accepted_.load(std::memory_order_relaxed));
    s.add("states_unknown_name", states_unknown_name_.load(std::memory_order_relaxed));
    state_rejections_.addTo(s, "states_rejected");
    s.add("nonfinite_commands", c.nonfinite_commands);
    s.add("solver_rejections", c.solver_rejections);
    s.add("solves_deferred", c.solves_deferred);
    s.publish(diag_pub_);
  }

  std::string name_, controller_, cylinder_list_;
  PiMutex last_reject_mutex_;  // last_reject_: written by the input queue, read by the diagnostics
  std::string last_reject_;
  std::unique_ptr<CylinderPool> pool_;
  std::unique_ptr<CommandSlot> slot_;
  ros::Duration period_;
  ros::Publisher command_pub_, diag_pub_;
  // Actuator states and force references; declared before their subscribers, which remove
  // their callbacks from it when they go.
  rosutil::FifoCallbackQueue input_queue_;
  ros::Subscriber state_sub_, reference_sub_;
  ros::WallTimer diag_timer_;
  std::atomic<bool> transport_fifo_{false};  // roscpp's threads under SCHED_FIFO
  std::thread tick_, publisher_;
  std::atomic<bool> running_{false};
  double tick_phase_ = 0.0;    // fraction of the period (latestTick)
  bool tick_on_state_ = false;  // tick when a state arrives (stateTickLoop) instead of on the grid
  sem_t state_ready_;          // posted by onState under ~tick_on_state
  int realtime_priority_ = 15;  // tick thread; the publisher, input queue and roscpp's threads one above (0: normal)
  std::atomic<bool> fifo_refused_{false};
  sem_t command_ready_;
  Clock::time_point window_start_;
  // Input verdicts, counted on the input queue (lock-free: read by the diagnostics).
  rosutil::RejectionCounters reference_rejections_, state_rejections_;
  std::atomic<std::uint64_t> references_accepted_{0}, references_ignored_{0}, references_clamped_negative_{0};
  std::atomic<std::uint64_t> states_accepted_{0}, states_unknown_name_{0}, published_{0};
  std::atomic<long long> state_received_ns_{0};  // steady clock of the last accepted state, 0 = none
  std::uint64_t last_published_ = 0, last_nonfinite_ = 0, last_rejected_ = 0, last_states_rejected_ = 0;
};

// Declared in pool_node.cpp and pool_nodelet.cpp. Throws std::runtime_error (one line
// naming the bad parameter) when the configuration is invalid.
std::shared_ptr<void> startPool(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& name) {
  return std::make_shared<PoolRos>(nh, pnh, name);
}

}  // namespace adroit::pneumatics
