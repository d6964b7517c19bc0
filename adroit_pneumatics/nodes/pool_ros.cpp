// ROS wrapper of CylinderPool, shared by the pool node (pool_node.cpp) and the nodelet
// (pool_nodelet.cpp): reads and validates the parameters, wires the topics, publishes
// valve commands at ~rate and diagnostics at 1 Hz. All callbacks run on one
// single-threaded queue (ros::spin in the node, the nodelet's ST handle), so the pool
// needs no lock.
#include <chrono>
#include <memory>
#include <set>
#include <sstream>
#include <stdexcept>

#include <ros/package.h>
#include <ros/ros.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ForceReference.h>
#include <adroit_msgs/ValveCommand.h>
#include <diagnostic_msgs/DiagnosticArray.h>

#include "adroit_description/scenes.h"
#include "adroit_pneumatics/params_io.h"
#include "adroit_pneumatics/pool.h"

namespace adroit::pneumatics {

namespace {

// Typed access to private parameters: a wrong type or unknown key throws one line that
// names the parameter.
class Params {
 public:
  explicit Params(const ros::NodeHandle& pnh) : pnh_(pnh) {}

  std::string name(const std::string& key) const { return pnh_.resolveName(key); }
  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    throw std::runtime_error("bad parameter " + name(key) + ": " + what);
  }
  bool has(const std::string& key) const { return pnh_.hasParam(key); }

  double number(const std::string& key, double fallback) const {
    XmlRpc::XmlRpcValue v;
    if (!pnh_.getParam(key, v)) return fallback;
    if (v.getType() == XmlRpc::XmlRpcValue::TypeDouble) return static_cast<double>(v);
    if (v.getType() == XmlRpc::XmlRpcValue::TypeInt) return static_cast<int>(v);
    fail(key, "expected a number");
  }
  int integer(const std::string& key, int fallback) const {
    XmlRpc::XmlRpcValue v;
    if (!pnh_.getParam(key, v)) return fallback;
    if (v.getType() != XmlRpc::XmlRpcValue::TypeInt) fail(key, "expected an integer");
    return static_cast<int>(v);
  }
  bool boolean(const std::string& key, bool fallback) const {
    XmlRpc::XmlRpcValue v;
    if (!pnh_.getParam(key, v)) return fallback;
    if (v.getType() != XmlRpc::XmlRpcValue::TypeBoolean) fail(key, "expected true or false");
    return static_cast<bool>(v);
  }
  std::string string(const std::string& key, const std::string& fallback) const {
    XmlRpc::XmlRpcValue v;
    if (!pnh_.getParam(key, v)) return fallback;
    if (v.getType() != XmlRpc::XmlRpcValue::TypeString) fail(key, "expected a string");
    return static_cast<std::string>(v);
  }
  std::vector<std::string> strings(const std::string& key) const {
    XmlRpc::XmlRpcValue v;
    std::vector<std::string> out;
    if (!pnh_.getParam(key, v)) return out;
    if (v.getType() != XmlRpc::XmlRpcValue::TypeArray) fail(key, "expected a list of names");
    for (int i = 0; i < v.size(); ++i) {
      if (v[i].getType() != XmlRpc::XmlRpcValue::TypeString) fail(key, "expected a list of names");
      out.push_back(static_cast<std::string>(v[i]));
    }
    return out;
  }
  // A misspelt key would otherwise be ignored silently and its default used.
  void checkKeys(const std::string& ns, const std::set<std::string>& allowed) const {
    XmlRpc::XmlRpcValue v;
    if (!pnh_.getParam(ns.empty() ? std::string("") : ns, v)) return;
    if (v.getType() != XmlRpc::XmlRpcValue::TypeStruct) fail(ns, "expected a map");
    for (const auto& kv : v) {
      if (!allowed.count(kv.first)) fail(ns.empty() ? kv.first : ns + "/" + kv.first, "unknown parameter");
    }
  }

 private:
  ros::NodeHandle pnh_;
};

// Model file from ~model_file, or the scene ~scene of adroit_description.
std::string modelPath(const Params& p) {
  const std::string file = p.string("model_file", "");
  if (!file.empty()) return file;
  const std::string scene = p.string("scene", "arm_hand");
  const std::string share = ros::package::getPath("adroit_description");
  if (share.empty()) p.fail("scene", "package adroit_description not found");
  try {
    return description::sceneFile(share, scene);
  } catch (const std::exception& e) {
    p.fail("scene", e.what());
  }
}

}  // namespace

