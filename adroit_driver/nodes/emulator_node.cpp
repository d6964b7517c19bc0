// adroit_can_emulator: the robot's electronics (palm MCU, valve boards, sensor boards) on
// emulated CAN buses, played from the simulation (HardwareEmulator), so that the hardware
// driver adroit_hw runs unchanged without the robot. A thin wrapper: parameters, the
// ~inject_fault service, what the real robot's lab would also provide (the object's
// motion-capture pose), the joint values sent for tests, and diagnostics.
#include <ros/ros.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <map>
#include <set>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <diagnostic_msgs/DiagnosticStatus.h>
#include <geometry_msgs/TransformStamped.h>
#include <mujoco/mujoco.h>
#include <nav_msgs/Odometry.h>
#include <sensor_msgs/JointState.h>
#include <tf2_ros/transform_broadcaster.h>

#include "adroit_driver/can_calibration.h"
#include "adroit_driver/hardware_emulator.h"
#include "adroit_msgs/InjectFault.h"
#include "adroit_msgs/SetObjectPose.h"
#include "adroit_ros/diagnostics.h"
#include "adroit_ros/params.h"
#include "object_odometry.h"

namespace adroit::driver {
namespace {

using rosutil::ParameterError;
constexpr const char* kName = "adroit_can_emulator";
constexpr std::size_t kMaxSocketPath = 107;  // sockaddr_un::sun_path minus the terminating zero

// Every key this node reads (readConfig, readBusPaths, the calibration in EmulatorNode;
// modelPath: scene, model_file); keep in step with them.
const std::set<std::string> kEmulatorKeys{"scene", "model_file", "initial_keyframe", "sensor_realism", "seed",
                                          "drop_probability", "corrupt_probability", "delay", "realtime_priority",
                                          "buses", "calibration"};

can::EmulatorConfig readConfig(const rosutil::Params& p) {
  p.checkKeys("", kEmulatorKeys);  // a misspelt key would silently run at its default
  can::EmulatorConfig c;
  c.sim.model_path = p.modelPath("arm_hand");
  c.sim.initial_keyframe = p.string("initial_keyframe", c.sim.initial_keyframe);
  c.sim.sensors.enabled = p.boolean("sensor_realism", c.sim.sensors.enabled);
  const int seed = p.integer("seed", static_cast<int>(c.seed), 0, 2147483647);
  c.sim.sensors.seed = static_cast<std::uint64_t>(seed);
  c.seed = static_cast<std::uint64_t>(seed);
  c.faults.drop_probability = p.number("drop_probability", 0.0, 0, 1);
  c.faults.corrupt_probability = p.number("corrupt_probability", 0.0, 0, 1);
  c.faults.delay = p.number("delay", 0.0, 0, can::kMaxInjectedDelay);
  c.realtime_priority = p.integer("realtime_priority", 30, 0, 98);
  const std::string invalid = validate(c.sim);
  if (!invalid.empty()) throw ParameterError("bad parameter " + invalid);
  return c;
}

// ~buses: {palm: "unix:/tmp/adroit_can_palm", act0: ...}; every bus of the layout has a default.
std::vector<std::string> readBusPaths(const rosutil::Params& p, const std::vector<std::string>& buses) {
  p.checkKeys("buses", std::set<std::string>(buses.begin(), buses.end()));
  const std::string prefix = "unix:";
  std::vector<std::string> paths;
  for (const auto& bus : buses) {
    const std::string key = "buses/" + bus;
    const std::string spec = p.string(key, prefix + can::defaultBusPath(bus));
    if (spec.compare(0, prefix.size(), prefix) != 0)
      p.fail(key, "must be an emulator endpoint \"unix:<path>\" (the emulator cannot drive a SocketCAN "
                  "interface), got '" + spec + "'");
    const std::string path = spec.substr(prefix.size());
    if (path.empty() || path.size() > kMaxSocketPath)
      p.fail(key, "the socket path must have 1 to " + std::to_string(kMaxSocketPath) + " characters");
    if (std::find(paths.begin(), paths.end(), path) != paths.end()) p.fail(key, "'" + path + "' is used by two buses");
    paths.push_back(path);
  }
  return paths;
}


std::string flagsText(std::uint8_t flags) {
  std::string t;
  if (flags & can::kFlagEstopInput) t += " estop_input";
  if (flags & can::kFlagWatchdog) t += " watchdog";
  if (flags & can::kFlagSupplyOpen) t += " supply_open";
  return t;
}

class EmulatorNode {
 public:
  EmulatorNode(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), pnh_(pnh) {
    const rosutil::Params p(pnh_);
    const can::EmulatorConfig config = readConfig(p);
    try {
      emulator_ = std::make_unique<can::HardwareEmulator>(config);
    } catch (const std::invalid_argument& e) {  // the simulation names its parameter (~initial_keyframe ...)
      throw ParameterError(std::string("bad parameter ") + e.what());
    }
    emulator_->setBusPaths(readBusPaths(p, emulator_->mapping().buses));
    const std::string calibration = p.string("calibration", "");
    if (!calibration.empty()) {
      try {
        emulator_->setCalibration(
            can::loadCalibration(calibration, emulator_->jointNames(), emulator_->cylinderNames()));
      } catch (const std::invalid_argument& e) {
        p.fail("calibration", e.what());
      }
    }
    calibration_ = calibration.empty() ? "identity" : calibration;

    truth_msg_.name = emulator_->jointNames();
    truth_pub_ = pnh_.advertise<sensor_msgs::JointState>("truth/joint_states", 10);
    diag_pub_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 5);
    if (emulator_->hasObject()) {
      odom_pub_ = nh_.advertise<nav_msgs::Odometry>("/adroit/object/odom", 10);
      odom_msg_.header.frame_id = "world";
      odom_msg_.child_frame_id = "object";
      tf_ = std::make_unique<tf2_ros::TransformBroadcaster>();
      place_srv_ = pnh_.advertiseService("set_object_pose", &EmulatorNode::onPlaceObject, this);
    }
    inject_srv_ = pnh_.advertiseService("inject_fault", &EmulatorNode::onInjectFault, this);
  }

