#include "adroit_driver/sim_driver.h"

#include <ros/package.h>

#include <boost/make_shared.hpp>

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <rosgraph_msgs/Clock.h>

#include "adroit_description/scenes.h"

namespace adroit::driver {

namespace {
using SteadyClock = std::chrono::steady_clock;

double wallSeconds() { return std::chrono::duration<double>(SteadyClock::now().time_since_epoch()).count(); }

// Typed parameter access: a parameter that is set with the wrong type is an error, not a
// silent default.
template <typename T>
T param(const ros::NodeHandle& pnh, const std::string& name, const T& fallback, const char* type) {
  if (!pnh.hasParam(name)) return fallback;
  T value;
  if (!pnh.getParam(name, value)) throw ParameterError("~" + name + " must be " + type);
  return value;
}
double paramDouble(const ros::NodeHandle& pnh, const std::string& name, double fallback) {
  return param<double>(pnh, name, fallback, "a number");
}

// Publication every `steps` physics steps; the rate must divide the step rate so that the
// published stream is regular (no 2-3-2-3 step beat).
int stepsPerPublication(const std::string& name, double rate, double timestep) {
  if (!(rate > 0) || !std::isfinite(rate))
    throw ParameterError("~" + name + " must be > 0 Hz, got " + std::to_string(rate));
  const double ratio = 1.0 / (rate * timestep);
  const int steps = static_cast<int>(std::lround(ratio));
  if (steps < 1 || std::abs(ratio - steps) > 1e-6)
    throw ParameterError("~" + name + " must be the step rate " + std::to_string(1.0 / timestep) +
                         " Hz divided by a whole number, got " + std::to_string(rate));
  return steps;
}

std::string boolText(bool b) { return b ? "true" : "false"; }
}  // namespace

DriverParams readParams(const ros::NodeHandle& pnh) {
  DriverParams p;
  SimConfig& c = p.sim;
  const std::string model_file = param<std::string>(pnh, "model_file", "", "a string");
  const std::string scene = param<std::string>(pnh, "scene", "arm_hand", "a string");
  if (!model_file.empty()) {
    c.model_path = model_file;
  } else {
    const std::string share = ros::package::getPath("adroit_description");
    if (share.empty()) throw ParameterError("~scene: package adroit_description not found");
    try {
      c.model_path = description::sceneFile(share, scene);
    } catch (const std::exception& e) {
      throw ParameterError(std::string("~scene: ") + e.what());
    }
  }
  const std::string mode = param<std::string>(pnh, "mode", "pneumatic", "a string");
  const auto parsed = parseMode(mode);
  if (!parsed) throw ParameterError("~mode must be 'pneumatic' or 'force', got '" + mode + "'");
  c.mode = *parsed;
  c.timestep = paramDouble(pnh, "timestep", c.timestep);
  c.watchdog_timeout = paramDouble(pnh, "watchdog_timeout", c.watchdog_timeout);
  c.min_tension = paramDouble(pnh, "min_tension", c.min_tension);
  c.supply_pressure = paramDouble(pnh, "supply_pressure", c.supply_pressure);
  c.initial_keyframe = param<std::string>(pnh, "initial_keyframe", c.initial_keyframe, "a string");
  SensorRealism& s = c.sensors;
  s.enabled = param<bool>(pnh, "sensor_realism", s.enabled, "true or false");
  const int seed = param<int>(pnh, "seed", static_cast<int>(s.seed), "an integer");
  if (seed < 0) throw ParameterError("~seed must be >= 0, got " + std::to_string(seed));
  s.seed = static_cast<std::uint64_t>(seed);
  s.joint_rate = paramDouble(pnh, "sensors/joint_rate", s.joint_rate);
  s.joint_noise_std = paramDouble(pnh, "sensors/joint_noise_std", s.joint_noise_std);
  s.joint_velocity_noise_std = paramDouble(pnh, "sensors/joint_velocity_noise_std", s.joint_velocity_noise_std);
  s.joint_quantum = paramDouble(pnh, "sensors/joint_quantum", s.joint_quantum);
  s.joint_delay = paramDouble(pnh, "sensors/joint_delay", s.joint_delay);
  s.cylinder_delay = paramDouble(pnh, "sensors/cylinder_delay", s.cylinder_delay);
  s.cylinder.pressure_noise_std = paramDouble(pnh, "sensors/pressure_noise_std", s.cylinder.pressure_noise_std);
  s.cylinder.length_noise_std = paramDouble(pnh, "sensors/length_noise_std", s.cylinder.length_noise_std);
  s.touch_noise_std = paramDouble(pnh, "sensors/touch_noise_std", s.touch_noise_std);
  s.touch_delay = paramDouble(pnh, "sensors/touch_delay", s.touch_delay);
  s.object_noise_std = paramDouble(pnh, "sensors/object_noise_std", s.object_noise_std);
  s.object_delay = paramDouble(pnh, "sensors/object_delay", s.object_delay);
  const std::string invalid = validate(c);
  if (!invalid.empty()) throw ParameterError(invalid);

  p.realtime = param<bool>(pnh, "realtime", p.realtime, "true or false");
  p.start_paused = param<bool>(pnh, "start_paused", p.start_paused, "true or false");
  ros::param::param<bool>("/use_sim_time", p.use_sim_time, false);
  if (!p.realtime && !p.use_sim_time)
    throw ParameterError("~realtime: false (lockstep) needs /use_sim_time: true so that every node follows /clock");
  p.joint_state_rate = paramDouble(pnh, "joint_state_rate", p.joint_state_rate);
  p.actuator_state_rate = paramDouble(pnh, "actuator_state_rate", p.actuator_state_rate);
  p.touch_rate = paramDouble(pnh, "touch_rate", p.touch_rate);
  p.object_rate = paramDouble(pnh, "object_rate", p.object_rate);
  p.marker_rate = paramDouble(pnh, "marker_rate", p.marker_rate);
  if (!(p.marker_rate >= 0 && p.marker_rate <= 100))
    throw ParameterError("~marker_rate must be in [0, 100] Hz, got " + std::to_string(p.marker_rate));
  p.realtime_priority = param<int>(pnh, "realtime_priority", p.realtime_priority, "an integer");
  if (p.realtime_priority < 0 || p.realtime_priority > 99)
    throw ParameterError("~realtime_priority must be in [0, 99] (0 = normal scheduling), got " +
                         std::to_string(p.realtime_priority));
  p.lockstep_nice = param<int>(pnh, "lockstep_nice", p.lockstep_nice, "an integer");
  if (p.lockstep_nice < -20 || p.lockstep_nice > 0)
    throw ParameterError("~lockstep_nice must be in [-20, 0] (0 = unchanged), got " + std::to_string(p.lockstep_nice));
  p.diagnostics_period = paramDouble(pnh, "diagnostics_period", p.diagnostics_period);
  if (!(p.diagnostics_period >= 0.05 && p.diagnostics_period <= 60))
    throw ParameterError("~diagnostics_period must be in [0.05, 60] s, got " + std::to_string(p.diagnostics_period));
  return p;
}

// ---------------------------------------------------------------------------- setup

SimDriver::SimDriver(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), io_(nh, "adroit") {
  params_ = readParams(pnh);
  const double dt = params_.sim.timestep;
  joint_every_ = stepsPerPublication("joint_state_rate", params_.joint_state_rate, dt);
  actuator_every_ = stepsPerPublication("actuator_state_rate", params_.actuator_state_rate, dt);
  touch_every_ = stepsPerPublication("touch_rate", params_.touch_rate, dt);
  object_every_ = stepsPerPublication("object_rate", params_.object_rate, dt);
  try {
    robot_ = std::make_unique<SimulatedRobot>(params_.sim);
  } catch (const std::invalid_argument& e) {
    throw ParameterError(e.what());
  } catch (const std::runtime_error& e) {  // ModelLoadError and cylinder table errors
    throw ParameterError(std::string("~scene/~model_file: ") + e.what());
  }
  paused_ = params_.start_paused;
  wall_offset_ = ros::WallTime::now().toSec();

  joint_msg_.name = robot_->jointNames();
  actuator_msg_.name = robot_->cylinderNames();
  touch_msg_.name = robot_->touchNames();
  odom_msg_.header.frame_id = "world";
  odom_msg_.child_frame_id = "object";

  joint_pub_ = io_.advertise<sensor_msgs::JointState>("joint_states", 10);
  actuator_pub_ = io_.advertise<adroit_msgs::ActuatorStates>("actuator_states", 10);
  touch_pub_ = io_.advertise<adroit_msgs::Touch>("touch", 10);
  if (robot_->hasObject()) odom_pub_ = io_.advertise<nav_msgs::Odometry>("object/odom", 10);
  diag_pub_ = io_.advertise<diagnostic_msgs::DiagnosticArray>("diagnostics", 5);
  safe_pub_ = io_.advertise<std_msgs::Bool>("safe_state", 1, true);
  marker_pub_ = io_.advertise<visualization_msgs::MarkerArray>("markers", 2);
  if (params_.use_sim_time) clock_pub_ = nh_.advertise<rosgraph_msgs::Clock>("/clock", 10);
  tf_ = std::make_unique<tf2_ros::TransformBroadcaster>();

  const auto hints = ros::TransportHints().tcpNoDelay();
  valve_sub_ = io_.subscribe("valve_command", 10, &SimDriver::onValveCommand, this, hints);
  force_sub_ = io_.subscribe("tendon_force_command", 10, &SimDriver::onForceCommand, this, hints);
  estop_input_sub_ = io_.subscribe("estop_input", 10, &SimDriver::onEstopInput, this, hints);
  services_.push_back(io_.advertiseService("reset", &SimDriver::onReset, this));
  services_.push_back(io_.advertiseService("set_object_pose", &SimDriver::onSetObjectPose, this));
  services_.push_back(io_.advertiseService("pause", &SimDriver::onPause, this));
  services_.push_back(io_.advertiseService("step", &SimDriver::onStep, this));
  services_.push_back(io_.advertiseService("estop", &SimDriver::onEstop, this));
  services_.push_back(io_.advertiseService("estop_release", &SimDriver::onRelease, this));
  diag_timer_ = nh_.createWallTimer(ros::WallDuration(params_.diagnostics_period), &SimDriver::onDiagnostics, this);
  publishSafeStateIfChanged();

  ROS_INFO("adroit_sim: %s, %s mode, %zu cylinders, %zu joints, dt %.4f s, %s%s, sensor realism %s (seed %lu)",
           params_.sim.model_path.c_str(), modeName(params_.sim.mode), robot_->cylinders().size(),
           robot_->jointNames().size(), dt, params_.realtime ? "real time" : "lockstep",
           params_.use_sim_time ? " with /clock" : "", params_.sim.sensors.enabled ? "on" : "off",
           static_cast<unsigned long>(params_.sim.sensors.seed));
}

SimDriver::~SimDriver() { stop(); }

void SimDriver::start() {
  if (running_.exchange(true)) return;
  if (!params_.realtime) {  // real time: the simulation thread publishes
    {
      std::lock_guard<std::mutex> lock(publish_mutex_);
      publisher_running_ = true;
    }
    publisher_ = std::thread(&SimDriver::publishLoop, this);
  }
  thread_ = std::thread(&SimDriver::loop, this);
}

void SimDriver::stop() {
  if (!running_.exchange(false)) return;
  control_cv_.notify_all();
  published_cv_.notify_all();  // a simulation thread waiting for queue space must see the stop
  if (thread_.joinable()) thread_.join();
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    publisher_running_ = false;  // the publisher drains what is queued, then ends
  }
  work_cv_.notify_all();
  if (publisher_.joinable()) publisher_.join();
}

