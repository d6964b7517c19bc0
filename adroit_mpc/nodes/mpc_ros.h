// ROS wrapper of the behaviour MPC (adroit_mpc node). One file per job:
//   mpc_params.cpp    ~parameters -> MpcParams (one-line errors naming the parameter)
//   mpc_state.cpp     /adroit/joint_states + /adroit/object/odom -> planning-model state
//   mpc_ros.cpp       set-up, the planner thread, the 200 Hz control thread, lockstep loop
//   mpc_services.cpp  set_task, release, goal (topic and interactive marker), type, reconfigure
//   mpc_markers.cpp   rviz markers of the plan, diagnostics
//
// Threads:
//  * state queue (1 spinner): joint states and odometry, validated and copied into the state
//    store (a few hundred numbers under state_mutex_);
//  * default queue (1 spinner): services, goal topics, reconfigure, markers, diagnostics;
//  * planner thread: latest state -> the runner's MPC side (adroit_mpc/mpc_runner.h: observe /
//    setTask under its task mutex, optional latency compensation, optimize, a good policy
//    published lock-free);
//  * control thread: at control_rate the runner's control side evaluates the newest policy on
//    the newest state: tendon forces (force mode) or the force reference for the pools
//    (pneumatic mode); it never waits for the optimiser;
//  * lockstep (tests, benchmarks): one thread optimises, then steps the paused driver one
//    control period at a time through /adroit/step, so closed-loop runs are deterministic.
#pragma once

#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <adroit_msgs/ForceReference.h>
#include <adroit_msgs/SetTask.h>
#include <adroit_msgs/TendonForceCommand.h>
#include <dynamic_reconfigure/server.h>
#include <geometry_msgs/PoseStamped.h>
#include <interactive_markers/interactive_marker_server.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/String.h>
#include <std_srvs/Trigger.h>
#include <visualization_msgs/MarkerArray.h>

#include "adroit_core/model_tables.h"
#include "adroit_core/mujoco_model.h"
#include "adroit_core/pi_mutex.h"
#include "adroit_mpc/MpcConfig.h"
#include "adroit_mpc/mpc_runner.h"
#include "adroit_mpc/planner.h"
#include "adroit_mpc/task.h"
#include "adroit_ros/diagnostics.h"
#include "adroit_ros/params.h"
#include "adroit_ros/realtime.h"

namespace adroit::mpc_node {

using rosutil::ParameterError;

// Everything the node reads from its private parameters (defaults: config/mpc.yaml).
struct MpcParams {
  std::string scene;       // adroit_description scene (planning variant is loaded)
  std::string model_file;  // resolved planning model path
  std::string task;        // active task at start
  std::string planner;     // ilqg | sampling
  bool force_mode = true;  // false: pneumatic (force references to the pools)
  adroit_mpc::PlannerSettings settings;
  double control_rate = 200;       // Hz
  double state_timeout = 0.1;      // s of wall time without a joint state: stop publishing
  double feedback_scale = 1.0;     // of the policy's gains at the control rate
  // Plan from the state the running policy is predicted to reach when the new plan takes
  // over (adroit_mpc/latency_compensation.h); default: the start task's hint.
  bool latency_compensation = false;
  double marker_rate = 5;          // wall Hz, only while someone listens
  double diagnostics_period = 1.0;  // wall s
  // Nice value of the optimiser (the planner thread and its workers; the control loop runs
  // under SCHED_FIFO at control_priority, roscpp's threads at normal weight).
  int nice = 19;
  int control_priority = 10;  // below the pools' (15) and the driver's (20)
  // Lockstep: drive a paused simulation through /adroit/step.
  bool lockstep = false;
  double physics_timestep = 0.002;  // s, the driver's step
  int lockstep_controls_per_plan = 4;  // control periods stepped between two optimisations
  double min_tension = 0.3;             // N, the planning model's lower tendon force (PlanningModelSettings)
  std::map<std::string, adroit_mpc::TaskParams> tasks;  // ~tasks/<name>/...
};

// Throws ParameterError with one line naming the parameter.
MpcParams readParams(const ros::NodeHandle& pnh);

// The planning model's state assembled from the driver's topics.
struct StateSnapshot {
  double time = 0;  // node time (s since the node's time origin) of the joint state
  double object_time = -1;  // node time of the object odometry (-1: none yet or no object)
  std::vector<double> qpos, qvel, act;
  std::uint64_t serial = 0;  // joint states accepted so far
};

class MpcNode {
 public:
  // Throws ParameterError (or std::exception) with one line to report.
  MpcNode(ros::NodeHandle nh, ros::NodeHandle pnh);
  ~MpcNode();
  void start();
  void stop();

