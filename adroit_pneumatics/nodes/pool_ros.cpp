// ROS wrapper of PoolGroup, shared by the pool node (pool_node.cpp) and the nodelet
// (pool_nodelet.cpp): one pool, or a group of pools (~members, pool_params.h) driven as one.
// Reads and validates the parameters, wires the topics, publishes one valve command per
// tick for every cylinder of the group at ~rate and one diagnostics status per pool every
// ~diagnostics_period.
//
// Threads, one set per node whatever the number of pools (the 200 Hz tick must never
// allocate, serialise or wait on another thread):
//  * the input queue (adroit_ros FifoCallbackQueue, under SCHED_FIFO one above the tick, as
//    are roscpp's own threads in the pool node): actuator states and force references,
//    their names resolved once for the group, validated by each pool and handed to the tick
//    through lock-free hand-overs. At normal scheduling the states waited 50-100 ms behind
//    busy SCHED_FIFO threads on two cores and the pools exhausted on stale states;
//  * the node's queue (ros::spin in the node, the nodelet's handle): the diagnostics timer;
//  * the tick thread: sleeps until the next period on the ROS clock (so it follows /clock
//    under use_sim_time), runs every pool's update in turn (PoolGroup::update) and puts the
//    commands into a preallocated slot (CommandSlot), then wakes the publisher with a
//    semaphore post;
//  * the publisher thread: builds the one ValveCommand (by index, resolved once from the
//    actuator-state order) and publishes it; roscpp allocates and serialises here.
// Both run under SCHED_FIFO (~realtime_priority, the publisher one above) when the system
// permits: the driver's watchdog trips when a cylinder goes 50 ms without a command, and at
// normal scheduling a busy node on the same two cores delayed the tick by up to 80 ms.
// Six pools each with these threads woke the machine ~3 x 6 x 200 times a second and sent
// the driver six commands per tick: a group has one of each (README "Pool group").
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

#include <ros/ros.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ForceReference.h>
#include <adroit_msgs/ValveCommand.h>
#include <diagnostic_msgs/DiagnosticArray.h>

#include "adroit_core/pi_mutex.h"
#include "adroit_core/scheduling.h"
#include "adroit_pneumatics/pool_group.h"
#include "adroit_ros/diagnostics.h"
#include "adroit_ros/realtime.h"
#include "pool_params.h"

namespace adroit::pneumatics {

namespace {

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

// One pool's input verdicts, counted on the input queue (lock-free: read by the diagnostics),
// and what its diagnostics compare against the previous window.
struct PoolStats {
  explicit PoolStats(const PoolSpec& spec)
      : name(spec.name), controller(spec.options.controller), reference_rejections(reasonNames<RejectReason>()),
        state_rejections(reasonNames<StateReject>()) {
    for (const auto& c : spec.cylinders) cylinder_list += (cylinder_list.empty() ? "" : " ") + c.name;
  }
  const std::string name, controller;  // name: the diagnostics status
  std::string cylinder_list;
  rosutil::RejectionCounters reference_rejections, state_rejections;
  std::atomic<std::uint64_t> references_accepted{0}, references_ignored{0}, references_clamped_negative{0};
  std::atomic<std::uint64_t> states_accepted{0}, states_unknown_name{0};
  PiMutex last_reject_mutex;  // last_reject: written by the input queue, read by the diagnostics
  std::string last_reject;
  std::uint64_t last_nonfinite = 0, last_rejected = 0, last_states_rejected = 0;  // diagnostics only
};

std::vector<std::unique_ptr<CylinderPool>> makePools(const GroupSpec& spec) {
  std::vector<std::unique_ptr<CylinderPool>> pools;
  for (const PoolSpec& p : spec.pools) pools.push_back(std::make_unique<CylinderPool>(p.cylinders, p.known, p.options));
  return pools;
}

}  // namespace

class PoolRos {
 public:
  PoolRos(ros::NodeHandle nh, ros::NodeHandle pnh, std::string name)
      : name_(std::move(name)), spec_(readGroupSpec(pnh, name_)), group_(makePools(spec_)) {
    for (const PoolSpec& p : spec_.pools) stats_.push_back(std::make_unique<PoolStats>(p));
    period_ = ros::Duration(1.0 / spec_.rate);
    slot_ = std::make_unique<CommandSlot>(emptyCommand(group_.names().size()));
    if (sem_init(&command_ready_, 0, 0) != 0 || sem_init(&state_ready_, 0, 0) != 0)
      throw std::runtime_error("sem_init failed");

    command_pub_ = nh.advertise<adroit_msgs::ValveCommand>("/adroit/valve_command", 10);
    diag_pub_ = nh.advertise<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 10);
    ros::NodeHandle input(nh);
    input.setCallbackQueue(input_queue_.queue());
    state_sub_ = input.subscribe("/adroit/actuator_states", 10, &PoolRos::onState, this, ros::TransportHints().tcpNoDelay());
    reference_sub_ =
        input.subscribe("/adroit/force_reference", 10, &PoolRos::onReference, this, ros::TransportHints().tcpNoDelay());
    diag_timer_ = nh.createWallTimer(ros::WallDuration(spec_.diagnostics_period), &PoolRos::onDiagnostics, this);
    window_start_ = Clock::now();