ros::Time SimDriver::stamp() const {
  // Sim time: the driver's monotonic clock is the ROS clock. Wall time: the wall time the
  // real-time schedule assigns to this state (regular, unlike the publication instant).
  return params_.use_sim_time ? ros::Time(robot_->clock()) : ros::Time(wall_offset_ + robot_->clock());
}

// ---------------------------------------------------------------------------- loop

bool SimDriver::enterRealtimeScheduling() {
  sched_param sp{};
  sp.sched_priority = params_.realtime_priority;
  const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  if (error != 0) {
    ROS_WARN("adroit_sim: ~realtime_priority %d: SCHED_FIFO not permitted (%s); stepping with normal scheduling "
             "(grant an rtprio limit or CAP_SYS_NICE, or set ~realtime_priority: 0)",
             params_.realtime_priority, std::strerror(error));
    return false;
  }
  fifo_priority_ = params_.realtime_priority;
  ROS_INFO("adroit_sim: simulation thread under SCHED_FIFO, priority %d", params_.realtime_priority);
  return true;
}

void SimDriver::leaveRealtimeScheduling(const char* why) {
  sched_param sp{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
  fifo_priority_ = 0;
  ROS_WARN("adroit_sim: leaving SCHED_FIFO: %s", why);
}

void SimDriver::raiseLockstepWeight() {
  if (params_.lockstep_nice == 0) return;
  if (std::thread::hardware_concurrency() < 2) {
    ROS_WARN("adroit_sim: one CPU: ~lockstep_nice not applied, so that the other nodes keep a share of it");
    return;
  }
  // Linux: a thread id as PRIO_PROCESS sets the nice value of that thread alone.
  if (setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), params_.lockstep_nice) != 0) {
    ROS_WARN("adroit_sim: ~lockstep_nice %d not permitted (%s); stepping at the default weight "
             "(grant a nice limit or CAP_SYS_NICE, or set ~lockstep_nice: 0)",
             params_.lockstep_nice, std::strerror(errno));
    return;
  }
  thread_nice_ = params_.lockstep_nice;
}

