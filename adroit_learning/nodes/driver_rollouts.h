// Rollout backend (a): rollouts through live drivers over ROS, paced one of two ways.
//  * lockstep (simulation driver): for each control step the backend reads the driver's
//    published state, evaluates the controller next to the driver, publishes the valve command
//    stamped with a fresh stamp, and asks `step` for one control step's physics steps that start
//    only once that command has arrived (Step.srv's command_stamp).
//  * realtime (hardware, or a simulation driver running in real time): the backend paces itself
//    on the ROS clock at the control rate, reading the newest state at each tick. A keep-alive
//    thread sends a command every 10 ms: between rollouts the hold command, so the driver's
//    command watchdog never trips while the trainer computes its update; during a rollout the
//    rollout's latest command again (the valves hold it anyway), so a 25 Hz controller meets a
//    50 ms watchdog with margin. A rollout command older than two control steps is not
//    repeated: the keep-alive falls back to the hold command and counts a stall. The keep-alive
//    is the only thread that publishes commands (woken at once for a new one): no thread at
//    normal scheduling holds a lock the command path needs (the shared slot is a PiMutex).
// Resets go through `reset` (qpos in model order, pressures).
//
// Several drivers (backend (c): other machines under one master, each in its own namespace)
// run the requests in parallel, one connection per driver. The driver's safe state is never
// released here: a rollout that meets it fails and says so.
#pragma once
#include <adroit_core/mujoco_model.h>
#include <adroit_core/pi_mutex.h>
#include <adroit_learning/rollout_backend.h>
#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/Touch.h>
#include <adroit_msgs/ValveCommand.h>
#include <mujoco/mujoco.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace adroit::learning_node {

enum class Pacing { kLockstep, kRealtime };

// One driver: its topics and services under `ns` (e.g. /adroit).
class DriverConnection {
 public:
  // touch: the sensors Observation::touch reports, in order (fingertipTouch of the model's).
  DriverConnection(ros::NodeHandle& nh, const std::string& ns, double timeout, Pacing pacing,
                   std::vector<std::string> touch = {});
  ~DriverConnection();
  const std::string& ns() const { return ns_; }
  // Waits (up to the timeout) until the driver has published joint and actuator states.
  bool waitForStreams(std::string& error);
  // Whether the driver publishes object odometry (waits up to 1 s for the connection).
  bool publishesObject();
  std::vector<std::string> jointNames();
  std::vector<std::string> cylinderNames();
  // Resets to qpos/pressure with every valve at `hold_volts`. Lockstep: paused, then two
  // physics steps so every sensor stream reports the reset state. Realtime: the valves stay
  // held (keep-alive) until the rollout's first command.
  // A real robot refuses /reset (it exists only in simulation): realtime pacing then resets by
  // control (resetByControl) and the rollout starts from the measured rest posture.
  bool reset(const std::vector<double>& qpos, const std::vector<double>& pressure, double hold_volts,
             std::string& error);
  // The observation at control step t of a rollout: lockstep, the newest state stamped at the
  // end of the last step; realtime, the newest state newer than the previous observation
  // (waits up to the timeout). Realtime, t = 0 starts the rollout's clock.
  bool observe(int t, Observation& obs, std::string& error);
  // Publishes a command; the first one of a rollout ends the keep-alive hold.
  bool send(const std::vector<double>& volts, std::string& error);
  // One control step of `dt` seconds (`steps` physics steps): lockstep, the driver steps once
  // the last sent command has arrived; realtime, sleeps until the next tick on the ROS clock.
  bool advance(int steps, double dt, std::string& error);
  // Ends a rollout: the keep-alive holds the valves again (realtime).
  void hold();
  // Realtime: ticks reached after their time by more than half a control step.
  int lateTicks() const { return late_ticks_; }
  // Realtime: rollout commands the keep-alive replaced by the hold command because the rollout
  // sent none for two control steps.
  int stalls() const { return stalls_.load(); }
  // Realtime: resets done by control (a real robot, which cannot be set to a state).
  std::uint64_t resetsByControl() const { return resets_by_control_; }

 private:
  void onJoints(const sensor_msgs::JointState::ConstPtr& msg);
  void onActuators(const adroit_msgs::ActuatorStates::ConstPtr& msg);
  void onOdometry(const nav_msgs::Odometry::ConstPtr& msg);
  void onSafeState(const std_msgs::Bool::ConstPtr& msg);
  void onTouch(const adroit_msgs::Touch::ConstPtr& msg);
  bool safe(std::string& error);
  bool step(int steps, std::string& error);
  bool waitForState(ros::Time min_stamp, Observation& obs, std::string& error);
  void publish(const std::vector<double>& volts);
  bool touchFromMessage(std::vector<double>& touch, std::string& error) const;
  void keepAlive();
  // Realtime: the valves are held at `volts` from now on (the keep-alive publishes at once).
  void holdAt(std::vector<double> volts);