    running_ = true;
    input_queue_.start(spec_.realtime_priority > 0 ? spec_.realtime_priority + 1 : 0);
    if (spec_.realtime_priority > 0) {
      std::string error;
      transport_fifo_ = rosutil::fifoRosThreads(spec_.realtime_priority + 1, &error);
      if (!transport_fifo_)
        ROS_WARN("%s: roscpp's threads keep normal scheduling (%s): on a busy machine actuator states may arrive "
                 "late (the pool node, or the manager adroit_pneumatics/pool_manager, runs them under SCHED_FIFO)",
                 name_.c_str(), error.c_str());
    }
    publisher_ = std::thread(&PoolRos::publishLoop, this);
    tick_ = std::thread(&PoolRos::tickLoop, this);
    for (std::size_t k = 0; k < group_.size(); ++k)
      ROS_INFO("%s: %s pool of %zu cylinders at %.0f Hz: %s", stats_[k]->name.c_str(), stats_[k]->controller.c_str(),
               group_.pool(k).size(), spec_.rate, stats_[k]->cylinder_list.c_str());
    if (group_.size() > 1)
      ROS_INFO("%s: %zu pools as one group: one tick, one valve command of %zu cylinders per period", name_.c_str(),
               group_.size(), group_.names().size());
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
    const std::vector<StateVerdict>& verdicts = group_.setState(
        ros::Time::now().toSec(), stamp, msg->name, msg->pressure, msg->length, msg->length_rate, msg->supply_pressure);
    bool accepted = false;
    for (std::size_t k = 0; k < verdicts.size(); ++k) accepted = countState(*stats_[k], verdicts[k]) || accepted;
    if (!accepted) return;
    state_received_ns_.store(Clock::now().time_since_epoch().count(), std::memory_order_relaxed);
    if (spec_.tick_on_state) {
      int pending = 0;  // one wake-up at most: a tick uses the newest state anyway
      if (sem_getvalue(&state_ready_, &pending) == 0 && pending == 0) sem_post(&state_ready_);
    }
  }

  // One pool's verdict on a state, counted (and logged, throttled); true if accepted.
  static bool countState(PoolStats& s, const StateVerdict& v) {
    if (v.unknown_names) {
      s.states_unknown_name.fetch_add(1, std::memory_order_relaxed);
      ROS_WARN_THROTTLE(5.0, "%s: actuator state names cylinders the model does not have (skipped)", s.name.c_str());
    }
    if (v.ok()) {
      s.states_accepted.fetch_add(1, std::memory_order_relaxed);
      return true;
    }
    s.state_rejections.count(counterIndex(v.reason));
    ROS_ERROR_THROTTLE(1.0, "%s: rejected actuator state (%s): %s", s.name.c_str(), rejectReasonName(v.reason),
                       v.detail.c_str());
    return false;
  }

  void onReference(const adroit_msgs::ForceReference::ConstPtr& msg) {
    const double now = ros::Time::now().toSec();
    // An unstamped reference starts now (documented in the README).
    const double t0 = msg->header.stamp.isZero() ? now : msg->header.stamp.toSec();
    const std::vector<Verdict>& verdicts = group_.setReference(now, t0, msg->dt, msg->steps, msg->name, msg->force);
    for (std::size_t k = 0; k < verdicts.size(); ++k) countReference(*stats_[k], verdicts[k]);
  }