void SimDriver::loop() {
  const double dt = params_.sim.timestep;
  // Real time: state k is published at origin + k dt (wall); computing it happens before.
  auto origin = SteadyClock::now();
  double origin_clock = 0;
  bool resync = true;
  // A SCHED_FIFO thread that never sleeps would starve its core: after this many deadlines
  // missed in a row (the machine cannot step this scene in real time) it returns to normal
  // scheduling.
  constexpr int kMaxMissedInRow = 250;
  sim_thread_id_ = syscall(SYS_gettid);
  bool fifo = params_.realtime && params_.realtime_priority > 0 && enterRealtimeScheduling();
  if (!params_.realtime) raiseLockstepWeight();
  int missed_in_row = 0;
  while (running_) {
    bool requested = false, last_requested = false, publish_now = false;
    {
      std::unique_lock<std::mutex> lock(control_mutex_);
      publish_now = publish_now_;
      publish_now_ = false;
      if (paused_ && pending_steps_ == 0 && !publish_now) {
        lock.unlock();
        flushPublication();  // nothing follows for a while: what is queued goes out now
        lock.lock();
        if (paused_ && pending_steps_ == 0 && !publish_now_) control_cv_.wait_for(lock, std::chrono::milliseconds(50));
        resync = true;
        missed_in_row = 0;
        continue;
      }
      requested = paused_ && pending_steps_ > 0;
      last_requested = requested && pending_steps_ == 1;
    }
    if (publish_now) {
      publishDue(true, wallSeconds(), true);
      continue;
    }
    const auto compute_start = SteadyClock::now();
    double clock_after;
    {
      std::lock_guard<std::mutex> lock(robot_mutex_);
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
    double lateness = -1;  // publication after the deadline (s), real time on schedule
    if (params_.realtime && !requested) {
      auto deadline = origin + std::chrono::duration_cast<SteadyClock::duration>(
                                   std::chrono::duration<double>(clock_after - origin_clock - dt));
      const double late = std::chrono::duration<double>(compute_end - deadline).count();
      if (late > params_.max_lag) {
        // Far behind (machine overloaded, debugger): restart the schedule from now rather
        // than running fast to catch up.
        std::lock_guard<std::mutex> lock(stats_mutex_);
        ++resyncs_;
        resync = true;
      } else if (late > 0) {
        std::lock_guard<std::mutex> lock(stats_mutex_);
        ++deadline_misses_;
      } else {
        missed_in_row = -1;
        std::this_thread::sleep_until(deadline);
      }
      if (++missed_in_row >= kMaxMissedInRow && fifo) {
        leaveRealtimeScheduling(("the simulation cannot keep real time (" + std::to_string(kMaxMissedInRow) +
                                 " deadlines missed in a row)").c_str());
        fifo = false;
      }
      if (!resync) lateness = std::max(0.0, std::chrono::duration<double>(SteadyClock::now() - deadline).count());
    }
    // Real time: every state goes out at its deadline, from this thread. Lockstep: the
    // publisher is woken for a few steps at a time (see publishDue), and at once after the
    // last requested step.
    const double step_seconds = std::chrono::duration<double>(compute_end - compute_start).count();
    publishDue(false, wallSeconds(), params_.realtime || last_requested);
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      step_time_.add(step_seconds);
      if (lateness >= 0) lateness_.add(lateness);
    }
    if (requested) {
      std::lock_guard<std::mutex> lock(control_mutex_);
      if (pending_steps_ > 0 && --pending_steps_ == 0) control_cv_.notify_all();
    }
  }
}