class PoolRos {
 public:
  PoolRos(ros::NodeHandle nh, ros::NodeHandle pnh, std::string name) : name_(std::move(name)) {
    const Params p(pnh);
    p.checkKeys("", {"model_file", "scene", "cylinders", "pool", "group_size", "controller", "params_file", "rate",
                     "reference_timeout", "state_timeout", "exhaust_volts", "ilqg", "pidf", "diagnostics_period"});
    p.checkKeys("ilqg", {"horizon", "dt", "alpha_p", "alpha_u", "alpha_w", "u_min", "u_max", "iterations",
                         "feedback_fraction", "solve_every", "disturbance_gain", "disturbance_limit",
                         "u_des_steady_state", "measurement_gain", "measurement_band", "jump_threshold",
                         "jump_iterations"});
    p.checkKeys("pidf", {"kp", "ki", "kd", "filter_hz", "feedforward", "u_min", "u_max"});

    // Cylinders: the model is the source of names and bores.
    const std::string model_file = modelPath(p);
    std::vector<description::Cylinder> table;
    try {
      table = loadModelCylinders(model_file);
    } catch (const std::exception& e) {
      p.fail(p.has("model_file") ? "model_file" : "scene", e.what());
    }
    std::vector<std::string> known;
    for (const auto& c : table) known.push_back(c.name);
    std::vector<std::string> mine = p.strings("cylinders");
    if (mine.empty()) {
      if (!p.has("pool")) p.fail("cylinders", "set ~cylinders (list of names) or ~pool (index into the default split)");
      const auto split = defaultPoolSplit(known, p.integer("group_size", 8));
      const int index = p.integer("pool", 0);
      if (index < 0 || index >= static_cast<int>(split.size()))
        p.fail("pool", "must be in [0, " + std::to_string(split.size() - 1) + "] for " + model_file);
      mine = split[index];
    } else if (p.has("pool")) {
      p.fail("pool", "give either ~cylinders or ~pool, not both");
    }

    // Parametric models: a malformed YAML names its field (params_io).
    const std::string params_file =
        p.string("params_file", ros::package::getPath("adroit_pneumatics") + "/config/parametric_default.yaml");
    ParameterSet models;
    try {
      models = loadParameterSet(params_file);
    } catch (const std::exception& e) {
      p.fail("params_file", e.what());
    }
    for (const auto& kv : models.cylinders) {
      if (std::find(known.begin(), known.end(), kv.first) == known.end())
        p.fail("params_file", params_file + ": parametric.cylinders." + kv.first + ": not a cylinder of " + model_file);
    }

    std::vector<PoolCylinder> cylinders;
    for (const auto& n : mine) {
      const auto it = std::find_if(table.begin(), table.end(), [&](const auto& c) { return c.name == n; });
      if (it == table.end()) p.fail("cylinders", "unknown cylinder '" + n + "' (not in " + model_file + ")");
      cylinders.push_back({n, it->bore_area, deadVolume(it->type, it->bore_diameter), models.forCylinder(n)});
    }

    PoolOptions o;
    o.controller = p.string("controller", "ilqg");
    o.reference_timeout = p.number("reference_timeout", o.reference_timeout);
    o.state_timeout = p.number("state_timeout", o.state_timeout);
    o.exhaust_volts = p.number("exhaust_volts", o.exhaust_volts);
    o.ilqg.horizon = p.integer("ilqg/horizon", o.ilqg.horizon);
    o.ilqg.dt = p.number("ilqg/dt", o.ilqg.dt);
    o.ilqg.alpha_p = p.number("ilqg/alpha_p", o.ilqg.alpha_p);
    o.ilqg.alpha_u = p.number("ilqg/alpha_u", o.ilqg.alpha_u);
    o.ilqg.alpha_w = p.number("ilqg/alpha_w", o.ilqg.alpha_w);
    o.ilqg.u_min = p.number("ilqg/u_min", o.ilqg.u_min);
    o.ilqg.u_max = p.number("ilqg/u_max", o.ilqg.u_max);
    o.ilqg.iterations = p.integer("ilqg/iterations", o.ilqg.iterations);
    o.ilqg.feedback_fraction = p.number("ilqg/feedback_fraction", o.ilqg.feedback_fraction);
    o.solve_every = p.integer("ilqg/solve_every", o.solve_every);
    o.ilqg.disturbance_gain = p.number("ilqg/disturbance_gain", o.ilqg.disturbance_gain);
    o.ilqg.disturbance_limit = p.number("ilqg/disturbance_limit", o.ilqg.disturbance_limit);
    o.ilqg.u_des_steady_state = p.boolean("ilqg/u_des_steady_state", o.ilqg.u_des_steady_state);
    o.ilqg.measurement_gain = p.number("ilqg/measurement_gain", o.ilqg.measurement_gain);
    o.ilqg.measurement_band = p.number("ilqg/measurement_band", o.ilqg.measurement_band);
    o.ilqg.jump_threshold = p.number("ilqg/jump_threshold", o.ilqg.jump_threshold);
    o.ilqg.jump_iterations = p.integer("ilqg/jump_iterations", o.ilqg.jump_iterations);
    o.pidf.kp = p.number("pidf/kp", o.pidf.kp);
    o.pidf.ki = p.number("pidf/ki", o.pidf.ki);
    o.pidf.kd = p.number("pidf/kd", o.pidf.kd);
    o.pidf.filter_hz = p.number("pidf/filter_hz", o.pidf.filter_hz);
    o.pidf.feedforward = p.boolean("pidf/feedforward", o.pidf.feedforward);
    o.pidf.u_min = p.number("pidf/u_min", o.pidf.u_min);
    o.pidf.u_max = p.number("pidf/u_max", o.pidf.u_max);
    try {
      o.validate();
    } catch (const std::exception& e) {
      // The options' messages start with the field ("ilqg: horizon ...", "controller ...").
      throw std::runtime_error("bad parameter " + pnh.getNamespace() + "/" + e.what());
    }
    const double rate = p.number("rate", 200.0);
    if (!(rate > 0 && rate <= 2000)) p.fail("rate", "must be in (0, 2000] Hz");
    const double diag_period = p.number("diagnostics_period", 1.0);
    if (!(diag_period > 0)) p.fail("diagnostics_period", "must be > 0");

    pool_ = std::make_unique<CylinderPool>(std::move(cylinders), known, o);
    controller_ = o.controller;

    command_pub_ = nh.advertise<adroit_msgs::ValveCommand>("/adroit/valve_command", 10);
    diag_pub_ = nh.advertise<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 10);
    state_sub_ = nh.subscribe("/adroit/actuator_states", 10, &PoolRos::onState, this, ros::TransportHints().tcpNoDelay());
    reference_sub_ =
        nh.subscribe("/adroit/force_reference", 10, &PoolRos::onReference, this, ros::TransportHints().tcpNoDelay());
    tick_timer_ = nh.createTimer(ros::Duration(1.0 / rate), &PoolRos::onTick, this);
    diag_timer_ = nh.createWallTimer(ros::WallDuration(diag_period), &PoolRos::onDiagnostics, this);
    window_start_ = std::chrono::steady_clock::now();

