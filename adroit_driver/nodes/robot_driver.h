// The driver's ROS wrapper of a Robot (robot.h): one wrapper for the simulated robot (node
// adroit_sim, SimNodelet) and the hardware over CAN (node adroit_hw), so the two present the
// same topics, services and diagnostics by construction. One file per job:
//   sim_params.cpp           ~parameters -> DriverParams + SimConfig, the simulation driver
//   hardware_params.cpp      ~parameters -> DriverParams + CanRobotConfig, the hardware driver
//   robot_driver.cpp         set-up: topics, services, the two callback queues, start/stop
//   driver_loop.cpp          the robot thread: pacing (real time / lockstep / input-driven)
//   driver_publication.cpp   the publication ring and the publisher thread (messages, /clock, tf)
//   driver_services.cpp      commands, e-stop, pause, step, reset, set object pose, recover
//   driver_diagnostics.cpp   diagnostics, and each safety event logged once
//   driver_markers.cpp       rviz markers built from a snapshot, off the robot thread
//
// Threads. The robot thread steps the robot and hands each step's outputs to the
// publisher thread through a preallocated ring: after start-up it allocates nothing,
// serialises nothing and logs nothing (test_sim_allocations proves it). The safety path
// (e-stop service and input, release, pause, valve and force commands, the safety monitor)
// has its own callback queue and spinner thread, so a long /step or /reset on the default
// queue never delays it. A robot driven by its input (the hardware) is stepped as soon as
// input arrives and at least every timestep, and each output is published when a new
// sample of it is in.
#pragma once

#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/CommandLatency.h>
#include <geometry_msgs/PoseStamped.h>
#include <adroit_msgs/Reset.h>
#include <adroit_msgs/SetObjectPose.h>
#include <adroit_msgs/Step.h>
#include <adroit_msgs/TendonForceCommand.h>
#include <adroit_msgs/Touch.h>
#include <adroit_msgs/ValveCommand.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include "adroit_core/mujoco_model.h"
#include "adroit_core/pi_mutex.h"
#include "adroit_core/timing_stats.h"
#include "adroit_ros/realtime.h"
#include "adroit_driver/robot.h"
#include "adroit_ros/params.h"

namespace adroit::driver {

using ParameterError = rosutil::ParameterError;

// Monotonic wall time in seconds (pacing, rates, grace periods).
inline double wallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// What the wrapper reads from its private parameters (config/sim.yaml, config/hardware.yaml);
// the robot's own configuration is read by the node that builds it.
struct DriverParams {
  bool realtime = true;
  bool use_sim_time = false;
  bool start_paused = false;
  double joint_state_rate = 500, actuator_state_rate = 250, touch_rate = 250, object_rate = 250;
  double marker_rate = 20;          // wall Hz, only while someone listens
  double diagnostics_period = 1.0;  // wall s
  // s behind schedule before real time re-synchronises rather than running steps back to
  // back to catch up (a stalled machine pauses the simulated world instead of fast-forwarding
  // it past commands that could not arrive meanwhile).
  double max_lag = 0.02;
  // Diagnostics warn about cylinders never commanded once this long (wall s) has passed
  // since start or release: a pool that never started leaves its cylinders unwatched.
  double never_commanded_grace = 10.0;
  // Real time only: SCHED_FIFO priority of the wrapper's I/O (publisher realtime_priority - 1,
  // safety queue - 2, roscpp's threads - 3) and of the hardware's robot thread; 0 = normal
  // scheduling. Falls back to normal scheduling, with a warning, when not permitted.
  int realtime_priority = 20;
  // Real time, simulation only: SCHED_FIFO priority of the physics (the simulation thread),
  // below every controller's command path (pools 14-16, teleop 12-13, MPC 10-12; adroit_ros
  // realtime.h): the simulated world is the plant, not the safety path. On a machine that
  // cannot run everything on time the physics yields, the real-time factor drops (reported),
  // and the commands the watchdog waits for keep flowing. At the top priority it took a core
  // to catch up after every slow-down of the machine while the pools waited, and the
  // watchdog tripped on commands that could not be sent. 0 = normal scheduling.
  int physics_priority = 9;
  // Lockstep only: nice value of the simulation thread, in [-20, 0], 0 = unchanged. The
  // thread never sleeps there, so SCHED_FIFO would be throttled (50 ms stalls every second);
  // a high normal-scheduling weight instead keeps consumer processes from preempting it.
  int lockstep_nice = -20;
};

// Reads and validates the wrapper's ~parameters. Throws ParameterError. `simulated` false
// (hardware): real time only, no /clock, no start paused.
DriverParams readDriverParams(const rosutil::Params& p, bool simulated);
// The ~keys readDriverParams reads, for Params::checkKeys of the node that calls it.
std::set<std::string> driverKeys(bool simulated);
// The simulation's own ~parameters (scene, mode, timestep, sensors...). Throws ParameterError.
SimConfig readSimConfig(const rosutil::Params& p);
class RobotDriver;
// The simulation driver from ~parameters (SimulatedRobot). Throws ParameterError.
std::unique_ptr<RobotDriver> makeSimDriver(ros::NodeHandle nh, ros::NodeHandle pnh);
// The hardware driver from ~parameters (CanRobot, hardware_params.cpp). Throws ParameterError,
// or std::runtime_error when the robot does not come up within ~connect_timeout.
std::unique_ptr<RobotDriver> makeHardwareDriver(ros::NodeHandle nh, ros::NodeHandle pnh);
// A driver node's main(): ros::init as `name`, the driver from `make` (one [FATAL] line and
// exit code 1 when it throws), then two spinner threads for the default queue (a long /step
// must not hold up diagnostics; the safety path has its own queue and thread).
using DriverFactory = std::unique_ptr<RobotDriver> (*)(ros::NodeHandle nh, ros::NodeHandle pnh);
int runDriverNode(int argc, char** argv, const char* name, DriverFactory make);

// Publication every `steps` physics steps; the rate must divide the step rate so that the
// published stream is regular (no 2-3-2-3 step beat). Throws ParameterError.
int stepsPerPublication(const std::string& name, double rate, double timestep);

// The most steps one /adroit/step request may ask for (1000 simulated seconds at 2 ms):
// larger requests are refused, and any request is cancelled by pause or e-stop.
constexpr std::uint32_t kMaxStepsPerRequest = 500000;

class RobotDriver {
 public:
  // `name` prefixes the log lines and names the diagnostics status ("adroit_sim"). Throws
  // ParameterError when the rates do not suit the robot's timestep.
  RobotDriver(ros::NodeHandle nh, DriverParams params, std::unique_ptr<Robot> robot, std::string name);
  ~RobotDriver();