void SimDriver::publishDue(bool all, double wall_now, bool flush) {
  std::uint64_t slot_index;
  {
    std::unique_lock<std::mutex> lock(publish_mutex_);
    published_cv_.wait(lock, [this] { return queued_batches_ - published_batches_ < kRingSize || !running_; });
    if (!running_ && !all) return;
    slot_index = queued_batches_;
  }
  // The slot is this thread's until queued_batches_ moves past it.
  Batch& batch = ring_[slot_index % kRingSize];
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    const std::uint64_t k = robot_->counters().steps;
    batch.all = all;
    batch.clock = params_.use_sim_time && !all;
    batch.joints = all || k % joint_every_ == 0;
    batch.actuators = all || k % actuator_every_ == 0;
    batch.touch = all || k % touch_every_ == 0;
    batch.object = robot_->hasObject() && (all || k % object_every_ == 0);
    batch.sim_clock = robot_->clock();
    batch.stamp = stamp();
    const Signals& sensed = robot_->sensed();
    if (batch.joints || batch.actuators || batch.touch || batch.object) batch.signals = sensed;
    if (batch.actuators) batch.command = robot_->appliedCommand();
    batch.markers.reset();
    const bool markers = params_.marker_rate > 0 &&
                         (all || wall_now - last_marker_wall_ >= 1.0 / params_.marker_rate) &&
                         marker_pub_.getNumSubscribers() > 0;
    if (markers) {
      fillMarkers();
      last_marker_wall_ = wall_now;
      batch.markers = boost::make_shared<visualization_msgs::MarkerArray>(marker_msg_);
    }
  }
  bool wake = false;
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    ++queued_batches_;
    // Lockstep: waking the publisher costs more than handing it a batch (a futex wake-up, an
    // IPI on a VM, and roscpp's poll and /clock threads woken in turn); a polling publisher
    // finds the batch by itself (see kPollPeriod). The order of the batches does not change.
    wake = publisher_idle_ ||
           (publisher_polling_ && (flush || queued_batches_ - published_batches_ >= kRingSize / 2));
  }
  if (params_.realtime) {
    publishQueued();
  } else if (wake) {
    work_cv_.notify_one();
  }
  publishSafeStateIfChanged();
}