  // Listens on the buses (std::runtime_error when a path is taken) and starts publishing.
  void start() {
    emulator_->start();
    std::string buses;
    const auto& names = emulator_->mapping().buses;
    for (std::size_t b = 0; b < names.size(); ++b) buses += " " + names[b] + "=unix:" + emulator_->busPaths()[b];
    ROS_INFO("%s: %zu joints, %zu cylinders, calibration %s; buses:%s", kName, emulator_->jointNames().size(),
             emulator_->cylinderNames().size(), calibration_.c_str(), buses.c_str());
    for (int i = 0; i < 100 && emulator_->realtimeScheduling() == 0; ++i) ros::WallDuration(0.001).sleep();
    if (emulator_->realtimeScheduling() < 0)
      ROS_WARN("%s: ~realtime_priority: SCHED_FIFO not permitted; the boards' streams keep their rates only on an "
               "idle machine (the driver faults a stream 3 periods late)", kName);
    truth_timer_ = nh_.createWallTimer(ros::WallDuration(0.01), &EmulatorNode::publishTruth, this);
    if (emulator_->hasObject())
      object_timer_ = nh_.createWallTimer(ros::WallDuration(0.004), &EmulatorNode::publishObject, this);
    diag_timer_ = nh_.createWallTimer(ros::WallDuration(1.0), &EmulatorNode::publishDiagnostics, this);
  }

  void stop() {
    truth_timer_.stop();
    object_timer_.stop();
    diag_timer_.stop();
    emulator_->stop();  // closes the connections, removes the socket files
  }

 private:
  bool onInjectFault(adroit_msgs::InjectFault::Request& req, adroit_msgs::InjectFault::Response& res) {
    res.success = emulator_->inject(req.fault, req.target, req.value, &res.message);
    if (res.success)
      ROS_WARN("%s: inject_fault %s: %s", kName, req.fault.c_str(), res.message.c_str());
    else
      ROS_ERROR("%s: inject_fault refused: %s", kName, res.message.c_str());
    return true;
  }

  // A person in the lab putting the object somewhere (the driver's /adroit/set_object_pose is
  // the simulation's: on a robot it refuses). Same request, same checks.
  bool onPlaceObject(adroit_msgs::SetObjectPose::Request& req, adroit_msgs::SetObjectPose::Response& res) {
    const auto& p = req.pose.position;
    const auto& q = req.pose.orientation;
    const auto& l = req.twist.linear;
    const auto& a = req.twist.angular;
    std::string error;
    res.success = emulator_->placeObject({p.x, p.y, p.z}, {q.w, q.x, q.y, q.z}, {l.x, l.y, l.z}, {a.x, a.y, a.z}, &error);
    res.message = res.success ? "object placed" : error;
    if (!res.success) ROS_WARN("%s: set_object_pose refused: %s", kName, error.c_str());
    return true;
  }

  // The joint values the palm last sent, in physical units: what the driver should report.
  void publishTruth(const ros::WallTimerEvent&) {
    const can::EmulatorSnapshot s = emulator_->snapshot();
    if (s.steps == 0) return;
    truth_msg_.header.stamp = ros::Time::now();
    truth_msg_.position = s.joint;
    truth_pub_.publish(truth_msg_);
  }