    std::ostringstream list;
    for (const auto& n : pool_->names()) list << ' ' << n;
    ROS_INFO("%s: %s pool of %zu cylinders at %.0f Hz:%s", name_.c_str(), controller_.c_str(), pool_->size(), rate,
             list.str().c_str());
  }

 private:
  using Clock = std::chrono::steady_clock;

  void onState(const adroit_msgs::ActuatorStates::ConstPtr& msg) {
    const Verdict v =
        pool_->setState(ros::Time::now().toSec(), msg->name, msg->pressure, msg->length, msg->length_rate,
                        msg->supply_pressure);
    if (v.ok()) {
      state_received_ = Clock::now();
      have_state_ = true;
    } else {
      ROS_ERROR_THROTTLE(1.0, "%s: rejected actuator state: %s", name_.c_str(), v.detail.c_str());
    }
  }

  void onReference(const adroit_msgs::ForceReference::ConstPtr& msg) {
    const double now = ros::Time::now().toSec();
    // An unstamped reference starts now.
    const double t0 = msg->header.stamp.isZero() ? now : msg->header.stamp.toSec();
    const Verdict v = pool_->setReference(now, t0, msg->dt, msg->steps, msg->name, msg->force);
    if (!v.ok()) {
      last_reject_ = v.detail;
      ROS_ERROR_THROTTLE(1.0, "%s: rejected force reference (%s): %s", name_.c_str(), rejectReasonName(v.reason),
                         v.detail.c_str());
    }
  }

  void onTick(const ros::TimerEvent&) {
    const ros::Time now = ros::Time::now();
    const std::vector<double>& volts = pool_->update(now.toSec());
    adroit_msgs::ValveCommand::Ptr msg(new adroit_msgs::ValveCommand);
    msg->header.stamp = now;
    msg->name = pool_->names();
    msg->volts = volts;
    command_pub_.publish(msg);
    ++published_;
    if (have_state_) pool_->recordPolicyLag(std::chrono::duration<double>(Clock::now() - state_received_).count());
  }

  void onDiagnostics(const ros::WallTimerEvent&) {
    const auto t = Clock::now();
    const double window = std::chrono::duration<double>(t - window_start_).count();
    window_start_ = t;
    const PoolWindow w = pool_->takeWindow();
    const PoolCounters& c = pool_->counters();
    const std::uint64_t rejected = c.rejectedTotal();

    diagnostic_msgs::DiagnosticStatus s;
    s.name = name_;
    s.hardware_id = "adroit_pneumatics pool";
    const std::size_t n = pool_->size(), ex = pool_->exhausting();
    if (c.nonfinite_commands > last_nonfinite_) {
      s.level = diagnostic_msgs::DiagnosticStatus::ERROR;
      s.message = "controller produced non-finite commands (exhausted)";
    } else if (ex > 0) {
      s.level = diagnostic_msgs::DiagnosticStatus::WARN;
      s.message = "exhausting " + std::to_string(ex) + "/" + std::to_string(n) + " cylinders (no valid reference or state)";
    } else if (rejected > last_rejected_) {
      s.level = diagnostic_msgs::DiagnosticStatus::WARN;
      s.message = "rejected force references: " + last_reject_;
    } else {
      s.level = diagnostic_msgs::DiagnosticStatus::OK;
      s.message = "tracking " + std::to_string(n) + "/" + std::to_string(n) + " cylinders";
    }
    last_nonfinite_ = c.nonfinite_commands;
    last_rejected_ = rejected;

    auto add = [&s](const std::string& key, const std::string& value) {
      diagnostic_msgs::KeyValue kv;
      kv.key = key;
      kv.value = value;
      s.values.push_back(kv);
    };
    auto num = [](double x) {
      std::ostringstream o;
      o << x;
      return o.str();
    };
    std::string names;
    for (const auto& nm : pool_->names()) names += (names.empty() ? "" : " ") + nm;
    add("controller", controller_);
    add("cylinders", names);
    add("publish_rate_hz", num(window > 0 ? (published_ - last_published_) / window : 0.0));
    last_published_ = published_;
    add("exhausting", std::to_string(ex));
    add("solve_time", formatSummary(w.solve, 1e3, "ms"));
    add("solve_time_p99_ms", num(w.solve.p99 * 1e3));
    add("policy_lag", formatSummary(w.lag, 1e3, "ms"));
    add("policy_lag_p99_ms", num(w.lag.p99 * 1e3));
    add("tracking_rmse_N", num(w.force_rmse));
    add("tracking_rmse_kPa", num(w.pressure_rmse / 1e3));
    add("references_accepted", std::to_string(c.references_accepted));
    add("references_ignored", std::to_string(c.references_ignored));
    add("references_rejected", std::to_string(rejected));
    for (int r = 1; r < static_cast<int>(RejectReason::kCount); ++r)
      add(std::string("references_rejected_") + rejectReasonName(static_cast<RejectReason>(r)),
          std::to_string(c.references_rejected[r]));
    add("last_rejection", last_reject_);
    add("reference_timeouts", std::to_string(c.reference_timeouts));
    add("states_accepted", std::to_string(c.states_accepted));
    add("states_rejected", std::to_string(c.states_rejected));
    add("nonfinite_commands", std::to_string(c.nonfinite_commands));
    add("solver_rejections", std::to_string(c.solver_rejections));

    diagnostic_msgs::DiagnosticArray a;
    a.header.stamp = ros::Time::now();
    a.status.push_back(s);
    diag_pub_.publish(a);
  }

  std::string name_, controller_, last_reject_;
  std::unique_ptr<CylinderPool> pool_;
  ros::Publisher command_pub_, diag_pub_;
  ros::Subscriber state_sub_, reference_sub_;
  ros::Timer tick_timer_;
  ros::WallTimer diag_timer_;
  Clock::time_point state_received_, window_start_;
  bool have_state_ = false;
  std::uint64_t published_ = 0, last_published_ = 0, last_nonfinite_ = 0, last_rejected_ = 0;
};

// Declared in pool_node.cpp and pool_nodelet.cpp. Throws std::runtime_error (one line
// naming the bad parameter) when the configuration is invalid.
std::shared_ptr<void> startPool(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& name) {
  return std::make_shared<PoolRos>(nh, pnh, name);
}

}  // namespace adroit::pneumatics