void SimDriver::flushPublication() {
  bool wake;
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    wake = (publisher_idle_ || publisher_polling_) && queued_batches_ > published_batches_;
  }
  if (wake) work_cv_.notify_one();
}

std::uint64_t SimDriver::queuedBatches() {
  std::lock_guard<std::mutex> lock(publish_mutex_);
  return queued_batches_;
}

void SimDriver::waitForPublication(std::uint64_t batches) {
  // Bounded wait: a stopping driver must not hang the service thread.
  std::unique_lock<std::mutex> lock(publish_mutex_);
  published_cv_.wait_for(lock, std::chrono::seconds(2),
                       [&] { return published_batches_ >= batches || !running_; });
}

void SimDriver::republishAndWait() {
  // At least the republish batch the loop is about to queue; every batch queued after the
  // reset reads the new state. Returning once it is out, after every older queued state,
  // means a caller never receives a pre-reset message after the service answered.
  const std::uint64_t target = queuedBatches() + 1;
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    publish_now_ = true;
  }
  control_cv_.notify_all();
  waitForPublication(target);
}

void SimDriver::publishLoop() {
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

void SimDriver::publishQueued() {
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

void SimDriver::publishClock(double sim_clock) {
  // By shared pointer: this node's own /clock subscription (roscpp subscribes every node to
  // /clock under /use_sim_time) then gets the message directly, without a serialisation.
  auto clock = boost::make_shared<rosgraph_msgs::Clock>();
  clock->clock = ros::Time(sim_clock);
  clock_pub_.publish(clock);
}

void SimDriver::publishBatch(const Batch& batch) {
  fillMessages(batch);
  if (batch.joints) {
    joint_pub_.publish(joint_msg_);
    const double wall_now = wallSeconds();
    std::lock_guard<std::mutex> lock(stats_mutex_);
    if (!batch.all && last_joint_wall_ > 0 && joint_intervals_.size() < 2000000)
      joint_intervals_.push_back(wall_now - last_joint_wall_);
    last_joint_wall_ = batch.all ? -1 : wall_now;
  }
  if (batch.actuators) actuator_pub_.publish(actuator_msg_);
  if (batch.touch) touch_pub_.publish(touch_msg_);
  if (batch.object) {
    odom_pub_.publish(odom_msg_);
    geometry_msgs::TransformStamped t;
    t.header = odom_msg_.header;
    t.child_frame_id = odom_msg_.child_frame_id;
    t.transform.translation.x = odom_msg_.pose.pose.position.x;
    t.transform.translation.y = odom_msg_.pose.pose.position.y;
    t.transform.translation.z = odom_msg_.pose.pose.position.z;
    t.transform.rotation = odom_msg_.pose.pose.orientation;
    tf_->sendTransform(t);
  }
  if (batch.markers) marker_pub_.publish(batch.markers);
}

void SimDriver::fillMessages(const Batch& batch) {
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
    const auto& o = s.object;
    odom_msg_.header.stamp = batch.stamp;
    auto& pose = odom_msg_.pose.pose;
    pose.position.x = o[0], pose.position.y = o[1], pose.position.z = o[2];
    pose.orientation.w = o[3], pose.orientation.x = o[4], pose.orientation.y = o[5], pose.orientation.z = o[6];
    // nav_msgs/Odometry: twist in the child (object) frame. MuJoCo's free joint gives the
    // linear velocity in the world frame and the angular one in the body frame.
    double rot[9], linear_body[3];
    mju_quat2Mat(rot, o.data() + 3);
    mju_rotVecMatT(linear_body, o.data() + 7, rot);
    auto& tw = odom_msg_.twist.twist;
    tw.linear.x = linear_body[0], tw.linear.y = linear_body[1], tw.linear.z = linear_body[2];
    tw.angular.x = o[10], tw.angular.y = o[11], tw.angular.z = o[12];
  }
}

// ---------------------------------------------------------------------------- commands

void SimDriver::reportCommand(const char* topic, const CommandResult& result) {
  if (result.applied) return;
  const bool valid = result.verdict == CommandVerdict::kAccepted || result.verdict == CommandVerdict::kClamped;
  if (!valid) {
    ROS_ERROR_THROTTLE(1.0, "adroit_sim: %s rejected: %s", topic, result.error.c_str());
    return;
  }
  // A valid command while the safe state holds is expected (the senders keep running until
  // release; at shutdown their last commands land here): said once per safe-state episode.
  if (!warned_ignored_while_safe_.exchange(true))
    ROS_WARN("adroit_sim: %s and further commands ignored until /adroit/estop_release: %s", topic,
             result.error.c_str());
}

void SimDriver::onValveCommand(const adroit_msgs::ValveCommand::ConstPtr& msg) {
  CommandResult result;
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    result = robot_->commandValves(msg->name, msg->index, msg->volts);
  }
  reportCommand("valve_command", result);
}

