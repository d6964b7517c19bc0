// Teleop node (thesis 9.2.3, 10.3): glove records -> calibrated joint targets q_glove ->
// tendon tensions u = k J_tendon (q - q_glove) (TendonMapping) -> the driver, as tendon force
// commands (force mode) or force references for the pools (pneumatic mode).
//
// Each command carries the stamp of the glove record it answers, so the driver's
// /adroit/command_latency measures glove-to-physics latency. Commands also follow the hand's
// own motion: on joint_states, at ~command_rate, with the newest glove target.
//
// Safety: nothing is commanded while the dead-man is released (/adroit_teleop/deadman
// std_msgs/Bool, or /adroit_teleop/enable), or while the glove is stale (no record for
// ~stale_after); the driver's command watchdog then takes the robot to its safe state. After a
// stale glove, commanding resumes only once the dead-man is pressed again; pressing it
// releases the driver's latch only when the watchdog alone latched it (never an e-stop).
//
// Calibration: /adroit_teleop/calibrate (adroit_msgs/Calibrate): start, record (averages the
// glove over ~record_window while the named pose is held), ..., fit (writes the YAML and uses
// it at once).
#include <ros/ros.h>

#include <algorithm>
#include <mutex>
#include <optional>

#include <adroit_msgs/Calibrate.h>
#include <adroit_msgs/ForceReference.h>
#include <adroit_msgs/GloveSensors.h>
#include <adroit_msgs/TendonForceCommand.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>
#include <std_msgs/String.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <yaml-cpp/yaml.h>

#include "adroit_ros/diagnostics.h"
#include "adroit_ros/node_main.h"
#include "adroit_ros/params.h"
#include "adroit_ros/realtime.h"
#include "adroit_core/pi_mutex.h"
#include "adroit_teleop/calibration_session.h"
#include "adroit_teleop/glove_protocol.h"
#include "adroit_teleop/tendon_mapping.h"