  static void countReference(PoolStats& s, const Verdict& v) {
    if (!v.ok()) {
      s.reference_rejections.count(counterIndex(v.reason));
      {
        const std::lock_guard<PiMutex> lock(s.last_reject_mutex);
        s.last_reject = v.detail;
      }
      ROS_ERROR_THROTTLE(1.0, "%s: rejected force reference (%s): %s", s.name.c_str(), rejectReasonName(v.reason),
                         v.detail.c_str());
      return;
    }
    if (v.ignored) {
      ++s.references_ignored;
      return;
    }
    ++s.references_accepted;
    if (v.clamped_negative) {
      ++s.references_clamped_negative;
      ROS_WARN_THROTTLE(5.0, "%s: force reference asks for negative tension; clamped to 0 N", s.name.c_str());
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

  // The latest tick time <= now on this node's grid: multiples of the period on the ROS
  // clock, shifted by ~tick_phase periods. pools.launch without a group gives each pool node
  // its own phase, so they re-solve one after another instead of all at once
  // (pneumatics_bench --only pool: aligned vs staggered); a group runs its pools in turn.
  ros::Time latestTick(const ros::Time& now) const {
    const std::int64_t period = period_.toNSec();
    const std::int64_t offset = static_cast<std::int64_t>(spec_.tick_phase * static_cast<double>(period));
    const std::int64_t t = static_cast<std::int64_t>(now.toNSec()) - offset;
    ros::Time tick;
    tick.fromNSec(static_cast<std::uint64_t>(t - t % period + offset));
    return tick;
  }

  // One tick of every pool at `now`, handed to the publisher.
  void tickOnce(double now) {
    putCommand(*slot_, now, group_.update(now));
    sem_post(&command_ready_);  // never blocks
  }

  // ~tick_on_state (the hardware): a tick as soon as a new state is in, so a sensor sample
  // reaches the valves without waiting for the grid (the latency the reflex budget counts);
  // after a period without a state, a tick anyway (the pools' own stale-state handling).
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
      tickOnce(ros::Time::now().toSec());
    }
  }