void SimDriver::onForceCommand(const adroit_msgs::TendonForceCommand::ConstPtr& msg) {
  CommandResult result;
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    result = robot_->commandForces(msg->name, msg->index, msg->force);
  }
  reportCommand("tendon_force_command", result);
}

void SimDriver::onEstopInput(const std_msgs::Bool::ConstPtr& msg) {
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    if (msg->data && !robot_->safety().estop_input) ROS_WARN("adroit_sim: e-stop input held: safe state");
    robot_->setEstopInput(msg->data);
  }
  publishSafeStateIfChanged();
}

void SimDriver::publishSafeStateIfChanged() {
  bool safe;
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    safe = robot_->safety().safe_state;
    if (safe_published_once_ && safe == last_safe_published_) return;
    safe_published_once_ = true;
    last_safe_published_ = safe;
  }
  std_msgs::Bool msg;
  msg.data = safe;
  safe_pub_.publish(msg);
}

// ---------------------------------------------------------------------------- services

bool SimDriver::onReset(adroit_msgs::Reset::Request& req, adroit_msgs::Reset::Response& res) {
  std::string error;
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    const bool by_state = req.keyframe.empty() && (!req.qpos.empty() || !req.qvel.empty() || !req.pressure.empty());
    if (!req.keyframe.empty() && (!req.qpos.empty() || !req.qvel.empty() || !req.pressure.empty())) {
      res.success = false;
      res.message = "give either a keyframe or state arrays, not both";
      return true;
    }
    res.success = by_state ? robot_->resetToState(req.qpos, req.qvel, req.pressure, &error)
                           : robot_->resetToKeyframe(req.keyframe, &error);
  }
  res.message = res.success ? "reset" : error;
  if (res.success) {
    republishAndWait();
  } else {
    ROS_ERROR("adroit_sim: reset refused: %s", error.c_str());
  }
  return true;
}