 private:
  using Config = adroit_mpc::MpcConfig;
  enum Reject : std::size_t {
    kJointLength,
    kJointNonFinite,
    kJointMissing,
    kOdomNonFinite,
    kOdomQuaternion,
    kOdomFrame,
    kGoal,
    kTaskName,
    kTaskCommand,
    kRejectCount
  };

  // --- state input (mpc_state.cpp, state queue) ---
  void onJointState(const sensor_msgs::JointState::ConstPtr& msg);
  void onOdometry(const nav_msgs::Odometry::ConstPtr& msg);
  bool rebuildJointMap(const std::vector<std::string>& names);
  // Copies the newest complete state; false before the first one.
  bool latestState(StateSnapshot& out);
  double nodeTime(const ros::Time& stamp) const { return (stamp - time_origin_).toSec(); }
  ros::Time rosTime(double node_time) const { return time_origin_ + ros::Duration(node_time); }
  double stateAgeWall() const;  // wall s since the last accepted joint state (inf: none)

  // --- planning and control (mpc_ros.cpp) ---
  adroit_mpc::RunnerSettings runnerSettings();  // real time on the node's clock, the ~parameters
  void enterOptimiserThread();  // ~nice for this thread, then the planner (re)started from it
  void plannerLoop();
  void controlLoop();
  void lockstepLoop();
  // One optimisation on `state` (the runner's MPC side); true when a new policy was published.
  bool planOnce(const StateSnapshot& state);
  // The current policy on `state` at time t: tendon forces (force mode) or the force
  // reference over the rest of its horizon for the pools (pneumatic mode). False when
  // nothing was sent (policy older than its horizon, or not finite).
  bool sendCommand(double t, const StateSnapshot& state);
  bool sendForces(double t, const StateSnapshot& state);
  bool sendPolicyReference(double t, const StateSnapshot& state);
  // command_time >= 0: the driver steps once the command stamped then has arrived.
  bool callStep(std::uint32_t steps, double command_time, double* sim_time);
  bool waitForState(double sim_time, StateSnapshot& out);
  void publishEvents(const std::vector<adroit_mpc::TaskEvent>& events);

