// Set-up of the driver: the topics and services on their callback queues, and the threads.
#include "robot_driver.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <rosgraph_msgs/Clock.h>

#include <cstdio>

#include "adroit_core/scheduling.h"

namespace adroit::driver {

RobotDriver::RobotDriver(ros::NodeHandle nh, DriverParams params, std::unique_ptr<Robot> robot, std::string name)
    : params_(std::move(params)),
      robot_(std::move(robot)),
      name_str_(std::move(name)),
      name_(name_str_.c_str()),
      nh_(nh),
      io_(nh, "adroit") {
  const double dt = robot_->timestep();
  // An input-driven robot publishes each sample when it arrives: the rates do not apply.
  if (!robot_->drivenByInput()) {
    joint_every_ = stepsPerPublication("joint_state_rate", params_.joint_state_rate, dt);
    actuator_every_ = stepsPerPublication("actuator_state_rate", params_.actuator_state_rate, dt);
    touch_every_ = stepsPerPublication("touch_rate", params_.touch_rate, dt);
    object_every_ = stepsPerPublication("object_rate", params_.object_rate, dt);
  }
  paused_ = params_.start_paused;
  // Stamps are wall_offset_ + clock(): the robot's clock may have started before this wrapper.
  wall_offset_ = ros::WallTime::now().toSec() - (robot_->drivenByInput() ? robot_->clock() : 0.0);
  released_wall_ = wall_offset_;

  // Everything the threads reuse is sized here, once.
  marker_data_ = copyData(robot_->model(), robot_->data());
  marker_truth_ = robot_->truth();
  commanded_snapshot_.assign(robot_->cylinders().size(), 0);
  for (StepTiming* t : {&timing_, &timing_spare_}) {
    t->step_time.reserve(kTimingCapacity);
    t->lateness.reserve(kTimingCapacity);
  }
  for (Batch& b : ring_) {
    b.signals = robot_->sensed();
    b.command = robot_->appliedCommand();
  }
  joint_msg_.name = robot_->jointNames();
  actuator_msg_.name = robot_->cylinderNames();
  touch_msg_.name = robot_->touchNames();
  odom_msg_.header.frame_id = "world";
  odom_msg_.child_frame_id = "object";
  base_tf_.header.frame_id = "world";
  base_tf_.child_frame_id = robot_->baseFrame();

  joint_pub_ = io_.advertise<sensor_msgs::JointState>("joint_states", 10);
  actuator_pub_ = io_.advertise<adroit_msgs::ActuatorStates>("actuator_states", 10);
  touch_pub_ = io_.advertise<adroit_msgs::Touch>("touch", 10);
  if (robot_->hasObject()) odom_pub_ = io_.advertise<nav_msgs::Odometry>("object/odom", 10);
  diag_pub_ = io_.advertise<diagnostic_msgs::DiagnosticArray>("diagnostics", 5);
  safe_pub_ = io_.advertise<std_msgs::Bool>("safe_state", 1, true);
  marker_pub_ = io_.advertise<visualization_msgs::MarkerArray>("markers", 2);
  latency_pub_ = io_.advertise<adroit_msgs::CommandLatency>("command_latency", 50);
  if (robot_->hasFreeBase())  // teleop scenes: a motion-capture stream moves the hand's base
    base_sub_ = io_.subscribe("hand_base/target", 10, &RobotDriver::onBaseTarget, this,
                              ros::TransportHints().tcpNoDelay());
  if (params_.use_sim_time) clock_pub_ = nh_.advertise<rosgraph_msgs::Clock>("/clock", 10);
  tf_ = std::make_unique<tf2_ros::TransformBroadcaster>();

  // The safety path: its own queue and thread (started in start()).
  safety_io_ = ros::NodeHandle(nh_, "adroit");
  safety_io_.setCallbackQueue(safety_queue_.queue());
  const auto hints = ros::TransportHints().tcpNoDelay();
  valve_sub_ = safety_io_.subscribe("valve_command", 10, &RobotDriver::onValveCommand, this, hints);
  force_sub_ = safety_io_.subscribe("tendon_force_command", 10, &RobotDriver::onForceCommand, this, hints);
  estop_input_sub_ = safety_io_.subscribe("estop_input", 10, &RobotDriver::onEstopInput, this, hints);
  services_.push_back(safety_io_.advertiseService("estop", &RobotDriver::onEstop, this));
  services_.push_back(safety_io_.advertiseService("estop_release", &RobotDriver::onRelease, this));
  services_.push_back(safety_io_.advertiseService("pause", &RobotDriver::onPause, this));
  services_.push_back(safety_io_.advertiseService("recover", &RobotDriver::onRecover, this));
  monitor_timer_ = safety_io_.createWallTimer(ros::WallDuration(0.05), &RobotDriver::onSafetyMonitor, this);
  // The rest on the caller's queue (the node spins it with two threads, so a long /step
  // does not hold up diagnostics).
  services_.push_back(io_.advertiseService("reset", &RobotDriver::onReset, this));
  services_.push_back(io_.advertiseService("set_object_pose", &RobotDriver::onSetObjectPose, this));
  services_.push_back(io_.advertiseService("step", &RobotDriver::onStep, this));
  diag_timer_ = nh_.createWallTimer(ros::WallDuration(params_.diagnostics_period), &RobotDriver::onDiagnostics, this);
  publishSafeStateIfChanged();

  ROS_INFO("%s: %s, %s mode, %zu cylinders, %zu joints, dt %.4f s, %s%s", name_, robot_->modelPath().c_str(),
           modeName(robot_->mode()), robot_->cylinders().size(), robot_->jointNames().size(), dt,
           robot_->drivenByInput() ? "driven by its input" : (params_.realtime ? "real time" : "lockstep"),
           params_.use_sim_time ? " with /clock" : "");
}

RobotDriver::~RobotDriver() { stop(); }

int runDriverNode(int argc, char** argv, const char* name, DriverFactory make) {
  ros::init(argc, argv, name);
  rosutil::startRos();  // roscpp's threads known, for start() to put them under SCHED_FIFO
  std::unique_ptr<RobotDriver> driver;
  try {
    driver = make(ros::NodeHandle(), ros::NodeHandle("~"));
  } catch (const std::exception& e) {
    // One line on stderr (rosconsole prints nothing before the node has started).
    std::fprintf(stderr, "[FATAL] %s: %s\n", name, e.what());
    return 1;
  }
  driver->start();
  ros::MultiThreadedSpinner spinner(2);
  spinner.spin();
  driver->stop();
  return 0;
}

void RobotDriver::start() {
  if (running_.exchange(true)) return;
  {
    std::lock_guard<std::mutex> lock(publish_mutex_);
    publisher_running_ = true;
  }
  publisher_ = std::thread(&RobotDriver::publishLoop, this);
  thread_ = std::thread(robot_->drivenByInput() ? &RobotDriver::inputLoop : &RobotDriver::loop, this);
  // Real time: the commands' whole path under SCHED_FIFO (adroit_ros/realtime.h), roscpp's
  // socket thread that receives them just below the safety queue that applies them, so a busy
  // machine cannot hold commands back until the watchdog trips.
  safety_queue_.start(params_.realtime && params_.realtime_priority > 2 ? params_.realtime_priority - 2 : 0);
  if (params_.realtime && params_.realtime_priority > 3) {
    std::string error;
    if (rosutil::fifoRosThreads(params_.realtime_priority - 3, &error))
      transport_fifo_priority_ = params_.realtime_priority - 3;
    else
      ROS_WARN("%s: roscpp's threads keep normal scheduling (%s): on a busy machine commands may reach the "
               "safety queue late", name_, error.c_str());
  }
}

void RobotDriver::stop() {
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
  safety_queue_.stop();
}

ros::Time RobotDriver::stamp() const {
  // Sim time: the driver's monotonic clock is the ROS clock. Wall time: the wall time the
  // real-time schedule assigns to this state (regular, unlike the publication instant).
  return params_.use_sim_time ? ros::Time(robot_->clock()) : ros::Time(wall_offset_ + robot_->clock());
}

std::vector<double> RobotDriver::takeJointIntervals() {
  std::lock_guard<std::mutex> lock(intervals_mutex_);
  std::vector<double> out;
  out.swap(joint_intervals_);
  return out;
}

}  // namespace adroit::driver