bool SimDriver::onSetObjectPose(adroit_msgs::SetObjectPose::Request& req, adroit_msgs::SetObjectPose::Response& res) {
  const auto& p = req.pose.position;
  const auto& q = req.pose.orientation;
  const auto& l = req.twist.linear;
  const auto& a = req.twist.angular;
  std::string error;
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    res.success = robot_->setObjectPose({p.x, p.y, p.z}, {q.w, q.x, q.y, q.z}, {l.x, l.y, l.z}, {a.x, a.y, a.z}, &error);
  }
  res.message = res.success ? "object placed" : error;
  if (res.success) republishAndWait();
  return true;
}

bool SimDriver::onPause(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res) {
  std::lock_guard<std::mutex> lock(control_mutex_);
  paused_ = req.data;
  if (!paused_) pending_steps_ = 0;
  control_cv_.notify_all();
  res.success = true;
  res.message = paused_ ? "paused" : "running";
  return true;
}

bool SimDriver::onStep(adroit_msgs::Step::Request& req, adroit_msgs::Step::Response& res) {
  std::unique_lock<std::mutex> lock(control_mutex_);
  if (!paused_) {
    res.success = false;
    res.message = "the simulation is running; pause it (/adroit/pause) before stepping";
  } else if (req.steps > 0) {
    pending_steps_ += req.steps;
    control_cv_.notify_all();
    const double budget = 10.0 + req.steps * params_.sim.timestep * 100.0;
    res.success = control_cv_.wait_for(lock, std::chrono::duration<double>(budget),
                                       [this] { return pending_steps_ == 0 || !paused_ || !running_; }) &&
                  pending_steps_ == 0;
    res.message = res.success ? "stepped" : "stepping interrupted (resumed, stopped or timed out)";
  } else {
    res.success = true;
    res.message = "nothing to do";
  }
  lock.unlock();
  // Answer once the stepped states are out, so a caller sees them before the reply.
  waitForPublication(queuedBatches());
  std::lock_guard<std::mutex> robot_lock(robot_mutex_);
  res.sim_time = robot_->clock();
  return true;
}

bool SimDriver::onEstop(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    robot_->estop();
  }
  ROS_WARN("adroit_sim: e-stop: supply exhausted, every valve open to exhaust (latched)");
  publishSafeStateIfChanged();
  res.success = true;
  res.message = "e-stop latched";
  return true;
}

bool SimDriver::onRelease(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    res.success = robot_->release(&res.message);
  }
  if (res.success) {
    warned_ignored_while_safe_ = false;
    ROS_INFO("adroit_sim: safe state %s", res.message.c_str());
  }
  else ROS_WARN("adroit_sim: release %s", res.message.c_str());
  publishSafeStateIfChanged();
  return true;
}

// ---------------------------------------------------------------------------- diagnostics