  std::string ns_;
  double timeout_;
  std::vector<std::string> touch_names_;
  static constexpr double kRealResetSettle = 2.0;  // s, every cylinder exhausted before a rollout on a real robot
  static constexpr double kExhaustVolts = -5.0;
  std::uint64_t resets_by_control_ = 0;
  bool resetByControl(std::size_t cylinders, double hold_volts, std::string& error);
  Pacing pacing_;
  ros::Subscriber joints_sub_, actuators_sub_, odom_sub_, safe_sub_, touch_sub_;
  ros::Publisher valve_pub_;
  ros::ServiceClient step_client_, reset_client_, pause_client_;
  std::mutex mutex_;
  std::condition_variable cv_;
  sensor_msgs::JointState::ConstPtr joints_;
  adroit_msgs::ActuatorStates::ConstPtr actuators_;
  nav_msgs::Odometry::ConstPtr odom_;
  adroit_msgs::Touch::ConstPtr touch_;  // the newest (published with the joint states)
  bool safe_state_ = false;
  ros::Time sim_time_, last_stamp_, reset_floor_;
  ros::Time next_tick_, last_observed_;  // realtime pacing
  int late_ticks_ = 0;
  // The command slot, rollout vs keep-alive; priority inheritance, so a rollout thread preempted
  // while it writes cannot stall the keep-alive (SCHED_FIFO).
  PiMutex command_mutex_;
  std::condition_variable_any command_cv_;  // wakes the keep-alive for a new command
  bool send_now_ = false;                   // (command_mutex_)
  adroit_msgs::ValveCommand command_;       // the message (lockstep: the rollout; realtime: the keep-alive)
  std::vector<double> hold_volts_, latest_volts_;  // (command_mutex_)
  std::atomic<bool> holding_{false}, stop_{false};
  std::chrono::steady_clock::time_point last_send_;  // the rollout's latest command (command_mutex_)
  double repeat_for_ = 0.1;                          // s a rollout command is repeated (command_mutex_)
  std::atomic<int> stalls_{0};
  std::thread keep_alive_;
};

class DriverRollouts : public RolloutBackend {
 public:
  // model: the task scene's MJCF (qpos layout for resets, joint ranges); namespaces: one per
  // driver. Throws std::runtime_error when a driver does not answer or runs another robot.
  DriverRollouts(ros::NodeHandle& nh, const std::vector<std::string>& namespaces, ModelPtr model, double timeout,
                 Pacing pacing);
  std::string name() const override { return "driver"; }
  std::vector<std::string> jointNames() const override { return joints_; }
  std::vector<std::string> cylinderNames() const override { return cylinders_; }
  bool hasObject() const override { return has_object_; }
  std::vector<std::string> touchNames() const override { return touch_; }
  std::vector<double> jointRanges() const override;
  ObjectGeometry objectGeometry() const override;
  Eigen::VectorXd initialState(const TrainingTask& task, const StateLayout& layout) override;
  std::vector<RolloutResult> run(const TrainingTask& task, const StateLayout& layout, const LgController& controller,
                                 const std::vector<RolloutRequest>& requests, const std::atomic<bool>& cancel) override;
  std::vector<RolloutResult> runPolicy(const TrainingTask& task, const StateLayout& layout,
                                       const PolicyFactory& make_policy, const std::vector<RolloutRequest>& requests,
                                       int steps, const std::atomic<bool>& cancel) override;

 private:
  // Driver k runs requests k, k + K, ... on its own thread: rollout(driver, request) -> result.
  template <class Rollout>
  std::vector<RolloutResult> runOnDrivers(const std::vector<RolloutRequest>& requests, Rollout&& rollout);
  // One rollout on `driver` with `act` (runControlLoop), after its reset.
  template <class Act>
  RolloutResult runOne(DriverConnection& driver, const TrainingTask& task, const StateLayout& layout,
                       const RolloutRequest& request, int steps, Act&& act, const std::atomic<bool>& cancel);
  ModelPtr model_;
  std::vector<std::unique_ptr<DriverConnection>> drivers_;
  std::vector<std::string> joints_, cylinders_, touch_;
  bool has_object_ = false;
};

}  // namespace adroit::learning_node