  void start();  // starts the simulation, publisher and safety threads
  void stop();

  // For benchmarks: publication intervals of joint_states (wall s) since the last call
  // (recorded only after collectJointIntervals(true)), and the steps simulated so far.
  void collectJointIntervals(bool on) { collect_joint_intervals_ = on; }
  std::vector<double> takeJointIntervals();
  std::uint64_t steps() const { return steps_done_.load(std::memory_order_relaxed); }
  // Kernel thread id of the simulation thread (0 before start), for scheduling statistics
  // and the allocation test.
  long simulationThreadId() const { return sim_thread_id_; }

 private:
  // What is due after one step, handed from the simulation thread to the publisher thread
  // (building, serialising and sending the messages costs about as much as a physics step,
  // and must never delay the simulation). Slots live in a ring and are reused: handing a
  // step over copies a few hundred numbers and allocates nothing.
  struct Batch {
    bool all = false;  // an explicit republish (after reset / set pose), not a step
    bool clock = false, joints = false, actuators = false, touch = false, object = false;
    bool markers = false;  // build markers from the snapshot (sim_markers.cpp)
    bool base = false;     // teleop scenes: tf world -> hand base
    // A command with a new stamp acted on for the first time in this step: its stamp and when
    // the step began (published on command_latency).
    bool latency = false;
    ros::Time command_stamp, command_applied;
    double sim_clock = 0;
    ros::Time stamp;
    Signals signals;
    std::vector<double> command;
  };

  // Robot thread.
  void loop();
  void inputLoop();  // a robot driven by its input (hardware)
  bool enterRealtimeScheduling(int priority, const char* parameter);
  void leaveRealtimeScheduling(const char* why);
  void raiseLockstepWeight();
  void recordStepTiming(double step_seconds, double lateness);
  void runPendingRequest();  // a reset / set pose handed over by a service

  // Publication (sim_publication.cpp).
  // Queues what is due after a step (all: an explicit republish). Lockstep: flush wakes a
  // polling publisher now rather than at its next look.
  void publishDue(bool all, double wall_now, bool flush);
  void flushPublication();
  void publishLoop();
  void publishQueued();
  void publishClock(double sim_clock);
  void publishBatch(const Batch& batch);
  void fillMessages(const Batch& batch);
  std::uint64_t queuedBatches();
  void waitForPublication(std::uint64_t batches);  // until that many batches are sent
  ros::Time stamp() const;

  // Markers (sim_markers.cpp): the simulation thread copies mjData and the true signals
  // into a preallocated snapshot at the marker rate; the publisher thread builds from it.
  void takeMarkerSnapshot();
  void publishMarkers();