namespace adroit::teleop {

namespace {

struct TeleopParams {
  std::string model_path, calibration_path, poses_path, mode, task;
  MappingGains gains;
  double stale_after = 0.1, command_rate = 200.0, record_window = 0.3;
  bool start_enabled = false;
  int realtime_priority = 16;  // SCHED_FIFO of the input queue and roscpp's threads; 0 = normal
};

TeleopParams readParams(const rosutil::Params& p) {
  p.checkKeys("", {"scene", "model_file", "calibration", "poses", "mode", "gains", "stale_after", "command_rate",
                   "record_window", "start_enabled", "task", "realtime_priority"});
  p.checkKeys("gains", {"stiffness", "damping", "min_tension", "scale"});
  TeleopParams t;
  t.model_path = p.modelPath("teleop_tube");
  t.calibration_path = p.string("calibration", "");
  if (t.calibration_path.empty()) p.fail("calibration", "is required: the glove calibration YAML to load");
  t.poses_path = p.string("poses", "");
  t.mode = p.string("mode", "force");
  if (t.mode != "force" && t.mode != "pneumatic") p.fail("mode", "must be force or pneumatic, got '" + t.mode + "'");
  t.gains.stiffness = p.number("gains/stiffness", t.gains.stiffness, 0.0, 1e6);
  t.gains.damping = p.number("gains/damping", t.gains.damping, 0.0, 1e5);
  t.gains.min_tension = p.number("gains/min_tension", t.gains.min_tension, 0.0, 5.0);
  ros::NodeHandle pnh("~");
  std::map<std::string, double> scale;
  if (pnh.hasParam("gains/scale") && !pnh.getParam("gains/scale", scale))
    p.fail("gains/scale", "must map joint-name prefixes to factors, e.g. {WRJ: 2.0}");
  for (const auto& [prefix, factor] : scale)
    if (!(factor >= 0 && factor < 1e3)) p.fail("gains/scale/" + prefix, "must be in [0, 1000)");
  t.gains.scale = scale;
  t.stale_after = p.number("stale_after", t.stale_after, 0.005, 10.0);
  t.command_rate = p.number("command_rate", t.command_rate, 1.0, 1000.0);
  t.record_window = p.number("record_window", t.record_window, 0.02, 10.0);
  t.start_enabled = p.boolean("start_enabled", t.start_enabled);
  t.task = p.string("task", "");  // free text for recorded demonstrations, e.g. "pickup"
  t.realtime_priority = p.integer("realtime_priority", t.realtime_priority, 0, 98);
  return t;
}

// The value of `key` in the driver's diagnostics status, if present.
std::optional<std::string> diagnosticValue(const diagnostic_msgs::DiagnosticStatus& s, const std::string& key) {
  for (const auto& kv : s.values)
    if (kv.key == key) return kv.value;
  return std::nullopt;
}

class TeleopNode {
 public:
  TeleopNode(ros::NodeHandle nh, ros::NodeHandle pnh) : params_(readParams(rosutil::Params(pnh))) {
    try {
      loadCalibrationFile(params_.calibration_path);
    } catch (const CalibrationError& e) {
      throw rosutil::ParameterError("adroit_teleop: bad parameter " + pnh.resolveName("calibration") + ": " + e.what());
    }
    try {
      model_ = loadModelFile(params_.model_path).model;
    } catch (const std::exception& e) {
      throw rosutil::ParameterError("adroit_teleop: cannot load the teleop model: " + std::string(e.what()));
    }
    enabled_ = params_.start_enabled;

    ros::NodeHandle adroit(nh, "adroit"), io(nh, "adroit_teleop");
    const auto hints = ros::TransportHints().tcpNoDelay();
    if (params_.mode == "force")
      force_pub_ = adroit.advertise<adroit_msgs::TendonForceCommand>("tendon_force_command", 10);
    else
      reference_pub_ = adroit.advertise<adroit_msgs::ForceReference>("force_reference", 10);
    target_pub_ = io.advertise<sensor_msgs::JointState>("joint_targets", 20);
    enabled_pub_ = io.advertise<std_msgs::Bool>("enabled", 1, true);
    metadata_pub_ = io.advertise<std_msgs::String>("metadata", 1, true);
    diag_pub_ = adroit.advertise<diagnostic_msgs::DiagnosticArray>("diagnostics", 5);
    ros::NodeHandle glove_input(io), joint_input(adroit);
    glove_input.setCallbackQueue(input_queue_.queue());
    joint_input.setCallbackQueue(input_queue_.queue());
    glove_sub_ = glove_input.subscribe("glove", 20, &TeleopNode::onGlove, this, hints);
    joints_sub_ = joint_input.subscribe("joint_states", 20, &TeleopNode::onJoints, this, hints);
    deadman_sub_ = io.subscribe("deadman", 10, &TeleopNode::onDeadman, this);
    safe_sub_ = adroit.subscribe("safe_state", 1, &TeleopNode::onSafeState, this);
    driver_diag_sub_ = adroit.subscribe("diagnostics", 10, &TeleopNode::onDriverDiagnostics, this);
    release_client_ = adroit.serviceClient<std_srvs::Trigger>("estop_release");
    services_.push_back(io.advertiseService("enable", &TeleopNode::onEnable, this));
    services_.push_back(io.advertiseService("calibrate", &TeleopNode::onCalibrate, this));
    diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), &TeleopNode::onDiagnostics, this);
    publishEnabled();
    publishMetadata();
    input_queue_.start(params_.realtime_priority);
    std::string error;
    if (params_.realtime_priority > 0 && !rosutil::fifoRosThreads(params_.realtime_priority, &error))
      ROS_WARN("adroit_teleop: roscpp's threads keep normal scheduling (%s): on a busy machine glove records may "
               "arrive late", error.c_str());
    ROS_INFO("adroit_teleop: %s mode, calibration %s (%d sensors -> %d joints), model %s, dead-man %s", params_.mode.c_str(),
             params_.calibration_path.c_str(), calibration_.sensors(), calibration_.joints(), params_.model_path.c_str(),
             enabled_ ? "pressed" : "released");
  }

