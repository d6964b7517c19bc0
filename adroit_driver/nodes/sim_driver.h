// ROS wrapper of SimulatedRobot, shared by the adroit_sim node and the SimNodelet:
// parameters -> core, topics/services/timers -> core, and the simulation thread that steps
// the core (paced at real time, or lockstep) and publishes the sensors at their rates.
#pragma once

#include <ros/ros.h>

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/Reset.h>
#include <adroit_msgs/SetObjectPose.h>
#include <adroit_msgs/Step.h>
#include <adroit_msgs/TendonForceCommand.h>
#include <adroit_msgs/Touch.h>
#include <adroit_msgs/ValveCommand.h>
#include <nav_msgs/Odometry.h>
#include <rosgraph_msgs/Clock.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include "adroit_core/timing_stats.h"
#include "adroit_driver/simulated_robot.h"

namespace adroit::driver {

// A parameter is missing, malformed or out of range; what() is the one line to print.
class ParameterError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Everything the driver reads from its private parameters (see config/sim.yaml).
struct DriverParams {
  SimConfig sim;
  bool realtime = true;
  bool use_sim_time = false;
  bool start_paused = false;
  double joint_state_rate = 500, actuator_state_rate = 250, touch_rate = 250, object_rate = 250;
  double marker_rate = 20;         // wall Hz, only while someone listens
  double diagnostics_period = 1.0;  // wall s
  double max_lag = 0.1;            // s behind schedule before real time re-synchronises
  // Real time only: SCHED_FIFO priority of the simulation thread (which steps and publishes),
  // 0 = normal scheduling. Falls back to normal scheduling, with a warning, when the system
  // does not permit it.
  int realtime_priority = 20;
  // Lockstep only: nice value of the simulation thread, in [-20, 0], 0 = unchanged. The
  // thread never sleeps there, so SCHED_FIFO would be throttled (50 ms stalls every second);
  // a high normal-scheduling weight instead keeps consumer processes from preempting it.
  int lockstep_nice = -20;
};

// Reads and validates ~parameters. Throws ParameterError (unknown scene, bad value...).
DriverParams readParams(const ros::NodeHandle& pnh);

class SimDriver {
 public:
  // Throws ParameterError or ModelLoadError with one line to report.
  SimDriver(ros::NodeHandle nh, ros::NodeHandle pnh);
  ~SimDriver();

  void start();  // starts the simulation thread
  void stop();

  // For benchmarks: publication intervals of joint_states (wall s) since the last call,
  // and the steps simulated so far.
  std::vector<double> takeJointIntervals();
  std::uint64_t steps();
  // Kernel thread id of the simulation thread (0 before start), for scheduling statistics.
  long simulationThreadId() const { return sim_thread_id_; }

 private:
  // What is due after one step. Lockstep: handed from the simulation thread to the
  // publisher thread, since building, serialising and sending the messages costs about as
  // much as a physics step, so it runs on the other core. Real time: the simulation thread
  // publishes it itself at the state's deadline; a hand-over would put a second thread
  // wake-up (tens of microseconds, millisecond tails on a VM) into every 2 ms period. Slots
  // live in a ring and are reused, so handing a step over copies a few hundred numbers and
  // allocates nothing.
  struct Batch {
    bool all = false;  // an explicit republish (after reset / set pose), not a step
    bool clock = false, joints = false, actuators = false, touch = false, object = false;
    double sim_clock = 0;
    ros::Time stamp;
    Signals signals;
    std::vector<double> command;
    visualization_msgs::MarkerArray::Ptr markers;
  };

  void loop();
  void publishLoop();  // the publisher thread (lockstep only)
  // Publishes every queued batch in order. Called by one thread only: the publisher thread
  // in lockstep, the simulation thread in real time.
  void publishQueued();
  // Queues what is due after a step (all: an explicit republish) and, in real time,
  // publishes it. Lockstep: flush wakes a polling publisher now rather than at its next look.
  void publishDue(bool all, double wall_now, bool flush);
  void flushPublication();  // lockstep: wakes the publisher for whatever is queued
  // Real time: the simulation thread under SCHED_FIFO (~realtime_priority); false and one
  // warning when not permitted.
  bool enterRealtimeScheduling();
  void leaveRealtimeScheduling(const char* why);
  // Lockstep: the simulation thread at ~lockstep_nice; one warning when not permitted.
  void raiseLockstepWeight();
  void publishClock(double sim_clock);
  void publishBatch(const Batch& batch);
  // After reset / set object pose: publish the new state now and wait until it is sent.
  void republishAndWait();
  std::uint64_t queuedBatches();
  void waitForPublication(std::uint64_t batches);  // until that many batches are sent
  void fillMessages(const Batch& batch);  // publisher thread
  void fillMarkers();
  ros::Time stamp() const;