  // What the lab's motion-capture system would publish for the object on the real robot.
  void publishObject(const ros::WallTimerEvent&) {
    const can::EmulatorSnapshot s = emulator_->snapshot();
    if (s.steps == 0) return;
    odom_msg_.header.stamp = ros::Time::now();
    geometry_msgs::TransformStamped t;
    fillObjectOdometry(s.object, &odom_msg_, &t);
    odom_pub_.publish(odom_msg_);
    tf_->sendTransform(t);
  }

  void publishDiagnostics(const ros::WallTimerEvent&) {
    const can::EmulatorSnapshot s = emulator_->snapshot();
    rosutil::StatusBuilder d(kName, kName);
    d.add("clock", s.clock);
    d.add("steps", s.steps);
    d.add("overruns", s.overruns);
    d.add("supply_open", s.supply_open);
    d.add("calibration", calibration_);
    std::string waiting;
    for (const auto& b : s.buses) {
      d.add(b.name + "/endpoint", "unix:" + b.path);
      d.add(b.name + "/host", b.bus_off     ? "bus-off (until it reconnects)"
                              : b.connected ? "connected"
                                            : "not connected");
      d.add(b.name + "/connections", b.connections);
      d.add(b.name + "/frames_sent", b.frames_sent);
      d.add(b.name + "/frames_received", b.frames_received);
      d.add(b.name + "/bad_frames", b.bad_frames);
      d.add(b.name + "/bad_datagrams", b.bad_datagrams);
      d.add(b.name + "/write_full", b.write_full);
      d.add(b.name + "/dropped", b.dropped);
      d.add(b.name + "/corrupted", b.corrupted);
      d.add(b.name + "/delayed", b.delayed + b.delay_overflow);
      if (!b.connected) waiting += " " + b.name;
    }
    const auto board = [&d](const std::string& name, const can::BoardStatus& b) {
      d.add(name, std::string(can::nodeStateName(b.state)) + flagsText(b.flags) + ", faults sent " +
                      std::to_string(b.faults_sent));
    };
    board("palm", s.palm);
    bool fault = false;
    std::uint64_t trips = 0;
    for (const auto& b : s.valve_boards) {
      board("valve board " + std::to_string(b.node - can::kValveBoardNodeBase), b);
      fault |= b.state == can::NodeState::kFault;
      trips += b.watchdog_trips;
    }
    for (const auto& b : s.sensor_boards)
      board("sensor board " + std::to_string(b.node - can::kSensorBoardNodeBase), b);
    d.add("watchdog_trips", trips);
    std::string injections;
    for (const auto& i : s.injections) injections += (injections.empty() ? "" : "; ") + i;
    d.add("injections", injections.empty() ? "none" : injections);
    if (fault) d.raise(diagnostic_msgs::DiagnosticStatus::ERROR, "a valve board is in the fault state");
    if (!injections.empty()) d.raise(diagnostic_msgs::DiagnosticStatus::WARN, "fault injection active: " + injections);
    if (!waiting.empty()) d.raise(diagnostic_msgs::DiagnosticStatus::WARN, "no host connected on" + waiting);
    d.raise(diagnostic_msgs::DiagnosticStatus::OK, "emulating");
    d.publish(diag_pub_);
  }

  ros::NodeHandle nh_, pnh_;
  std::unique_ptr<can::HardwareEmulator> emulator_;
  std::string calibration_;
  ros::Publisher truth_pub_, odom_pub_, diag_pub_;
  ros::ServiceServer inject_srv_, place_srv_;
  ros::WallTimer truth_timer_, object_timer_, diag_timer_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_;
  sensor_msgs::JointState truth_msg_;
  nav_msgs::Odometry odom_msg_;
};

}  // namespace
}  // namespace adroit::driver

int main(int argc, char** argv) {
  using adroit::driver::kName;
  ros::init(argc, argv, kName);
  // SIGTERM too: shut down through ros::spin() so that the socket files are removed.
  std::signal(SIGTERM, [](int) { ros::requestShutdown(); });
  std::unique_ptr<adroit::driver::EmulatorNode> node;
  try {
    node = std::make_unique<adroit::driver::EmulatorNode>(ros::NodeHandle(), ros::NodeHandle("~"));
    node->start();
  } catch (const std::exception& e) {
    // One line on stderr (rosconsole prints nothing before the node has started).
    std::fprintf(stderr, "[FATAL] %s: %s\n", kName, e.what());
    return 1;
  }
  ros::spin();
  node->stop();
  return 0;
}