 private:
  // --- glove and joints -> commands --------------------------------------------------------
  void onGlove(const adroit_msgs::GloveSensors::ConstPtr& msg) {
    std::lock_guard<PiMutex> lock(mutex_);
    ++glove_records_;
    if (static_cast<int>(msg->raw.size()) != calibration_.sensors()) {
      ++glove_rejected_;
      ROS_ERROR_THROTTLE(1.0, "adroit_teleop: a glove record of %zu sensors, the calibration has %d", msg->raw.size(),
                         calibration_.sensors());
      return;
    }
    sensors_.resize(calibration_.sensors());
    for (int i = 0; i < calibration_.sensors(); ++i) sensors_(i) = sensorValue(msg->raw[i]);
    if (session_) session_->addReading(sensors_);
    glove_q_.resize(calibration_.joints());
    calibration_.apply(sensors_, glove_q_);
    glove_stamp_ = msg->header.stamp;
    last_glove_wall_ = ros::WallTime::now();
    if (glove_stale_) {
      glove_stale_ = false;
      ROS_INFO("adroit_teleop: glove records again%s", enabled_ ? "" : "; press the dead-man to command");
    }
    publishTargets();
    command();
  }

  void onJoints(const sensor_msgs::JointState::ConstPtr& msg) {
    std::lock_guard<PiMutex> lock(mutex_);
    if (!mapping_ && !buildMapping(*msg)) return;
    if (msg->position.size() != q_.size() || msg->velocity.size() != q_.size()) return;
    q_ = msg->position;
    qdot_ = msg->velocity;
    have_q_ = true;
    // Follow the hand's motion with the newest target, at most at the command rate.
    const ros::WallTime now = ros::WallTime::now();
    if ((now - last_command_wall_).toSec() >= 1.0 / params_.command_rate) command();
  }

  bool buildMapping(const sensor_msgs::JointState& msg) {
    try {
      mapping_.emplace(copyModel(model_.get()), msg.name, params_.gains);
    } catch (const std::exception& e) {
      ROS_ERROR_THROTTLE(5.0, "adroit_teleop: the driver's joints do not fit the teleop model %s: %s (start the driver "
                              "with the same scene)",
                         params_.model_path.c_str(), e.what());
      return false;
    }
    // Each driver joint's calibration row; joints the calibration does not map keep q.
    target_index_.assign(msg.name.size(), -1);
    const auto& names = calibration_.jointNames();
    for (std::size_t j = 0; j < msg.name.size(); ++j) {
      const auto it = std::find(names.begin(), names.end(), msg.name[j]);
      if (it != names.end()) target_index_[j] = static_cast<int>(it - names.begin());
    }
    q_.assign(msg.name.size(), 0.0);
    qdot_ = target_ = q_;
    return true;
  }

  // Commands the robot if the dead-man is pressed, the glove fresh and the hand's state known.
  void command() {
    const ros::WallTime now = ros::WallTime::now();
    // Time this queue itself was held up (a busy machine) does not count against the glove:
    // its records may be waiting in the queue behind the joint state being handled now.
    const double held_up = (now - last_input_wall_).toSec() - kInputGap;
    if (!last_input_wall_.isZero() && held_up > 0) last_glove_wall_ += ros::WallDuration(held_up);
    last_input_wall_ = now;
    const bool fresh = glove_q_.size() > 0 && (now - last_glove_wall_).toSec() <= params_.stale_after;
    if (!fresh && glove_q_.size() > 0 && !glove_stale_) {
      glove_stale_ = true;
      if (enabled_) {
        // The glove went away under the operator's hand: stop, and wait for a new press.
        enabled_ = false;
        publishEnabled();
        ROS_WARN("adroit_teleop: glove stale (no record for %.3f s): commands stopped, the driver's watchdog takes "
                 "over; press the dead-man again once the glove is back",
                 params_.stale_after);
      }
    }
    if (!enabled_ || !fresh || !have_q_ || !mapping_) return;
    for (std::size_t j = 0; j < q_.size(); ++j) target_[j] = target_index_[j] >= 0 ? glove_q_(target_index_[j]) : q_[j];
    if (!mapping_->compute(q_, qdot_, target_, tensions_)) {
      ++commands_refused_;
      return;
    }
    last_command_wall_ = now;
    ++commands_;
    if (force_pub_) {
      force_msg_.header.stamp = glove_stamp_;
      if (force_msg_.name.empty()) force_msg_.name = mapping_->actuatorNames();
      force_msg_.force = tensions_;
      force_pub_.publish(force_msg_);
    } else {
      reference_msg_.header.stamp = glove_stamp_;
      reference_msg_.dt = 1.0 / params_.command_rate;
      reference_msg_.steps = 1;
      if (reference_msg_.name.empty()) reference_msg_.name = mapping_->actuatorNames();
      reference_msg_.force = tensions_;
      reference_pub_.publish(reference_msg_);
    }
  }