  // --- commands (mpc_services.cpp, default queue) ---
  bool onSetTask(adroit_msgs::SetTask::Request& req, adroit_msgs::SetTask::Response& res);
  bool onRelease(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void onGoal(const geometry_msgs::PoseStamped::ConstPtr& msg);
  void onType(const std_msgs::String::ConstPtr& msg);
  void onReconfigure(Config& config, uint32_t level);
  bool applyGoal(const geometry_msgs::Pose& pose, const std::string& frame, std::string* why);
  // A new bound task of that name, or nullptr and *why.
  std::unique_ptr<adroit_mpc::Task> buildTask(const std::string& name, std::string* why) const;
  void setupGoalMarker();
  void onGoalMarker(const visualization_msgs::InteractiveMarkerFeedbackConstPtr& feedback);
  void syncReconfigure();  // the live task's weights and the horizon into the server

  // --- markers and diagnostics (mpc_markers.cpp, default queue) ---
  void takeMarkerSnapshot();  // planner thread, try-lock
  void onMarkerTimer(const ros::WallTimerEvent& event);
  void onDiagnostics(const ros::WallTimerEvent& event);

  MpcParams params_;
  ros::NodeHandle nh_, pnh_;
  // The driver's states on a thread of their own under SCHED_FIFO (above the control loop):
  // marker building, a service or the optimiser never delays them.
  rosutil::FifoCallbackQueue state_queue_;
  std::unique_ptr<ros::AsyncSpinner> default_spinner_;

  ModelPtr model_;
  std::unique_ptr<ModelTables> tables_;
  int synergy_dims_ = 0;
  int object_qpos_ = -1, object_dof_ = -1;  // free joint object_root, -1 when absent
  std::vector<std::string> actuator_names_;

  // State store (state_mutex_): written by the state queue, copied by the other threads.
  // Priority inheritance: the optimiser (nice 19) may hold it when the real-time state
  // thread or control loop wants it.
  mutable PiMutex state_mutex_;
  StateSnapshot incoming_;
  bool joints_seen_ = false, object_seen_ = false;
  std::vector<std::string> joint_map_names_;  // names of the message the map was built for
  std::vector<int> joint_map_qpos_, joint_map_dof_;  // per message entry, -1 = not a model joint
  bool joint_map_ok_ = false;
  std::vector<int> hinge_joints_;                    // model hinge/slide joints the stream must cover
  std::atomic<long long> state_wall_ns_{0};          // steady clock of the last joint state, 0 = none
  ros::Time time_origin_;
  bool time_origin_set_ = false;
  std::atomic<std::uint64_t> joint_states_accepted_{0}, odom_accepted_{0};
  rosutil::RejectionCounters rejections_;
  std::string last_rejection_;  // default queue / state queue, logged text (under state_mutex_)

  // The closed loop: planner, live task, policy exchange, latency compensation, statistics.
  // The live task and the members below are changed under runner_->taskMutex().
  std::unique_ptr<adroit_mpc::MpcRunner> runner_;
  std::string task_name_;
  std::optional<geometry_msgs::Pose> goal_;          // last accepted goal (markers)
  StateSnapshot plan_state_;                         // planner thread
  adroit_mpc::PlannerState planner_state_;           // plan_state_ as the runner takes it

  // Control (control thread or lockstep loop).
  StateSnapshot control_state_;
  std::vector<double> ctrl_, reference_values_;
  adroit_msgs::TendonForceCommand force_msg_;
  adroit_msgs::ForceReference reference_msg_;
  ros::Publisher force_pub_, reference_pub_, marker_pub_, diag_pub_, typed_pub_, events_pub_;
  ros::Subscriber joint_sub_, odom_sub_, goal_sub_, type_sub_;
  std::vector<ros::ServiceServer> services_;
  ros::ServiceClient step_client_, pause_client_;
  ros::WallTimer marker_timer_, diag_timer_;
  std::unique_ptr<interactive_markers::InteractiveMarkerServer> goal_server_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<Config>> reconfigure_;
  Config reconfigure_config_;
  bool reconfigure_ready_ = false;

  // Counters of the diagnostics (the runner keeps the planning ones).
  std::atomic<std::uint64_t> commands_sent_{0}, references_sent_{0}, stale_stops_{0}, lockstep_failures_{0};
  std::atomic<bool> publishing_{false};  // control output active (fresh state, a policy)

  // Marker snapshot of the best trajectory (marker_mutex_; the planner only try-locks).
  std::mutex marker_mutex_;
  adroit_mpc::Trajectory marker_plan_;
  bool marker_fresh_ = false;
  std::atomic<bool> markers_wanted_{false};
  DataPtr marker_data_;
  visualization_msgs::MarkerArray marker_msg_;
  std::vector<int> tip_sites_;
  int object_body_ = -1;

  std::atomic<bool> running_{false};
  std::thread planner_thread_, control_thread_;
};

}  // namespace adroit::mpc_node