  void tickLoop() {
    enterRealtime(spec_.realtime_priority, "tick");
    if (spec_.tick_on_state) return stateTickLoop();
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
      tickOnce(now.toSec());
    }
  }

  // --- publisher thread ---------------------------------------------------------------
  void publishLoop() {
    // Above the ticks (its own and any other pool node's): it only hands a finished command
    // to roscpp. One below them, five ticks re-solving on a slowed-down machine kept the
    // publishers from sending for 60 ms and the driver's watchdog tripped.
    enterRealtime(spec_.realtime_priority > 0 ? spec_.realtime_priority + 1 : 0, "publisher");
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
      if (index.empty() && group_.valveIndicesResolved())
        for (int i : group_.valveIndices()) index.push_back(static_cast<std::uint16_t>(i));
      // By index once every pool knows the actuator-state order (the driver then resolves
      // no names); until then, by name (these commands are mostly exhaust anyway).
      if (!index.empty())
        msg->index = index;
      else
        msg->name = group_.names();
      msg->volts = c.volts;
      command_pub_.publish(msg);
      published_.fetch_add(1, std::memory_order_relaxed);
      const long long received = state_received_ns_.load(std::memory_order_relaxed);
      if (received != 0)
        group_.recordPolicyLag(
            std::chrono::duration<double>(Clock::now() - Clock::time_point(Clock::duration(received))).count());
    }
  }

  // --- diagnostics (the node's queue) -------------------------------------------------
  // One status per pool, all in one array.
  void onDiagnostics(const ros::WallTimerEvent&) {
    const auto t = Clock::now();
    const double window = std::chrono::duration<double>(t - window_start_).count();
    window_start_ = t;
    const std::uint64_t published = published_.load(std::memory_order_relaxed);
    const double rate = window > 0 ? (published - last_published_) / window : 0.0;
    last_published_ = published;
    diagnostic_msgs::DiagnosticArray array;
    array.header.stamp = ros::Time::now();
    for (std::size_t k = 0; k < group_.size(); ++k)
      array.status.push_back(poolStatus(group_.pool(k), *stats_[k], rate));
    diag_pub_.publish(array);
  }

  diagnostic_msgs::DiagnosticStatus poolStatus(CylinderPool& pool, PoolStats& st, double publish_rate) {
    const PoolWindow w = pool.takeWindow();
    const PoolCounters c = pool.counters();
    const std::uint64_t rejected = st.reference_rejections.total(), states_rejected = st.state_rejections.total();
    std::string last_reject;
    {
      const std::lock_guard<PiMutex> lock(st.last_reject_mutex);
      last_reject = st.last_reject;
    }
    const std::size_t n = pool.size(), ex = pool.exhausting();

    rosutil::StatusBuilder s(st.name, "adroit_pneumatics pool");
    if (c.nonfinite_commands > st.last_nonfinite)
      s.raise(diagnostic_msgs::DiagnosticStatus::ERROR, "controller produced non-finite commands (exhausted)");
    if (ex > 0)
      s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "exhausting " + std::to_string(ex) + "/" + std::to_string(n) +
                                                           " cylinders (no valid reference or state)");
    if (rejected > st.last_rejected)
      s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "rejected force references: " + last_reject);
    if (states_rejected > st.last_states_rejected)
      s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "rejected actuator states");
    s.raise(diagnostic_msgs::DiagnosticStatus::OK,
            "tracking " + std::to_string(n) + "/" + std::to_string(n) + " cylinders");
    st.last_nonfinite = c.nonfinite_commands;
    st.last_rejected = rejected;
    st.last_states_rejected = states_rejected;

    s.add("controller", st.controller);
    s.add("cylinders", st.cylinder_list);
    s.add("group", group_.size() > 1 ? name_ + " (" + std::to_string(group_.size()) + " pools)" : std::string("none"));
    s.add("addressing", group_.valveIndicesResolved() ? "index" : "name");
    const int priority = spec_.realtime_priority;
    s.add("scheduling", priority == 0    ? "normal (~realtime_priority 0)"
                        : fifo_refused_ ? "normal (SCHED_FIFO not permitted)"
                                        : "SCHED_FIFO " + std::to_string(priority));
    const int input_fifo = input_queue_.priority();
    s.add("input_scheduling", input_fifo > 0 ? "SCHED_FIFO " + std::to_string(input_fifo) : std::string("normal"));
    s.add("transport_scheduling", transport_fifo_ ? "SCHED_FIFO " + std::to_string(priority + 1) : std::string("normal"));
    s.add("publish_rate_hz", publish_rate);
    s.add("ticks", c.ticks);
    s.add("exhausting", ex);
    s.add("solve_time", formatSummary(w.solve, 1e3, "ms"));
    s.add("solve_time_p99_ms", w.solve.p99 * 1e3);
    s.add("policy_lag", formatSummary(w.lag, 1e3, "ms"));
    s.add("policy_lag_p99_ms", w.lag.p99 * 1e3);
    s.add("tracking_rmse_N", w.force_rmse);
    s.add("tracking_rmse_kPa", w.pressure_rmse / 1e3);
    s.add("references_accepted", st.references_accepted.load(std::memory_order_relaxed));
    s.add("references_ignored", st.references_ignored.load(std::memory_order_relaxed));
    s.add("references_clamped_negative", st.references_clamped_negative.load(std::memory_order_relaxed));
    st.reference_rejections.addTo(s, "references_rejected");
    s.add("last_rejection", last_reject);
    s.add("reference_timeouts", c.reference_timeouts);
    s.add("states_accepted", st.states_accepted.load(std::memory_order_relaxed));
    s.add("states_unknown_name", st.states_unknown_name.load(std::memory_order_relaxed));
    st.state_rejections.addTo(s, "states_rejected");
    s.add("nonfinite_commands", c.nonfinite_commands);
    s.add("solver_rejections", c.solver_rejections);
    s.add("solves_deferred", c.solves_deferred);
    return s.status();
  }

  std::string name_;  // the node's (logs; a single pool's status name too)
  GroupSpec spec_;
  PoolGroup group_;
  std::vector<std::unique_ptr<PoolStats>> stats_;  // per pool, group order
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
  sem_t state_ready_;           // posted by onState under ~tick_on_state
  std::atomic<bool> fifo_refused_{false};
  sem_t command_ready_;
  Clock::time_point window_start_;
  std::atomic<std::uint64_t> published_{0};
  std::atomic<long long> state_received_ns_{0};  // steady clock of the last accepted state, 0 = none
  std::uint64_t last_published_ = 0;
};

// Declared in pool_node.cpp and pool_nodelet.cpp. Throws std::runtime_error (one line
// naming the bad parameter) when the configuration is invalid.
std::shared_ptr<void> startPool(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& name) {
  return std::make_shared<PoolRos>(nh, pnh, name);
}

}  // namespace adroit::pneumatics