  void publishTargets() {
    target_msg_.header.stamp = glove_stamp_;
    if (target_msg_.name.empty()) target_msg_.name = calibration_.jointNames();
    target_msg_.position.assign(glove_q_.data(), glove_q_.data() + glove_q_.size());
    target_pub_.publish(target_msg_);
  }

  // --- dead-man ----------------------------------------------------------------------------
  void onDeadman(const std_msgs::Bool::ConstPtr& msg) {
    std::string message;
    setEnabled(msg->data, message);
  }
  bool onEnable(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res) {
    res.success = setEnabled(req.data, res.message);
    return true;
  }

  bool setEnabled(bool pressed, std::string& message) {
    bool release = false;
    {
      std::lock_guard<PiMutex> lock(mutex_);
      if (pressed == enabled_) {
        message = pressed ? "already commanding" : "already released";
        return true;
      }
      enabled_ = pressed;
      publishEnabled();
      // Only a latch the watchdog alone caused (our commands stopped) is ours to release.
      release = pressed && safe_state_ && watchdog_only_latch_;
    }
    message = pressed ? "commanding" : "released: no commands (the driver's watchdog takes over)";
    ROS_INFO("adroit_teleop: dead-man %s", pressed ? "pressed" : "released");
    if (release) {
      std_srvs::Trigger t;
      if (release_client_.call(t) && t.response.success) {
        message += "; driver watchdog latch released";
      } else {
        message += "; the driver's safe state could not be released: " + t.response.message;
        ROS_WARN("adroit_teleop: %s", message.c_str());
      }
    }
    return true;
  }

  void onSafeState(const std_msgs::Bool::ConstPtr& msg) {
    std::lock_guard<PiMutex> lock(mutex_);
    safe_state_ = msg->data;
  }

  void onDriverDiagnostics(const diagnostic_msgs::DiagnosticArray::ConstPtr& msg) {
    for (const auto& s : msg->status) {
      const auto watchdog = diagnosticValue(s, "watchdog_latched");
      const auto estop = diagnosticValue(s, "estop_latched");
      const auto fault = diagnosticValue(s, "fault_latched");
      if (!watchdog || !estop || !fault) continue;  // not the driver's status
      std::lock_guard<PiMutex> lock(mutex_);
      watchdog_only_latch_ = *watchdog == "true" && *estop == "false" && *fault == "false";
    }
  }

  void publishEnabled() {
    std_msgs::Bool b;
    b.data = enabled_;
    enabled_pub_.publish(b);
  }

  // What a recorded demonstration needs to be understood later (latched, so rosbag gets it).
  // The calibration file, read once (bounded, a regular file only): what runs is what the
  // metadata records. Throws CalibrationError naming the file.
  void loadCalibrationFile(const std::string& path) {
    std::string text = readCalibrationText(path);
    calibration_ = parseCalibration(path, text);
    calibration_text_ = std::move(text);
  }