  // Safety queue (sim_services.cpp).
  void onValveCommand(const adroit_msgs::ValveCommand::ConstPtr& msg);
  void onForceCommand(const adroit_msgs::TendonForceCommand::ConstPtr& msg);
  void onEstopInput(const std_msgs::Bool::ConstPtr& msg);
  void onBaseTarget(const geometry_msgs::PoseStamped::ConstPtr& msg);  // teleop scenes, default queue
  bool onPause(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res);
  bool onRecover(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onEstop(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onRelease(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void reportCommand(const char* topic, const CommandResult& result);
  void cancelSteps(const char* why);
  void noteCommandStamp(const ros::Time& stamp);  // wakes a /step waiting for this command  // pending /step requests end, unsuccessful
  // Default queue (sim_services.cpp).
  bool onReset(adroit_msgs::Reset::Request& req, adroit_msgs::Reset::Response& res);
  bool onSetObjectPose(adroit_msgs::SetObjectPose::Request& req, adroit_msgs::SetObjectPose::Response& res);
  bool onStep(adroit_msgs::Step::Request& req, adroit_msgs::Step::Response& res);
  // Runs `change` on the simulation thread between two steps, then republishes the state
  // and waits until it is sent. False (and *error) when refused or when the driver stops.
  bool changeState(const std::function<bool(std::string*)>& change, std::string* error);

  // Diagnostics (sim_diagnostics.cpp).
  void onDiagnostics(const ros::WallTimerEvent& event);
  void onSafetyMonitor(const ros::WallTimerEvent& event);  // safety queue, 20 Hz
  void publishSafeStateIfChanged();

  DriverParams params_;
  std::unique_ptr<Robot> robot_;
  std::string name_str_;
  const char* name_;  // name_str_.c_str(), for the log lines
  unsigned fresh_ = 0;  // input-driven robot: outputs with a new sample (robot thread, under robot_mutex_)
  int joint_every_ = 1, actuator_every_ = 1, touch_every_ = 1, object_every_ = 1;

  ros::NodeHandle nh_, io_;
  // The safety path: e-stop, release, pause and every command, on a thread of its own under
  // SCHED_FIFO just below the publisher (real time), never behind a long /step or /reset.
  rosutil::FifoCallbackQueue safety_queue_;
  ros::NodeHandle safety_io_;  // /adroit on safety_queue_
  ros::Publisher joint_pub_, actuator_pub_, touch_pub_, odom_pub_, diag_pub_, safe_pub_, marker_pub_, clock_pub_;
  ros::Subscriber valve_sub_, force_sub_, estop_input_sub_, base_sub_;
  ros::Publisher latency_pub_;
  std::atomic<std::uint64_t> base_targets_{0}, base_targets_rejected_{0};
  std::vector<ros::ServiceServer> services_;
  ros::WallTimer diag_timer_, monitor_timer_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_;

  // robot_ is guarded by robot_mutex_. The simulation thread holds it for a step; every
  // other holder only copies a few numbers (commands are validated before taking it,
  // resets and teleports run on the simulation thread itself). Priority inheritance: a
  // normal-priority holder preempted inside that window runs at the SCHED_FIFO simulation
  // thread's priority while it waits (test_pi_mutex: 37 ms instead of 336 ms behind a busy
  // thread). The other locks the simulation thread meets are either try-locks (timing,
  // marker snapshot) or guard a few counters (control, publication ring).
  PiMutex robot_mutex_;
  // Publisher thread's messages.
  sensor_msgs::JointState joint_msg_;
  adroit_msgs::ActuatorStates actuator_msg_;
  adroit_msgs::Touch touch_msg_;
  nav_msgs::Odometry odom_msg_;
  geometry_msgs::TransformStamped object_tf_, base_tf_;
  adroit_msgs::CommandLatency latency_msg_;
  // Simulation thread: the newest command stamp already acted on, and one not yet published.
  ros::Time applied_command_stamp_;
  bool latency_due_ = false;
  ros::Time latency_stamp_, latency_applied_;
  // Safety monitor's state (safety queue only).
  bool last_safe_published_ = false, safe_published_once_ = false;
  Counters logged_;            // event counters already logged
  std::atomic<std::uint64_t> estop_input_changes_{0};
  std::atomic<double> released_wall_{0};  // start or last release, for the never-commanded grace
  std::atomic<bool> warned_ignored_while_safe_{false};  // this safe-state episode
  std::atomic<bool> markers_wanted_{false};             // someone listens (checked at 20 Hz)
  std::atomic<std::uint64_t> nonfinite_suppressed_{0};  // states not published (NaN/Inf)

  // Wall-time mode: stamp = wall_offset_ + clock, the scheduled time of the state (moves
  // forward only, when the real-time schedule restarts after a pause or an overload).
  double wall_offset_ = 0;

  // Loop control, guarded by control_mutex_.
  std::mutex control_mutex_;
  std::condition_variable control_cv_;
  bool paused_ = false;
  std::uint64_t pending_steps_ = 0;
  std::string step_interruption_;  // why the last pending steps were cancelled
  std::uint64_t step_cancellations_ = 0;
  ros::Time last_command_stamp_;  // newest stamp of a valid force or valve command (lockstep)
  // A state change a service asked for, run by the simulation thread (changeState), and
  // the batch count that holds its republished state.
  const std::function<bool(std::string*)>* pending_change_ = nullptr;
  bool change_running_ = false, change_done_ = false, change_ok_ = false;
  std::string change_error_;
  std::uint64_t change_published_ = 0;

  std::atomic<bool> running_{false};
  std::atomic<std::uint64_t> steps_done_{0};
  std::atomic<int> fifo_priority_{0};  // of the simulation thread now (0 = normal scheduling)
  std::atomic<int> thread_nice_{0};    // of the simulation thread now (lockstep)
  std::atomic<int> publisher_fifo_priority_{0};  // of the publisher thread (real time), 0 = normal
  std::atomic<int> transport_fifo_priority_{0};  // of roscpp's threads (real time), 0 = normal
  std::atomic<long> sim_thread_id_{0};
  std::thread thread_;

  // Publication ring: slots [published_batches_, queued_batches_) wait for the publisher;
  // the counters are guarded by publish_mutex_. Bounded: when the publisher falls behind
  // the simulation waits, so no state is dropped and memory stays bounded.
  static constexpr std::size_t kRingSize = 64;
  // Lockstep. Waking a sleeping thread costs the waker a futex wake-up and an IPI: about
  // 50 us of CPU on the development VM, a quarter of an arm-hand step if done every step.
  // So while batches keep coming, the publisher looks for them by itself every
  // kPollPeriod and the simulation thread wakes nobody; a publisher that found nothing for
  // a period sleeps and is woken by the next batch. Real time wakes it every step (the
  // simulation thread sleeps until the next deadline anyway).
  static constexpr std::chrono::microseconds kPollPeriod{1000};
  std::mutex publish_mutex_;
  std::condition_variable work_cv_;       // the publisher waits for batches
  std::condition_variable published_cv_;  // the simulation thread / services wait for publication
  std::vector<Batch> ring_ = std::vector<Batch>(kRingSize);
  bool publisher_running_ = false;
  bool publisher_idle_ = false;     // the publisher waits for work (needs a wake-up)
  bool publisher_polling_ = false;  // the publisher looks again within kPollPeriod by itself
  std::uint64_t queued_batches_ = 0, published_batches_ = 0;
  std::thread publisher_;

  // Marker snapshot: written by the simulation thread when marker_mutex_ is free (try-lock,
  // so it never waits), read by the publisher thread.
  std::mutex marker_mutex_;
  DataPtr marker_data_;
  Signals marker_truth_;
  ros::Time marker_stamp_;
  bool marker_fresh_ = false;
  double last_marker_wall_ = -1;
  visualization_msgs::MarkerArray marker_msg_;

  // Statistics. The simulation thread adds to `timing_` under a try-lock (a sample that
  // meets a busy lock is dropped, and counted); diagnostics swap it with `timing_spare_`,
  // whose storage was reserved, so adding never allocates.
  struct StepTiming {
    SampleStats step_time;  // compute time of one step (s)
    SampleStats lateness;   // publication after the deadline (s), real time
    std::uint64_t deadline_misses = 0, resyncs = 0, dropped = 0;
  };
  static constexpr std::size_t kTimingCapacity = 1 << 16;  // samples per diagnostics window
  std::mutex stats_mutex_;
  StepTiming timing_, timing_spare_;
  std::uint64_t total_misses_ = 0, total_resyncs_ = 0;  // diagnostics thread
  std::vector<char> commanded_snapshot_;  // diagnostics thread: per cylinder, copied under the robot lock
  double window_wall_ = -1, window_clock_ = 0;
  std::uint64_t window_steps_ = 0;
  // Benchmark only (publisher thread), off unless asked for.
  std::atomic<bool> collect_joint_intervals_{false};
  std::mutex intervals_mutex_;
  std::vector<double> joint_intervals_;
  double last_joint_wall_ = -1;
};

}  // namespace adroit::driver