  void onValveCommand(const adroit_msgs::ValveCommand::ConstPtr& msg);
  void onForceCommand(const adroit_msgs::TendonForceCommand::ConstPtr& msg);
  void onEstopInput(const std_msgs::Bool::ConstPtr& msg);
  bool onReset(adroit_msgs::Reset::Request& req, adroit_msgs::Reset::Response& res);
  bool onSetObjectPose(adroit_msgs::SetObjectPose::Request& req, adroit_msgs::SetObjectPose::Response& res);
  bool onPause(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res);
  bool onStep(adroit_msgs::Step::Request& req, adroit_msgs::Step::Response& res);
  bool onEstop(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onRelease(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void onDiagnostics(const ros::WallTimerEvent& event);
  void reportCommand(const char* topic, const CommandResult& result);
  void publishSafeStateIfChanged();

  DriverParams params_;
  std::unique_ptr<SimulatedRobot> robot_;
  int joint_every_ = 1, actuator_every_ = 1, touch_every_ = 1, object_every_ = 1;

  ros::NodeHandle nh_, io_;
  ros::Publisher joint_pub_, actuator_pub_, touch_pub_, odom_pub_, diag_pub_, safe_pub_, marker_pub_, clock_pub_;
  ros::Subscriber valve_sub_, force_sub_, estop_input_sub_;
  std::vector<ros::ServiceServer> services_;
  ros::WallTimer diag_timer_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_;

  // robot_ and marker_msg_ are guarded by robot_mutex_; the other messages belong to the
  // publisher thread.
  std::mutex robot_mutex_;
  sensor_msgs::JointState joint_msg_;
  adroit_msgs::ActuatorStates actuator_msg_;
  adroit_msgs::Touch touch_msg_;
  nav_msgs::Odometry odom_msg_;
  visualization_msgs::MarkerArray marker_msg_;
  bool last_safe_published_ = false, safe_published_once_ = false;
  std::atomic<bool> warned_ignored_while_safe_{false};  // this safe-state episode
  // Wall-time mode: stamp = wall_offset_ + clock, the scheduled time of the state (moves
  // forward only, when the real-time schedule restarts after a pause or an overload).
  double wall_offset_ = 0;

  // Loop control, guarded by control_mutex_.
  std::mutex control_mutex_;
  std::condition_variable control_cv_;
  bool paused_ = false;
  std::uint64_t pending_steps_ = 0;
  bool publish_now_ = false;
  std::atomic<bool> running_{false};
  // Steps simulated so far, readable without the robot lock (a poller must not stall the
  // simulation thread).
  std::atomic<std::uint64_t> steps_done_{0};
  std::atomic<int> fifo_priority_{0};  // of the simulation thread now (0 = normal scheduling)
  std::atomic<int> thread_nice_{0};    // of the simulation thread now (lockstep)
  std::atomic<long> sim_thread_id_{0};
  std::thread thread_;

  // Publication ring: slots [published_batches_, queued_batches_) wait for the publisher;
  // the counters are guarded by publish_mutex_. Bounded: when the publisher falls behind
  // the simulation waits, so no state is dropped and memory stays bounded.
  static constexpr std::size_t kRingSize = 64;
  // Lockstep. Waking a sleeping thread costs the waker a futex wake-up and an IPI: about
  // 50 us of CPU on the development VM (nested KVM), a quarter of an arm-hand step if done
  // every step, plus roscpp's threads woken in turn. So: while batches keep coming, the
  // publisher looks for them by itself every kPollPeriod (a timer on its own core) and the
  // simulation thread wakes nobody; a publisher that found nothing for a period sleeps
  // and is woken by the next batch. A polling publisher is woken at once after the last
  // step of a /step request, before the simulation thread waits, for a republish, and when
  // the ring is half full. Real time publishes from the simulation thread (see Batch).
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

  // Statistics, guarded by stats_mutex_.
  std::mutex stats_mutex_;
  SampleStats step_time_;          // compute time of one step (s), this diagnostics window
  SampleStats lateness_;           // publication after the deadline (s), real-time mode
  std::vector<double> joint_intervals_;
  double last_joint_wall_ = -1;
  std::uint64_t deadline_misses_ = 0, resyncs_ = 0;
  double window_wall_ = -1, window_clock_ = 0;
  std::uint64_t window_steps_ = 0;
  double last_marker_wall_ = -1;
};

}  // namespace adroit::driver