  void publishMetadata() {
    YAML::Emitter yaml;
    yaml << YAML::BeginMap;
    yaml << YAML::Key << "task" << YAML::Value << params_.task;
    yaml << YAML::Key << "model" << YAML::Value << params_.model_path;
    yaml << YAML::Key << "mode" << YAML::Value << params_.mode;
    yaml << YAML::Key << "calibration" << YAML::Value << params_.calibration_path;
    yaml << YAML::Key << "calibration_created" << YAML::Value << calibration_.created;
    yaml << YAML::Key << "calibration_note" << YAML::Value << calibration_.note;
    yaml << YAML::Key << "sensors" << YAML::Value << calibration_.sensors();
    yaml << YAML::Key << "gains" << YAML::Value << YAML::Flow << YAML::BeginMap;
    yaml << YAML::Key << "stiffness" << YAML::Value << params_.gains.stiffness;
    yaml << YAML::Key << "damping" << YAML::Value << params_.gains.damping;
    yaml << YAML::Key << "min_tension" << YAML::Value << params_.gains.min_tension << YAML::EndMap;
    yaml << YAML::Key << "calibration_file" << YAML::Value << YAML::Literal << calibration_text_;
    yaml << YAML::EndMap;
    std_msgs::String m;
    m.data = yaml.c_str();
    metadata_pub_.publish(m);
  }

  // --- calibration -------------------------------------------------------------------------
  bool onCalibrate(adroit_msgs::Calibrate::Request& req, adroit_msgs::Calibrate::Response& res) {
    try {
      if (req.action == "start") {
        startCalibration(res);
      } else if (req.action == "record") {
        recordPose(res);
      } else if (req.action == "fit") {
        fitAndLoad(req.output.empty() ? params_.calibration_path : req.output, res);
      } else if (req.action == "cancel") {
        std::lock_guard<PiMutex> lock(mutex_);
        session_.reset();
        res.success = true;
        res.message = "calibration cancelled; the previous calibration stays";
      } else {
        res.message = "unknown action '" + req.action + "' (start | record | fit | cancel)";
      }
    } catch (const std::exception& e) {
      res.success = false;
      res.message = e.what();
    }
    if (!res.success) ROS_WARN("adroit_teleop: calibrate %s: %s", req.action.c_str(), res.message.c_str());
    return true;
  }

  void describeNext(adroit_msgs::Calibrate::Response& res) {
    res.remaining = session_->remaining();
    const CalibrationPose* pose = session_->current();
    res.pose = pose ? pose->name : "";
    if (pose) res.message += (res.message.empty() ? "" : "; ") + ("hold '" + pose->name + "': " + pose->instruction + ", then call record");
    else res.message += (res.message.empty() ? "" : "; ") + std::string("every pose recorded: call fit");
  }

  void startCalibration(adroit_msgs::Calibrate::Response& res) {
    if (params_.poses_path.empty()) throw CalibrationError("~poses names no pose file");
    CalibrationPoseSet poses = loadCalibrationPoses(params_.poses_path, jointRangesFromModel(model_.get()));
    std::lock_guard<PiMutex> lock(mutex_);
    session_.emplace(std::move(poses), calibration_.sensors());
    res.success = true;
    res.message = std::to_string(session_->poses().poses.size()) + " poses from " + params_.poses_path;
    describeNext(res);
  }

  void recordPose(adroit_msgs::Calibrate::Response& res) {
    std::string pose;
    {
      std::lock_guard<PiMutex> lock(mutex_);
      if (!session_) throw CalibrationError("no calibration running: call start first");
      if (!session_->current()) throw CalibrationError("every pose is recorded: call fit");
      pose = session_->current()->name;
      session_->clearReadings();  // readings from before the call were taken while moving into the pose
    }
    // The glove callback adds readings meanwhile (other spinner threads).
    ros::WallDuration(params_.record_window).sleep();
    std::lock_guard<PiMutex> lock(mutex_);
    if (!session_) throw CalibrationError("calibration cancelled while recording");
    const std::size_t n = session_->readings();
    session_->record();
    res.success = true;
    res.message = "'" + pose + "' recorded from " + std::to_string(n) + " glove readings";
    describeNext(res);
  }