void SimDriver::onDiagnostics(const ros::WallTimerEvent&) {
  diagnostic_msgs::DiagnosticStatus status;
  status.name = "adroit_sim";
  status.hardware_id = "simulation";
  auto add = [&status](const std::string& key, const std::string& value) {
    diagnostic_msgs::KeyValue kv;
    kv.key = key;
    kv.value = value;
    status.values.push_back(kv);
  };
  SafetyStatus safety;
  Counters counters;
  double clock, physics_time;
  {
    std::lock_guard<std::mutex> lock(robot_mutex_);
    safety = robot_->safety();
    counters = robot_->counters();
    clock = robot_->clock();
    physics_time = robot_->data()->time;
  }
  bool paused;
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    paused = paused_;
  }
  const double wall = wallSeconds();
  double rtf = 0, steps_per_second = 0;
  SampleStats step_samples, lateness_samples;
  std::uint64_t misses, resyncs;
  {
    // Only swaps under the lock: the simulation thread takes it every step.
    std::lock_guard<std::mutex> lock(stats_mutex_);
    if (window_wall_ > 0 && wall > window_wall_) {
      rtf = (clock - window_clock_) / (wall - window_wall_);
      steps_per_second = (counters.steps - window_steps_) / (wall - window_wall_);
    }
    window_wall_ = wall;
    window_clock_ = clock;
    window_steps_ = counters.steps;
    std::swap(step_samples, step_time_);
    std::swap(lateness_samples, lateness_);
    misses = deadline_misses_;
    resyncs = resyncs_;
  }
  const Summary step_time = step_samples.summary(), lateness = lateness_samples.summary();
  add("mode", modeName(params_.sim.mode));
  add("time_mode", params_.realtime ? "realtime" : "lockstep");
  add("paused", boolText(paused));
  add("clock", std::to_string(clock));
  add("physics_time", std::to_string(physics_time));
  add("real_time_factor", std::to_string(rtf));
  add("steps_per_second", std::to_string(steps_per_second));
  add("step_time", formatSummary(step_time, 1e6, "us"));
  add("publication_lateness", formatSummary(lateness, 1e6, "us"));
  add("deadline_misses", std::to_string(misses));
  const int fifo = fifo_priority_;
  const int nice = thread_nice_;
  add("thread_scheduling", fifo > 0 ? "SCHED_FIFO " + std::to_string(fifo)
                           : nice != 0 ? "normal, nice " + std::to_string(nice) : "normal");
  add("schedule_resyncs", std::to_string(resyncs));
  add("safe_state", boolText(safety.safe_state));
  add("estop_latched", boolText(safety.estop_latched));
  add("estop_input", boolText(safety.estop_input));
  add("watchdog_armed", boolText(safety.watchdog_armed));
  add("watchdog_latched", boolText(safety.watchdog_latched));
  add("watchdog_timeout", std::to_string(params_.sim.watchdog_timeout));
  add("fault_latched", boolText(safety.fault_latched));
  add("fault_persists", boolText(safety.fault_persists));
  add("fault", safety.fault);
  add("steps", std::to_string(counters.steps));
  add("commands_accepted", std::to_string(counters.accepted));
  add("commands_clamped", std::to_string(counters.clamped));
  add("rejected_total", std::to_string(counters.rejected()));
  add("rejected_addressing", std::to_string(counters.rejected_addressing));
  add("rejected_name", std::to_string(counters.rejected_name));
  add("rejected_not_finite", std::to_string(counters.rejected_not_finite));
  add("rejected_range", std::to_string(counters.rejected_range));
  add("rejected_wrong_mode", std::to_string(counters.rejected_wrong_mode));
  add("ignored_while_safe", std::to_string(counters.ignored_while_safe));
  add("watchdog_trips", std::to_string(counters.watchdog_trips));
  add("estops", std::to_string(counters.estops));
  add("faults", std::to_string(counters.faults));
  if (safety.fault_latched) {
    status.level = diagnostic_msgs::DiagnosticStatus::ERROR;
    status.message = "fault latched: " + safety.fault;
  } else if (safety.safe_state) {
    status.level = diagnostic_msgs::DiagnosticStatus::WARN;
    status.message = safety.estop_latched ? "safe state: e-stop" : "safe state: command watchdog";
  } else {
    status.level = diagnostic_msgs::DiagnosticStatus::OK;
    status.message = paused ? "paused" : "running";
  }
  diagnostic_msgs::DiagnosticArray array;
  array.header.stamp = ros::Time::now();
  array.status.push_back(status);
  diag_pub_.publish(array);
}

std::vector<double> SimDriver::takeJointIntervals() {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  std::vector<double> out;
  out.swap(joint_intervals_);
  return out;
}

std::uint64_t SimDriver::steps() { return steps_done_.load(std::memory_order_relaxed); }

}  // namespace adroit::driver
