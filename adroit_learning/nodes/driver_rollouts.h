// Rollout backend (a): rollouts through live simulation drivers over ROS, in lockstep. For
// each control step the backend reads the driver's published state, evaluates the controller
// next to the driver, publishes the valve command stamped with a fresh stamp, and asks
// `step` for one control step's physics steps that start only once that command has arrived
// (Step.srv's command_stamp). Resets go through `reset` (qpos in model order, pressures).
//
// Several drivers (backend (c): other machines under one master, each in its own namespace)
// run the requests in parallel, one connection per driver. The driver's safe state is never
// released here: a rollout that meets it fails and says so.
#pragma once
#include <adroit_core/mujoco_model.h>
#include <adroit_learning/rollout_backend.h>
#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ValveCommand.h>
#include <mujoco/mujoco.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>

#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace adroit::learning_node {

// One driver: its topics and services under `ns` (e.g. /adroit).
class DriverConnection {
 public:
  DriverConnection(ros::NodeHandle& nh, const std::string& ns, double timeout);
  const std::string& ns() const { return ns_; }
  // Waits (up to the timeout) until the driver has published joint and actuator states.
  bool waitForStreams(std::string& error);
  // Whether the driver publishes object odometry (waits up to 1 s for the connection).
  bool publishesObject();
  std::vector<std::string> jointNames();
  std::vector<std::string> cylinderNames();
  // Pause (lockstep stepping needs it), reset to qpos/pressure, then two physics steps with
  // every valve at `hold_volts` so every sensor stream reports the reset state.
  bool reset(const std::vector<double>& qpos, const std::vector<double>& pressure, double hold_volts,
             std::string& error);
  // The newest observation stamped at or after `since` (waits up to the timeout).
  bool observe(const ros::Time& since, Observation& obs, std::string& error);
  bool send(const std::vector<double>& volts, std::string& error);
  // Steps `steps` physics steps once the last sent command has arrived.
  bool step(int steps, std::string& error);
  const ros::Time& simTime() const { return sim_time_; }

 private:
  void onJoints(const sensor_msgs::JointState::ConstPtr& msg);
  void onActuators(const adroit_msgs::ActuatorStates::ConstPtr& msg);
  void onOdometry(const nav_msgs::Odometry::ConstPtr& msg);
  void onSafeState(const std_msgs::Bool::ConstPtr& msg);
  bool safe(std::string& error);

  std::string ns_;
  double timeout_;
  ros::Subscriber joints_sub_, actuators_sub_, odom_sub_, safe_sub_;
  ros::Publisher valve_pub_;
  ros::ServiceClient step_client_, reset_client_, pause_client_;
  std::mutex mutex_;
  std::condition_variable cv_;
  sensor_msgs::JointState::ConstPtr joints_;
  adroit_msgs::ActuatorStates::ConstPtr actuators_;
  nav_msgs::Odometry::ConstPtr odom_;
  bool safe_state_ = false;
  ros::Time sim_time_, last_stamp_, reset_floor_;
  adroit_msgs::ValveCommand command_;
};

class DriverRollouts : public RolloutBackend {
 public:
  // model: the task scene's MJCF (qpos layout for resets, joint ranges); namespaces: one per
  // driver. Throws std::runtime_error when a driver does not answer or runs another robot.
  DriverRollouts(ros::NodeHandle& nh, const std::vector<std::string>& namespaces, ModelPtr model, double timeout);
  std::string name() const override { return "driver"; }
  std::vector<std::string> jointNames() const override { return joints_; }
  std::vector<std::string> cylinderNames() const override { return cylinders_; }
  bool hasObject() const override { return has_object_; }
  std::vector<double> jointRanges() const override;
  Eigen::VectorXd initialState(const TrainingTask& task, const StateLayout& layout) override;
  std::vector<RolloutResult> run(const TrainingTask& task, const StateLayout& layout, const LgController& controller,
                                 const std::vector<RolloutRequest>& requests, const std::atomic<bool>& cancel) override;

 private:
  RolloutResult runOne(DriverConnection& driver, const TrainingTask& task, const StateLayout& layout,
                       const LgController& controller, const RolloutRequest& request, const std::atomic<bool>& cancel);
  ModelPtr model_;
  std::vector<std::unique_ptr<DriverConnection>> drivers_;
  std::vector<std::string> joints_, cylinders_;
  bool has_object_ = false;
};

}  // namespace adroit::learning_node