  void fitAndLoad(const std::string& path, adroit_msgs::Calibrate::Response& res) {
    std::lock_guard<PiMutex> lock(mutex_);
    if (!session_) throw CalibrationError("no calibration running: call start first");
    GloveCalibration fitted = session_->fit();
    char created[32];
    const std::time_t now = std::time(nullptr);
    std::strftime(created, sizeof(created), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
    fitted.created = created;
    fitted.note = "fitted by /adroit_teleop/calibrate on the poses of " + params_.poses_path;
    saveCalibration(path, fitted);
    loadCalibrationFile(path);  // what was written is what runs
    params_.calibration_path = path;
    session_.reset();
    mapping_.reset();  // the joint rows of the new calibration are looked up again
    have_q_ = false;
    glove_q_.resize(0);
    double worst = 0;
    for (int j = 0; j < calibration_.residual_rms.size(); ++j) worst = std::max(worst, calibration_.residual_rms(j));
    res.success = true;
    res.message = "calibration written to " + path + " and loaded (worst joint residual " + std::to_string(worst) + " rad)";
    publishMetadata();
    ROS_INFO("adroit_teleop: %s", res.message.c_str());
  }

  // --- diagnostics -------------------------------------------------------------------------
  void onDiagnostics(const ros::WallTimerEvent&) {
    rosutil::StatusBuilder s("adroit_teleop: teleop", "glove teleop");
    std::lock_guard<PiMutex> lock(mutex_);
    s.add("mode", params_.mode);
    s.add("deadman_pressed", enabled_);
    s.add("glove_stale", glove_stale_ || glove_q_.size() == 0);
    s.add("glove_records", glove_records_);
    s.add("glove_records_rejected", glove_rejected_);
    s.add("commands", commands_);
    s.add("commands_refused", commands_refused_);
    s.add("calibration", params_.calibration_path);
    s.add("calibrating", session_.has_value());
    if (!mapping_) s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "no joint_states from the driver yet");
    else if (glove_stale_ || glove_q_.size() == 0) s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "no fresh glove record");
    s.publish(diag_pub_);
  }

  TeleopParams params_;
  GloveCalibration calibration_;
  std::string calibration_text_;  // the file calibration_ was parsed from, for the metadata
  ModelPtr model_;

  // Everything below, between the input queue and the spinner threads. Priority inheritance:
  // a spinner thread holding it runs at the input queue's priority while that waits.
  PiMutex mutex_;
  std::optional<TendonMapping> mapping_;
  std::optional<CalibrationSession> session_;
  std::vector<int> target_index_;
  std::vector<double> q_, qdot_, target_, tensions_;
  bool have_q_ = false, enabled_ = false, glove_stale_ = false, safe_state_ = false, watchdog_only_latch_ = false;
  Eigen::VectorXd sensors_, glove_q_;
  ros::Time glove_stamp_;
  ros::WallTime last_glove_wall_, last_command_wall_, last_input_wall_;
  static constexpr double kInputGap = 0.01;  // s: joint states come every 2-4 ms, glove records every 8 ms
  std::uint64_t glove_records_ = 0, glove_rejected_ = 0, commands_ = 0, commands_refused_ = 0;
  adroit_msgs::TendonForceCommand force_msg_;
  adroit_msgs::ForceReference reference_msg_;
  sensor_msgs::JointState target_msg_;

  ros::Publisher force_pub_, reference_pub_, target_pub_, enabled_pub_, metadata_pub_, diag_pub_;
  // Glove records and joint states, the commands' path, on a thread of their own under
  // SCHED_FIFO (~realtime_priority; adroit_ros/realtime.h): at normal scheduling a busy machine
  // held them back until the driver's watchdog tripped. Declared before their subscribers.
  rosutil::FifoCallbackQueue input_queue_;
  ros::Subscriber glove_sub_, joints_sub_, deadman_sub_, safe_sub_, driver_diag_sub_;
  ros::ServiceClient release_client_;
  std::vector<ros::ServiceServer> services_;
  ros::WallTimer diag_timer_;
};

}  // namespace
}  // namespace adroit::teleop

int main(int argc, char** argv) {
  // 3 threads: a calibration record waits while glove records keep coming
  return adroit::rosutil::runNode<adroit::teleop::TeleopNode>(argc, argv, "teleop", 3);
}
