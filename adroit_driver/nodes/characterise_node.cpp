// adroit_characterise: the platform characterisation of issue 15 (item 6). Runs the acceptance
// experiments of thesis 3.9 and 5.2.2 (adroit_driver/characterisation.h) on whichever driver is up
// (simulation, hardware, emulated hardware) through the driver's ROS interface only, and writes CSV
// files, PNG plots (bench/plot_characterisation.py) and report.md into ~output_dir.
//
// It refuses to start (one line, exit 1) when the driver is in its safe state (e-stop, watchdog or
// fault latched), when another node publishes valve commands (the pools would fight it), or in
// simulated time. While it runs, every cylinder it has used is commanded at ~rate (the driver's
// 50 ms watchdog), idle at ~idle_volts when no experiment needs it; it aborts, exhausts and
// reports (exit 2) when the driver enters its safe state, the sensors stop, another commander
// appears, ~max_duration passes or on Ctrl-C. It ends by exhausting its cylinders; the driver's
// watchdog then takes over (its safe state also exhausts them).
//
// The reflex runs on the subscriber's callback: the joint-state callback (TCP_NODELAY, its own
// queue and thread) detects the disturbance and publishes the reaction itself, so the latency
// measured is the system's, not this program's command period.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <memory>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <ros/callback_queue.h>
#include <ros/master.h>
#include <ros/package.h>
#include <ros/ros.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/Touch.h>
#include <adroit_msgs/ValveCommand.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>

#include "adroit_core/mujoco_model.h"
#include "adroit_core/run_program.h"
#include "adroit_core/scheduling.h"
#include "adroit_driver/characterisation.h"
#include "adroit_ros/params.h"

namespace ch = adroit::driver::characterisation;
using adroit::rosutil::Params;

namespace {

const char* const kNode = "adroit_characterise";
constexpr double kPlotTimeout = 120.0;  // s: the plot script draws five figures (about 10 s here)
const std::vector<std::string> kExperiments{"bang_bang", "limit_to_limit", "reflex", "step", "chirp", "force"};

std::atomic<bool> g_interrupted{false};
void onSignal(int) { g_interrupted = true; }

struct Refused : std::runtime_error {
  using std::runtime_error::runtime_error;
};
struct Aborted : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// ------------------------------------------------------------------------------ parameters

struct Options {
  std::vector<std::string> experiments = kExperiments;
  bool quick = false;
  std::string output_dir;
  double rate = 500;           // Hz, command rate (the watchdog needs >= 20 Hz; the analysis wants more)
  double idle_volts = 0.0;     // V, used cylinders between experiments: the driver's own idle command
  double max_duration = 300;   // s, the whole run
  double wait_timeout = 10;    // s for the driver's topics
  int realtime_priority = 10;  // SCHED_FIFO of the command loop and the joint callback (0: normal)
  bool plot = true;
  std::string plot_script;
  // Cylinders held during the whole run, ramped in and out over arm_ramp: by default the elbow's
  // flexor lifts the forearm against its limit, so the hand hangs free of the table (the thesis'
  // experiments were made on a hand in free space).
  std::vector<std::pair<std::string, double>> arm_hold;
  double arm_ramp = 1.5;
  std::string joint = "FFJ2";  // bang-bang: the index MCP flexion (ShadowHand FFJ3)
  ch::BangBangParams bang_bang;
  ch::SequenceParams sequence;
  std::string disturbed_joint = "MFJ2", reacting_joint = "FFJ2";
  ch::ReflexParams reflex;
  int reflex_trials = 5;
  std::string valve_joint = "FFJ2";  // step and chirp: its flexor, its extensor exhausted
  ch::StepParams step;
  ch::ChirpParams chirp;
  std::vector<double> chirp_amplitudes{0.25, 1.0};
  std::string force_joint = "FFJ2";
  ch::ForceParams force;
};

// A list parameter given as a YAML list or, from the command line (_key:=a,b), as one string.
std::vector<std::string> listParam(const ros::NodeHandle& pnh, const Params& prm, const std::string& key,
                                   const std::vector<std::string>& fallback) {
  XmlRpc::XmlRpcValue v;
  if (!pnh.getParam(key, v)) return fallback;
  std::vector<std::string> out;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeArray) {
    for (int i = 0; i < v.size(); ++i) {
      if (v[i].getType() == XmlRpc::XmlRpcValue::TypeString)
        out.push_back(static_cast<std::string>(v[i]));
      else if (v[i].getType() == XmlRpc::XmlRpcValue::TypeInt)
        out.push_back(std::to_string(static_cast<int>(v[i])));
      else if (v[i].getType() == XmlRpc::XmlRpcValue::TypeDouble)
        out.push_back(std::to_string(static_cast<double>(v[i])));
      else
        prm.fail(key, "expected a list");
    }
  } else if (v.getType() == XmlRpc::XmlRpcValue::TypeString) {
    std::stringstream in(static_cast<std::string>(v));
    for (std::string item; std::getline(in, item, ',');) {
      item.erase(0, item.find_first_not_of(" []"));
      item.erase(item.find_last_not_of(" []") + 1);
      if (!item.empty()) out.push_back(item);
    }
  } else if (v.getType() == XmlRpc::XmlRpcValue::TypeInt || v.getType() == XmlRpc::XmlRpcValue::TypeDouble) {
    out.push_back(v.getType() == XmlRpc::XmlRpcValue::TypeInt ? std::to_string(static_cast<int>(v))
                                                              : std::to_string(static_cast<double>(v)));
  } else {
    prm.fail(key, "expected a list");
  }
  if (out.empty()) prm.fail(key, "must not be empty");
  return out;
}

std::vector<double> numbersParam(const ros::NodeHandle& pnh, const Params& prm, const std::string& key,
                                 const std::vector<double>& fallback) {
  if (!pnh.hasParam(key)) return fallback;
  std::vector<double> out;
  for (const auto& s : listParam(pnh, prm, key, {})) {
    try {
      std::size_t used = 0;
      out.push_back(std::stod(s, &used));
      if (used != s.size()) throw std::invalid_argument(s);
    } catch (const std::exception&) {
      prm.fail(key, "expected numbers, got '" + s + "'");
    }
  }
  return out;
}

std::string defaultOutputDir() {
  const char* home = std::getenv("ROS_HOME");
  std::string base = home ? home : std::string(std::getenv("HOME") ? std::getenv("HOME") : "/tmp") + "/.ros";
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  return base + "/adroit_characterisation/" + stamp;
}

// Installed next to this program; in a devel space (colcon test) only in the package's sources.
std::string plotScript() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n > 0) {
    const std::string path(buf, static_cast<std::size_t>(n));
    const std::string next_to = path.substr(0, path.find_last_of('/')) + "/plot_characterisation.py";
    if (std::filesystem::is_regular_file(next_to)) return next_to;
  }
  return ros::package::getPath("adroit_driver") + "/bench/plot_characterisation.py";
}

Options readOptions(const ros::NodeHandle& pnh, const Params& prm, const mjModel* model,
                    const std::vector<ch::JointPair>& pairs) {
  prm.checkKeys("", {"experiments", "quick", "output_dir", "scene", "model_file", "rate", "idle_volts", "max_duration",
                     "wait_timeout", "realtime_priority", "plot", "plot_script", "joint", "frequencies", "cycles",
                     "push_volts", "max_push_time", "sequence_joints", "move_time", "disturbed_joint",
                     "reacting_joint", "pulse_time", "reflex_trials", "valve_joint", "step_levels", "step_hold",
                     "chirp_offset", "chirp_amplitudes", "chirp_f0", "chirp_f1", "chirp_duration", "force_joint",
                     "force_hold", "arm_hold", "arm_ramp"});
  Options o;
  o.quick = prm.boolean("quick", false);
  if (o.quick) {  // a few minutes' experiments in about 20 s: for the tests
    o.bang_bang.frequencies = {1, 2, 4, 8};
    o.bang_bang.cycles = 3;
    o.bang_bang.reference_cycles = 1;
    o.bang_bang.stop_after_incomplete = 0;
    o.sequence.joints = {"FFJ2", "FFJ1", "THJ3", "WRJ0"};
    o.reflex_trials = 2;
    o.step.levels = {5};
    o.chirp_amplitudes = {0.5};
    o.chirp.f0 = 2;
    o.chirp.duration = 4;
  }
  o.experiments = listParam(pnh, prm, "experiments", o.experiments);
  for (const auto& e : o.experiments)
    if (std::find(kExperiments.begin(), kExperiments.end(), e) == kExperiments.end())
      prm.fail("experiments",
               "unknown experiment '" + e + "' (known: bang_bang, limit_to_limit, reflex, step, chirp, force)");
  o.output_dir = prm.string("output_dir", "");
  if (o.output_dir.empty()) o.output_dir = defaultOutputDir();
  o.rate = prm.number("rate", o.rate, 100, 1000);
  o.idle_volts = prm.number("idle_volts", o.idle_volts, -5, 1);
  o.max_duration = prm.number("max_duration", o.max_duration, 1, 3600);
  o.wait_timeout = prm.number("wait_timeout", o.wait_timeout, 0.5, 120);
  o.realtime_priority = prm.integer("realtime_priority", o.realtime_priority, 0, 98);
  o.plot = prm.boolean("plot", o.plot);
  o.plot_script = prm.string("plot_script", plotScript());

  auto joint = [&](const std::string& key, const std::string& fallback) {
    const std::string j = prm.string(key, fallback);
    try {
      ch::findPair(pairs, j);
    } catch (const std::exception& e) {
      prm.fail(key, e.what());
    }
    return j;
  };
  o.joint = joint("joint", o.joint);
  o.bang_bang.frequencies = numbersParam(pnh, prm, "frequencies", o.bang_bang.frequencies);
  o.bang_bang.cycles = prm.integer("cycles", o.bang_bang.cycles, 2, 100);
  o.bang_bang.push_volts = o.sequence.push_volts = prm.number("push_volts", 5.0, 1.0, 5.0);
  o.bang_bang.max_push_time = prm.number("max_push_time", o.bang_bang.max_push_time, 0.02, 0.5);
  try {
    o.bang_bang.validate();
  } catch (const std::exception& e) {
    prm.fail("frequencies", e.what());
  }
  o.sequence.joints = listParam(pnh, prm, "sequence_joints", o.sequence.joints);
  if (o.sequence.joints.empty())
    for (const auto& p : pairs)
      if (p.joint.rfind("AR", 0) != 0) o.sequence.joints.push_back(p.joint);  // the hand, as the thesis
  for (const auto& j : o.sequence.joints) {
    try {
      ch::findPair(pairs, j);
    } catch (const std::exception& e) {
      prm.fail("sequence_joints", e.what());
    }
  }
  o.sequence.move_time = prm.number("move_time", o.sequence.move_time, 0.05, 0.5);
  o.disturbed_joint = joint("disturbed_joint", o.disturbed_joint);
  o.reacting_joint = joint("reacting_joint", o.reacting_joint);
  if (o.disturbed_joint == o.reacting_joint) prm.fail("reacting_joint", "must differ from disturbed_joint");
  o.reflex.pulse_time = prm.number("pulse_time", o.reflex.pulse_time, 0.005, 0.2);
  o.reflex_trials = prm.integer("reflex_trials", o.reflex_trials, 1, 50);
  o.valve_joint = joint("valve_joint", o.valve_joint);
  o.step.levels = numbersParam(pnh, prm, "step_levels", o.step.levels);
  o.step.hold = prm.number("step_hold", o.step.hold, 0.1, 0.45);
  o.chirp.offset = prm.number("chirp_offset", o.chirp.offset, -4, 3.5);
  o.chirp_amplitudes = numbersParam(pnh, prm, "chirp_amplitudes", o.chirp_amplitudes);
  o.chirp.f0 = prm.number("chirp_f0", o.chirp.f0, 0.1, 50);
  o.chirp.f1 = prm.number("chirp_f1", 80.0, 1, 200);
  o.chirp.duration = prm.number("chirp_duration", o.quick ? o.chirp.duration : 12.0, 1, 60);
  if (o.chirp.f1 > 0.4 * o.rate) prm.fail("chirp_f1", "must be at most 0.4 of ~rate");
  auto check = [&](const std::string& key, const auto& params) {
    try {
      params.validate();
    } catch (const std::exception& e) {
      prm.fail(key, e.what());
    }
  };
  check("pulse_time", o.reflex);
  check("step_levels", o.step);
  for (double a : o.chirp_amplitudes) {
    ch::ChirpParams c = o.chirp;
    c.amplitude = a;
    check("chirp_amplitudes", c);
  }
  o.force_joint = joint("force_joint", o.force_joint);
  try {
    ch::tipSiteFor(o.force_joint);
  } catch (const std::exception& e) {
    prm.fail("force_joint", e.what());
  }
  o.force.hold = prm.number("force_hold", o.force.hold, 0.3, 1.0);

  std::vector<std::string> hold;
  if (mj_name2id(model, mjOBJ_ACTUATOR, "A_ARJ1_flex") >= 0 && mj_name2id(model, mjOBJ_ACTUATOR, "A_ARJ1_ext") >= 0)
    hold = {"A_ARJ1_flex:1.0", "A_ARJ1_ext:-5.0"};
  hold = listParam(pnh, prm, "arm_hold", hold.empty() ? std::vector<std::string>{"none"} : hold);
  if (!(hold.size() == 1 && hold[0] == "none")) {
    for (const auto& item : hold) {
      const auto colon = item.find(':');
      double volts = ch::kNaN;
      try {
        if (colon != std::string::npos) volts = std::stod(item.substr(colon + 1));
      } catch (const std::exception&) {
      }
      const std::string name = item.substr(0, colon);
      if (!std::isfinite(volts) || mj_name2id(model, mjOBJ_ACTUATOR, name.c_str()) < 0)
        prm.fail("arm_hold", "expected <cylinder>:<volts> items or none, got '" + item + "'");
      if (volts < -5 || volts > 4)
        prm.fail("arm_hold", "volts must be in [-5, 4] (a hold, not a push), got '" + item + "'");
      o.arm_hold.emplace_back(name, volts);
    }
  }
  o.arm_ramp = prm.number("arm_ramp", o.arm_ramp, 0.2, 10);
  return o;
}

// ------------------------------------------------------------------------------ the run

// Per-experiment safety limits: full supply only for about a stroke while the joint can move; a
// little longer where the joint is already held at its limit (steps, force).
ch::CommandLimits limitsFor(const std::string& experiment, const Options& o) {
  ch::CommandLimits l;
  if (experiment == "bang_bang")
    l = o.bang_bang.limits();
  else if (experiment == "limit_to_limit")
    l = o.sequence.limits();
  else if (experiment == "reflex")
    l = o.reflex.limits();
  else if (experiment == "step")
    l = o.step.limits();
  else if (experiment == "chirp")
    l = o.chirp.limits();
  else if (experiment == "force")
    l = o.force.limits();
  l.hold_volts = std::min(0.0, o.idle_volts);
  return l;
}

class Characteriser {
 public:
  Characteriser(const Options& options, std::string scene, const mjModel* model, std::vector<ch::JointPair> pairs)
      : o_(options), scene_(std::move(scene)), model_(model), pairs_(std::move(pairs)) {
    for (int a = 0; a < model_->nu; ++a) {
      const char* n = mj_id2name(model_, mjOBJ_ACTUATOR, a);
      cylinders_.push_back(n ? n : "");
    }
    active_.assign(cylinders_.size(), 0);
    idle_.assign(cylinders_.size(), o_.idle_volts);
    override_.assign(cylinders_.size(), ch::kNaN);
    period_ = 1.0 / o_.rate;
  }

  // The callbacks write into members destroyed before the subscribers: stop them first.
  ~Characteriser() {
    stopCommanding();
    for (auto* spinner : {joint_spinner_.get(), actuator_spinner_.get(), misc_spinner_.get()})
      if (spinner) spinner->stop();
    for (auto* sub : {&joint_sub_, &actuator_sub_, &touch_sub_, &safe_sub_, &diag_sub_}) sub->shutdown();
  }
  Characteriser(const Characteriser&) = delete;
  Characteriser& operator=(const Characteriser&) = delete;

  // Subscribes and checks that it may run; throws Refused with the one line to print.
  void connect();
  // Runs the experiments and writes the report; the exit code.
  int run();

 private:
  // -------- sensors (callbacks on their own queues)
  void onJoints(const sensor_msgs::JointState::ConstPtr& msg);
  void onActuators(const adroit_msgs::ActuatorStates::ConstPtr& msg);
  void onTouch(const adroit_msgs::Touch::ConstPtr& msg);
  void onSafeState(const std_msgs::Bool::ConstPtr& msg);
  void onDiagnostics(const diagnostic_msgs::DiagnosticArray::ConstPtr& msg);
  double now() const { return ros::Time::now().toSec() - origin_; }

  // -------- commands
  int cylinder(const std::string& name) const;
  void publishLocked(const std::vector<int>& which, const std::vector<double>& volts);
  // Commands for `duration` s at the command rate: `volts(t, v)` sets the plan's cylinders (model
  // actuator order; NaN = idle for a cylinder used before). Returns the plan's start on the run clock.
  double runPlan(const std::string& experiment, double duration,
                 const std::function<void(double, std::vector<double>&)>& volts, bool abortable = true);
  void commandLoop();
  void startCommanding();
  void stopCommanding();
  void checkAbort(const std::string& experiment);
  void rest(double seconds) {
    runPlan(current_, seconds, [](double, std::vector<double>&) {});
  }
  void exhaust();
  std::vector<std::string> otherCommanders() const;
  std::string safeStateCause(double wait);

  // -------- the arm's hold around the experiments
  void holdArm();
  void releaseArm();

  // -------- experiments
  void bangBang();
  void limitToLimit();
  void reflex();
  void step();
  void chirp();
  void force();

  // -------- recordings -> series and files (times relative to t0)
  ch::Series jointSeries(const std::string& joint, double t0, double t1) const;
  ch::Series actuatorSeries(const std::string& cylinder, bool force, double t0, double t1) const;
  void writeSamples(const std::string& experiment, double t0, double t1, const std::vector<std::string>& joints,
                    const std::vector<std::string>& cylinders) const;
  std::ofstream open(const std::string& file) const;
  void writeReport();

  Options o_;
  std::string scene_;
  const mjModel* model_;
  std::vector<ch::JointPair> pairs_;
  std::vector<std::string> cylinders_;  // model actuator order
  double period_ = 0.002;
  double origin_ = 0;  // run clock zero, ROS (wall) time
  std::string current_ = "start";

  ros::NodeHandle nh_;
  ros::CallbackQueue joint_queue_, actuator_queue_, misc_queue_;
  std::unique_ptr<ros::AsyncSpinner> joint_spinner_, actuator_spinner_, misc_spinner_;
  ros::Subscriber joint_sub_, actuator_sub_, touch_sub_, safe_sub_, diag_sub_;
  ros::Publisher valve_pub_;

  // Recordings, guarded by data_mutex_.
  mutable std::mutex data_mutex_;
  std::vector<int> joint_map_;  // message index -> pair index (-1)
  std::vector<std::string> joint_msg_names_;
  std::vector<double> joint_t_, joint_rx_, joint_q_;  // q: pairs_.size() per sample
  std::vector<int> actuator_map_;                     // message index -> model actuator (-1)
  std::vector<std::string> actuator_msg_names_;
  std::vector<double> act_t_, act_p_, act_f_, act_supply_;  // p, f: cylinders_.size() per sample
  std::vector<std::string> touch_names_;
  std::vector<double> touch_t_, touch_f_;
  mutable std::mutex cmd_mutex_;
  std::vector<double> cmd_t_, cmd_v_;  // cylinders_.size() per tick, NaN = not sent (cmd_mutex_)
  std::atomic<double> last_joint_wall_{0};
  std::atomic<int> safe_state_{-1};  // -1 unknown
  std::string driver_kind_ = "unknown";
  std::vector<diagnostic_msgs::KeyValue> driver_diag_;
  double driver_diag_time_ = -1;

  // Commands: the plan's loop and the reflex callback publish under command_mutex_.
  std::mutex command_mutex_;
  std::vector<char> active_;      // commanded since the start: kept commanded
  std::vector<double> idle_;      // their command when no experiment needs them (the arm's hold)
  std::vector<double> override_;  // the reflex's reaction, NaN = none
  bool final_ = false;            // exhausting at the end: no limits
  std::atomic<std::uint64_t> limiter_interventions_{0};

  // The plan the command thread runs (one at a time; runPlan waits for it).
  struct Plan {
    std::string experiment;
    long ticks = 0, k = 0;
    std::function<void(double, std::vector<double>&)> volts;
    double start = ch::kNaN;  // run clock of its first command
    bool done = false;
  };
  std::mutex plan_mutex_;
  std::condition_variable plan_cv_;
  std::shared_ptr<Plan> plan_;
  std::atomic<bool> commanding_{false};
  std::thread commander_;
  adroit_msgs::ValveCommand msg_;

  // Reflex state, guarded by reflex_mutex_ (the joint callback detects, the loop sequences).
  enum class ReflexState { kIdle, kTraining, kArmed, kFired };
  std::mutex reflex_mutex_;
  ReflexState reflex_state_ = ReflexState::kIdle;
  ch::OnsetDetector detector_{5.0, 0.01, 0.05};  // 5 sigma, at least 0.01 rad; at rest: below 0.05 rad
  int disturbed_pair_ = -1;
  std::vector<int> reaction_cylinders_;
  std::vector<double> reaction_volts_;
  double detect_stamp_ = ch::kNaN, detect_rx_ = ch::kNaN, reaction_sent_ = ch::kNaN;
  bool fifo_warned_ = false;

  ch::Report report_;
};

// ---------------------------------------------------------------- sensors

void Characteriser::onJoints(const sensor_msgs::JointState::ConstPtr& msg) {
  static thread_local bool scheduled = false;
  if (!scheduled && o_.realtime_priority > 0) {  // the reflex's path: keep it on time on a busy machine
    std::string error;
    if (!adroit::enterFifo(o_.realtime_priority, &error) && !fifo_warned_) {
      fifo_warned_ = true;
      ROS_WARN("%s: joint callback stays at normal scheduling (%s)", kNode, error.c_str());
    }
    scheduled = true;
  }
  const double rx = now();
  const double stamp = msg->header.stamp.toSec() - origin_;
  double disturbed_q = ch::kNaN;
  {
    std::lock_guard<std::mutex> lock(data_mutex_);
    if (msg->name != joint_msg_names_) {
      joint_msg_names_ = msg->name;
      joint_map_.assign(msg->name.size(), -1);
      for (std::size_t i = 0; i < msg->name.size(); ++i)
        for (std::size_t p = 0; p < pairs_.size(); ++p)
          if (pairs_[p].joint == msg->name[i]) joint_map_[i] = static_cast<int>(p);
    }
    if (msg->position.size() != msg->name.size()) return;
    const std::size_t base = joint_q_.size();
    joint_q_.resize(base + pairs_.size(), ch::kNaN);
    for (std::size_t i = 0; i < joint_map_.size(); ++i)
      if (joint_map_[i] >= 0) joint_q_[base + joint_map_[i]] = msg->position[i];
    joint_t_.push_back(stamp);
    joint_rx_.push_back(rx);
    if (disturbed_pair_ >= 0) disturbed_q = joint_q_[base + disturbed_pair_];
  }
  last_joint_wall_ = rx;
  if (!std::isfinite(disturbed_q)) return;
  std::lock_guard<std::mutex> lock(reflex_mutex_);
  if (reflex_state_ == ReflexState::kTraining) {
    detector_.train(disturbed_q);
  } else if (reflex_state_ == ReflexState::kArmed && detector_.feed(disturbed_q)) {
    // The reaction, from here: the next command period would add up to one period of latency.
    std::lock_guard<std::mutex> command_lock(command_mutex_);
    for (std::size_t i = 0; i < reaction_cylinders_.size(); ++i) override_[reaction_cylinders_[i]] = reaction_volts_[i];
    publishLocked(reaction_cylinders_, reaction_volts_);
    reaction_sent_ = now();
    detect_stamp_ = stamp;
    detect_rx_ = rx;
    reflex_state_ = ReflexState::kFired;
  }
}

void Characteriser::onActuators(const adroit_msgs::ActuatorStates::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(data_mutex_);
  if (msg->name != actuator_msg_names_) {
    actuator_msg_names_ = msg->name;
    actuator_map_.assign(msg->name.size(), -1);
    for (std::size_t i = 0; i < msg->name.size(); ++i) actuator_map_[i] = cylinder(msg->name[i]);
  }
  if (msg->pressure.size() != msg->name.size() || msg->force.size() != msg->name.size()) return;
  const std::size_t base = act_p_.size();
  act_p_.resize(base + cylinders_.size(), ch::kNaN);
  act_f_.resize(base + cylinders_.size(), ch::kNaN);
  for (std::size_t i = 0; i < actuator_map_.size(); ++i) {
    if (actuator_map_[i] < 0) continue;
    act_p_[base + actuator_map_[i]] = msg->pressure[i];
    act_f_[base + actuator_map_[i]] = msg->force[i];
  }
  act_t_.push_back(msg->header.stamp.toSec() - origin_);
  act_supply_.push_back(msg->supply_pressure);
}

void Characteriser::onTouch(const adroit_msgs::Touch::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(data_mutex_);
  if (touch_names_.empty()) touch_names_ = msg->name;
  if (msg->name != touch_names_ || msg->force.size() != touch_names_.size()) return;
  touch_t_.push_back(msg->header.stamp.toSec() - origin_);
  touch_f_.insert(touch_f_.end(), msg->force.begin(), msg->force.end());
}

void Characteriser::onSafeState(const std_msgs::Bool::ConstPtr& msg) { safe_state_ = msg->data ? 1 : 0; }

void Characteriser::onDiagnostics(const diagnostic_msgs::DiagnosticArray::ConstPtr& msg) {
  for (const auto& s : msg->status) {
    const bool driver =
        std::any_of(s.values.begin(), s.values.end(), [](const auto& kv) { return kv.key == "estop_latched"; });
    if (!driver) continue;
    std::lock_guard<std::mutex> lock(data_mutex_);
    driver_kind_ = s.hardware_id.empty() ? s.name : s.hardware_id;
    driver_diag_ = s.values;
    driver_diag_time_ = now();
  }
}

// ---------------------------------------------------------------- commands

int Characteriser::cylinder(const std::string& name) const {
  const auto it = std::find(cylinders_.begin(), cylinders_.end(), name);
  return it == cylinders_.end() ? -1 : static_cast<int>(it - cylinders_.begin());
}

void Characteriser::publishLocked(const std::vector<int>& which, const std::vector<double>& volts) {
  msg_.header.stamp = ros::Time::now();
  msg_.name.clear();
  msg_.volts.clear();
  for (std::size_t i = 0; i < which.size(); ++i) {
    msg_.name.push_back(cylinders_[which[i]]);
    msg_.volts.push_back(volts[i]);
  }
  valve_pub_.publish(msg_);
}

std::vector<std::string> Characteriser::otherCommanders() const {
  std::vector<std::string> others;
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  if (!ros::master::execute("getSystemState", args, result, payload, true)) return others;
  const std::string topic = ros::names::resolve("/adroit/valve_command");
  XmlRpc::XmlRpcValue& publishers = payload[0];
  for (int i = 0; i < publishers.size(); ++i) {
    if (static_cast<std::string>(publishers[i][0]) != topic) continue;
    for (int j = 0; j < publishers[i][1].size(); ++j) {
      const std::string node = publishers[i][1][j];
      if (node != ros::this_node::getName()) others.push_back(node);
    }
  }
  return others;
}

std::string Characteriser::safeStateCause(double wait) {
  // The driver's diagnostics (1 Hz) name the latch; wait for one issued after the change.
  const double asked = now();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait);
  while (std::chrono::steady_clock::now() < deadline) {
    {
      std::lock_guard<std::mutex> lock(data_mutex_);
      if (driver_diag_time_ >= asked) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::lock_guard<std::mutex> lock(data_mutex_);
  std::vector<std::string> causes;
  std::string fault;
  for (const auto& kv : driver_diag_) {
    if (kv.value != "true") {
      if (kv.key == "fault" && !kv.value.empty()) fault = kv.value;
      continue;
    }
    if (kv.key == "estop_latched") causes.push_back("e-stop latched");
    if (kv.key == "estop_input") causes.push_back("e-stop input held");
    if (kv.key == "watchdog_latched") causes.push_back("command watchdog latched");
    if (kv.key == "fault_latched") causes.push_back("fault latched" + (fault.empty() ? "" : ": " + fault));
  }
  std::string out;
  for (const auto& c : causes) out += (out.empty() ? "" : ", ") + c;
  return out.empty() ? "cause not reported" : out;
}

void Characteriser::checkAbort(const std::string& experiment) {
  if (g_interrupted || !ros::ok()) throw Aborted("interrupted during " + experiment);
  if (safe_state_ == 1)
    throw Aborted("the driver entered its safe state during " + experiment + " (" + safeStateCause(1.5) + ")");
  if (now() - last_joint_wall_ > 0.5) throw Aborted("no joint states for 0.5 s during " + experiment);
  if (now() > o_.max_duration)
    throw Aborted("~max_duration (" + std::to_string(o_.max_duration) + " s) passed during " + experiment);
}

// The command thread: every period it asks the current plan (if any) for its cylinders' commands,
// keeps every other cylinder used so far at its idle command, applies the experiment's limits and
// publishes. It never waits for the analysis or the files, so the watchdog never sees a gap.
void Characteriser::commandLoop() {
  std::string error;
  if (o_.realtime_priority > 0 && !adroit::enterFifo(o_.realtime_priority, &error))
    ROS_WARN("%s: command thread stays at normal scheduling (%s)", kNode, error.c_str());
  const std::size_t n = cylinders_.size();
  std::string limits_of = "rest";
  ch::CommandLimiter limiter(n, limitsFor(limits_of, o_));
  std::vector<double> desired(n), sent;
  std::vector<int> which;
  const auto period =
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(period_));
  auto deadline = std::chrono::steady_clock::now();
  for (long tick = 0; commanding_; ++tick) {
    std::fill(desired.begin(), desired.end(), ch::kNaN);
    std::shared_ptr<Plan> plan;
    {
      // The plan's function runs under plan_mutex_: once runPlan has dropped a plan, nothing
      // calls into the (then gone) experiment any more.
      std::lock_guard<std::mutex> lock(plan_mutex_);
      plan = plan_;
      if (plan) {
        if (plan->experiment != limits_of) {
          limiter_interventions_ += limiter.interventions();
          limits_of = plan->experiment;
          limiter = ch::CommandLimiter(n, limitsFor(limits_of, o_));
        }
        plan->volts(plan->k * period_, desired);
      }
    }
    double stamp;
    {
      std::lock_guard<std::mutex> lock(command_mutex_);
      which.clear();
      sent.clear();
      for (std::size_t c = 0; c < n; ++c) {
        if (std::isfinite(desired[c])) active_[c] = 1;
        if (!active_[c]) continue;
        double v = std::isfinite(override_[c]) ? override_[c] : std::isfinite(desired[c]) ? desired[c] : idle_[c];
        if (!final_) v = limiter.apply(c, tick * period_, v);
        which.push_back(static_cast<int>(c));
        sent.push_back(v);
      }
      if (!which.empty()) publishLocked(which, sent);
      stamp = now();
      std::lock_guard<std::mutex> record(cmd_mutex_);  // not data_mutex_: the sensors' callbacks grow theirs
      cmd_t_.push_back(stamp);
      const std::size_t base = cmd_v_.size();
      cmd_v_.resize(base + n, ch::kNaN);
      for (std::size_t i = 0; i < which.size(); ++i) cmd_v_[base + which[i]] = sent[i];
    }
    if (plan) {
      std::lock_guard<std::mutex> lock(plan_mutex_);
      if (plan->k == 0) plan->start = stamp;
      if (++plan->k >= plan->ticks) {
        plan->done = true;
        if (plan_ == plan) plan_.reset();
        plan_cv_.notify_all();
      }
    }
    deadline += period;
    const auto late = std::chrono::steady_clock::now() - deadline;
    if (late > 5 * period) deadline += late;  // after a stall keep the rate, do not burst
    std::this_thread::sleep_until(deadline);
  }
  limiter_interventions_ += limiter.interventions();
}

double Characteriser::runPlan(const std::string& experiment, double duration,
                              const std::function<void(double, std::vector<double>&)>& volts, bool abortable) {
  auto plan = std::make_shared<Plan>();
  plan->experiment = experiment;
  plan->ticks = std::max(1L, std::lround(duration / period_));
  plan->volts = volts;
  std::unique_lock<std::mutex> lock(plan_mutex_);
  plan_ = plan;
  while (!plan_cv_.wait_for(lock, std::chrono::milliseconds(10), [&] { return plan->done; })) {
    if (!abortable) continue;
    lock.unlock();
    try {
      checkAbort(experiment);
    } catch (const Aborted&) {
      lock.lock();
      if (plan_ == plan) plan_.reset();
      throw;
    }
    lock.lock();
  }
  return plan->start;
}

void Characteriser::startCommanding() {
  commanding_ = true;
  commander_ = std::thread(&Characteriser::commandLoop, this);
}

void Characteriser::exhaust() {
  // Vents every cylinder used, unlimited; the commands keep the watchdog quiet while they act.
  {
    std::lock_guard<std::mutex> lock(command_mutex_);
    std::fill(override_.begin(), override_.end(), ch::kNaN);
    final_ = true;
  }
  if (commander_.joinable()) {
    runPlan(
        "exhaust", 0.3,
        [&](double, std::vector<double>& v) {
          for (std::size_t c = 0; c < v.size(); ++c)
            if (active_[c]) v[c] = -5.0;
        },
        false);
  }
  stopCommanding();
}

void Characteriser::stopCommanding() {
  commanding_ = false;
  if (commander_.joinable()) commander_.join();
}

// ---------------------------------------------------------------- set-up

void Characteriser::connect() {
  bool sim_time = false;
  if (ros::param::get("/use_sim_time", sim_time) && sim_time)
    throw Refused("refusing to run: /use_sim_time is set (the experiments need the driver in real time)");
  origin_ = ros::Time::now().toSec();
  ros::NodeHandle joints(nh_), actuators(nh_), misc(nh_);
  joints.setCallbackQueue(&joint_queue_);
  actuators.setCallbackQueue(&actuator_queue_);
  misc.setCallbackQueue(&misc_queue_);
  const auto nodelay = ros::TransportHints().tcpNoDelay();
  safe_sub_ = misc.subscribe("/adroit/safe_state", 10, &Characteriser::onSafeState, this);
  diag_sub_ = misc.subscribe("/adroit/diagnostics", 10, &Characteriser::onDiagnostics, this);
  touch_sub_ = misc.subscribe("/adroit/touch", 50, &Characteriser::onTouch, this, nodelay);
  joint_sub_ = joints.subscribe("/adroit/joint_states", 200, &Characteriser::onJoints, this, nodelay);
  actuator_sub_ = actuators.subscribe("/adroit/actuator_states", 200, &Characteriser::onActuators, this, nodelay);
  joint_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &joint_queue_);
  actuator_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &actuator_queue_);
  misc_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &misc_queue_);
  joint_spinner_->start();
  actuator_spinner_->start();
  misc_spinner_->start();

  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o_.wait_timeout);
  auto waitFor = [&](const std::function<bool()>& ready) {
    while (!ready() && std::chrono::steady_clock::now() < deadline && !g_interrupted)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return ready();
  };
  if (!waitFor([&] { return safe_state_ >= 0; }))
    throw Refused("refusing to run: no driver (/adroit/safe_state not received within " +
                  std::to_string(static_cast<int>(o_.wait_timeout)) + " s)");
  if (safe_state_ == 1)
    throw Refused("refusing to run: the driver is in its safe state (" + safeStateCause(1.5) +
                  "); release it with /adroit/estop_release first");
  const auto others = otherCommanders();
  if (!others.empty()) {
    std::string names;
    for (const auto& n : others) names += (names.empty() ? "" : ", ") + n;
    throw Refused("refusing to run: " + names + " also publishes /adroit/valve_command (stop it, e.g. pools:=false)");
  }
  if (!waitFor([&] {
        std::lock_guard<std::mutex> lock(data_mutex_);
        return !joint_t_.empty() && !act_t_.empty();
      }))
    throw Refused("refusing to run: no /adroit/joint_states or /adroit/actuator_states within " +
                  std::to_string(static_cast<int>(o_.wait_timeout)) + " s");
  {
    std::lock_guard<std::mutex> lock(data_mutex_);
    for (const auto& p : pairs_) {
      if (std::find(joint_msg_names_.begin(), joint_msg_names_.end(), p.joint) == joint_msg_names_.end())
        throw Refused("refusing to run: the driver publishes no joint '" + p.joint + "' (another model?)");
      for (const auto& c : {p.flexor, p.extensor})
        if (std::find(actuator_msg_names_.begin(), actuator_msg_names_.end(), c) == actuator_msg_names_.end())
          throw Refused("refusing to run: the driver reports no cylinder '" + c + "' (pneumatic mode needed)");
    }
  }
  valve_pub_ = nh_.advertise<adroit_msgs::ValveCommand>("/adroit/valve_command", 50);
  if (!waitFor([&] { return valve_pub_.getNumSubscribers() > 0; }))
    throw Refused("refusing to run: the driver does not subscribe /adroit/valve_command");
  // Diagnostics come at 1 Hz: the driver's kind for the report.
  waitFor([&] {
    std::lock_guard<std::mutex> lock(data_mutex_);
    return driver_diag_time_ >= 0;
  });
}

// ---------------------------------------------------------------- experiments

void Characteriser::bangBang() {
  const auto& p = ch::findPair(pairs_, o_.joint);
  const int flex = cylinder(p.flexor), ext = cylinder(p.extensor);
  const ch::BangBangParams& b = o_.bang_bang;
  auto plan = [&](double f) {
    return [&, f](double t, std::vector<double>& v) {
      const ch::PairVolts pv = ch::bangBangVolts(b, f, t);
      v[flex] = pv.flex;
      v[ext] = pv.ext;
    };
  };
  ch::BangBangResult& r = report_.bang_bang;
  r = ch::BangBangResult();
  r.joint = p.joint;
  r.model_range = p.range();
  r.complete_fraction = b.complete_fraction;
  r.damping = p.damping;
  const double t_begin = now();
  const double t_ref = runPlan("bang_bang", b.reference_cycles / b.reference_hz, plan(b.reference_hz));
  {
    const ch::Series q = jointSeries(p.joint, 0, 1e9);
    double lo = INFINITY, hi = -INFINITY;
    for (std::size_t i = 0; i < q.size(); ++i)
      if (q.t[i] >= t_ref && q.t[i] <= now()) lo = std::min(lo, q.v[i]), hi = std::max(hi, q.v[i]);
    r.reference_low = lo;
    r.reference_high = hi;
    r.reference_range = hi - lo;
    r.bound_stroke_time =
        std::max(ch::dampingBoundTime(p, r.reference_range, true), ch::dampingBoundTime(p, r.reference_range, false));
  }
  report_.has_bang_bang = true;
  int incomplete = 0;
  std::vector<double> starts;
  for (double f : b.frequencies) {
    const int cycles = ch::bangBangCycles(b, f);
    const double t0 = runPlan("bang_bang", cycles / f, plan(f));
    starts.push_back(t0 - t_begin);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // let the last samples arrive
    const ch::Stroke s = ch::measureStroke(jointSeries(p.joint, 0, 1e9), t0, f, cycles, b.skip_cycles,
                                           r.reference_range, b.complete_fraction);
    r.strokes.push_back(s);
    ch::summariseBangBang(&r);
    ROS_INFO("%s: bang-bang %s %5.1f Hz: stroke %.3f rad (%3.0f %% of %.3f)", kNode, p.joint.c_str(), f, s.peak_to_peak,
             100 * s.fraction, r.reference_range);
    incomplete = s.complete ? 0 : incomplete + 1;
    if (b.stop_after_incomplete > 0 && incomplete >= b.stop_after_incomplete) break;  // the strokes stay incomplete
  }
  writeSamples("bang_bang", t_begin, now(), {p.joint}, {p.flexor, p.extensor});
  std::ofstream out = open("bang_bang.csv");
  out << "frequency_hz,start_s,stroke_rad,fraction,low_rad,high_rad,cycles,complete,reference_range_rad,"
         "reference_low_rad,reference_high_rad,model_range_rad,reference_start_s,bound_stroke_time_s\n";
  for (std::size_t i = 0; i < r.strokes.size(); ++i) {
    const ch::Stroke& s = r.strokes[i];
    out << s.frequency << ',' << starts[i] << ',' << s.peak_to_peak << ',' << s.fraction << ',' << s.low << ','
        << s.high << ',' << s.cycles << ',' << s.complete << ',' << r.reference_range << ',' << r.reference_low << ','
        << r.reference_high << ',' << r.model_range << ',' << t_ref - t_begin << ',' << r.bound_stroke_time << '\n';
  }
}

void Characteriser::limitToLimit() {
  const ch::SequenceParams& sp = o_.sequence;
  ch::SequenceResult& r = report_.sequence;
  r = ch::SequenceResult();
  report_.has_sequence = true;
  const double t_begin = now();
  std::ofstream out = open("limit_to_limit.csv");
  out << "joint,movement,command_s,time_s,start_rad,extreme_rad,excursion_rad,fraction_of_range,bound_time_s\n";
  std::vector<std::string> cylinders;
  for (const auto& name : sp.joints) {
    const auto& p = ch::findPair(pairs_, name);
    const int flex = cylinder(p.flexor), ext = cylinder(p.extensor);
    cylinders.push_back(p.flexor);
    cylinders.push_back(p.extensor);
    const double t0 = runPlan("limit_to_limit", sp.blockTime(), [&](double t, std::vector<double>& v) {
      const ch::PairVolts pv = ch::sequenceVolts(sp, t);
      v[flex] = pv.flex;
      v[ext] = pv.ext;
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const ch::Series q = jointSeries(p.joint, 0, 1e9);
    for (int move = 0; move < 2; ++move) {
      const double tc = t0 + sp.pre_time + move * sp.move_time;
      ch::Movement m = ch::measureMovement(q, tc, tc + sp.move_time, move == 0 ? p.flex_sign : -p.flex_sign, p.range());
      m.joint = p.joint;
      m.flexion = move == 0;
      m.bound_time = std::isfinite(m.excursion) ? ch::dampingBoundTime(p, m.excursion, m.flexion) : ch::kNaN;
      r.moves.push_back(m);
      out << m.joint << ',' << (m.flexion ? "flexion" : "extension") << ',' << tc - t_begin << ',' << m.time << ','
          << m.start << ',' << m.extreme << ',' << m.excursion << ',' << m.fraction_of_range << ',' << m.bound_time
          << '\n';
    }
    ch::summariseSequence(&r);
    ROS_INFO("%s: limit-to-limit %s: flexion %.0f ms, extension %.0f ms", kNode, p.joint.c_str(),
             r.moves[r.moves.size() - 2].time * 1e3, r.moves.back().time * 1e3);
  }
  writeSamples("limit_to_limit", t_begin, now(), sp.joints, cylinders);
}

void Characteriser::reflex() {
  const auto& dist = ch::findPair(pairs_, o_.disturbed_joint);
  const auto& react = ch::findPair(pairs_, o_.reacting_joint);
  const int d_flex = cylinder(dist.flexor), d_ext = cylinder(dist.extensor);
  const int r_flex = cylinder(react.flexor), r_ext = cylinder(react.extensor);
  const ch::ReflexParams& rp = o_.reflex;
  ch::ReflexResult& r = report_.reflex;
  r = ch::ReflexResult();
  r.disturbed_joint = dist.joint;
  r.pulse_cylinder = dist.flexor;
  r.reacting_joint = react.joint;
  r.reacting_cylinders = {react.extensor + " +5 V", react.flexor + " -5 V"};
  report_.has_reflex = true;
  {
    std::lock_guard<std::mutex> lock(reflex_mutex_);
    disturbed_pair_ = static_cast<int>(&dist - pairs_.data());
    reaction_cylinders_ = {r_ext, r_flex};
    reaction_volts_ = {rp.push_volts, rp.release_volts};
  }
  const double t_begin = now();
  std::ofstream out = open("reflex.csv");
  out << "trial,pulse_s,detect_s,receive_s,command_s,pressure_s,motion_s,pressure_latency_s,motion_latency_s,"
         "detect_threshold_rad,pressure_threshold_pa,motion_threshold_rad,valid,note\n";
  // A lead-in at the trial's rest state: the fingers may start far from it (a trial resets them
  // only as far as its push time allows).
  runPlan("reflex", 1.0, [&](double t, std::vector<double>& v) {
    const ch::ReflexVolts rv = ch::reflexVolts(rp, std::min(t, rp.train - 1e-3));
    v[d_flex] = rv.disturbed.flex;
    v[d_ext] = rv.disturbed.ext;
    v[r_flex] = rv.reacting.flex;
    v[r_ext] = rv.reacting.ext;
  });
  for (int trial = 0; trial < o_.reflex_trials; ++trial) {
    double t_pulse = ch::kNaN;
    bool at_rest = true;
    int stage = 0;  // 0 preparing, 1 learning the noise, 2 armed (the pulse is out), 3 over
    runPlan("reflex", rp.trial, [&](double t, std::vector<double>& v) {
      const ch::ReflexVolts rv = ch::reflexVolts(rp, t);
      v[d_flex] = rv.disturbed.flex;
      v[d_ext] = rv.disturbed.ext;
      v[r_flex] = rv.reacting.flex;
      v[r_ext] = rv.reacting.ext;
      std::lock_guard<std::mutex> lock(reflex_mutex_);
      if (stage == 0 && t >= rp.train) {
        detector_.reset();
        reflex_state_ = ReflexState::kTraining;
        stage = 1;
      } else if (stage == 1 && t >= rp.pulse) {
        at_rest = detector_.arm();
        reflex_state_ = at_rest ? ReflexState::kArmed : ReflexState::kIdle;
        t_pulse = now();  // the pulse goes out with this tick
        stage = 2;
      } else if (stage == 2) {
        const bool fired = reflex_state_ == ReflexState::kFired;
        if ((fired && now() > reaction_sent_ + rp.reaction_time) || (!fired && t >= rp.pulse + rp.search)) {
          std::lock_guard<std::mutex> command_lock(command_mutex_);
          for (int c : reaction_cylinders_) override_[c] = ch::kNaN;
          if (!fired) reflex_state_ = ReflexState::kIdle;
          stage = 3;
        }
      }
    });
    ch::ReflexTrial tr;
    {
      std::lock_guard<std::mutex> lock(reflex_mutex_);
      tr.t_pulse = t_pulse;
      if (reflex_state_ == ReflexState::kFired) {
        tr.t_detect = detect_stamp_;
        tr.t_receive = detect_rx_;
        tr.t_command = reaction_sent_;
      }
      tr.detect_threshold = detector_.threshold();
      reflex_state_ = ReflexState::kIdle;
      std::lock_guard<std::mutex> command_lock(command_mutex_);
      for (int c : reaction_cylinders_) override_[c] = ch::kNaN;
    }
    ch::measureReflex(actuatorSeries(react.extensor, false, 0, 1e9), jointSeries(react.joint, 0, 1e9), -react.flex_sign,
                      ch::ReflexThresholds(), &tr);
    if (!at_rest)
      tr.note = dist.joint + " was not at rest before the pulse (noise band " +
                std::to_string(tr.detect_threshold).substr(0, 5) + " rad)";
    r.trials.push_back(tr);
    ROS_INFO(
        "%s: reflex trial %d: detected %.1f ms after the pulse; pressure %.1f ms, motion %.1f ms after the "
        "detection %s",
        kNode, trial + 1, (tr.t_detect - tr.t_pulse) * 1e3, tr.pressureLatency() * 1e3, tr.motionLatency() * 1e3,
        tr.note.c_str());
    auto rel = [&](double x) { return x - t_begin; };
    out << trial + 1 << ',' << rel(tr.t_pulse) << ',' << rel(tr.t_detect) << ',' << rel(tr.t_receive) << ','
        << rel(tr.t_command) << ',' << rel(tr.t_pressure) << ',' << rel(tr.t_motion) << ',' << tr.pressureLatency()
        << ',' << tr.motionLatency() << ',' << tr.detect_threshold << ',' << tr.pressure_threshold << ','
        << tr.motion_threshold << ',' << tr.valid << ',' << tr.note << '\n';
  }
  {
    std::lock_guard<std::mutex> lock(reflex_mutex_);
    disturbed_pair_ = -1;
  }
  const ch::Series p = actuatorSeries(react.extensor, false, t_begin, now());
  std::vector<double> dt;
  for (std::size_t i = 1; i < p.size(); ++i) dt.push_back(p.t[i] - p.t[i - 1]);
  std::sort(dt.begin(), dt.end());
  r.pressure_period = dt.empty() ? ch::kNaN : dt[dt.size() / 2];
  ch::summariseReflex(&r);
  writeSamples("reflex", t_begin, now(), {dist.joint, react.joint},
               {dist.flexor, dist.extensor, react.flexor, react.extensor});
}

void Characteriser::step() {
  const auto& p = ch::findPair(pairs_, o_.valve_joint);
  const int flex = cylinder(p.flexor), ext = cylinder(p.extensor);
  const ch::StepParams& sp = o_.step;
  ch::StepResult& r = report_.step;
  r = ch::StepResult();
  r.cylinder = p.flexor;
  r.antagonist = p.extensor;
  r.joint = p.joint;
  report_.has_step = true;
  const double t0 = runPlan("step", sp.duration(), [&](double t, std::vector<double>& v) {
    const ch::PairVolts pv = ch::stepVolts(sp, t);
    v[flex] = pv.flex;
    v[ext] = pv.ext;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(10));  // the last samples
  std::ofstream out = open("step.csv");
  out << "from_v,to_v,step_s,p_initial_pa,p_final_pa,first_change_s,dead_time_s,rise_time_s,time_constant_s,t63_s,"
         "joint_motion_rad\n";
  const ch::Series pressure = actuatorSeries(p.flexor, false, t0, now());
  std::vector<double> dt;
  for (std::size_t i = 1; i < pressure.size(); ++i) dt.push_back(pressure.t[i] - pressure.t[i - 1]);
  std::sort(dt.begin(), dt.end());
  r.sample_period = dt.empty() ? ch::kNaN : dt[dt.size() / 2];
  for (const auto& s : sp.steps()) {
    const double ts = t0 + s.time;
    ch::StepResponse x = ch::measureStep(pressure, ts, ts + sp.hold);
    x.from_volts = s.from;
    x.to_volts = s.to;
    const ch::Series q = jointSeries(p.joint, ts, ts + sp.hold);
    if (!q.empty())
      x.joint_motion = *std::max_element(q.v.begin(), q.v.end()) - *std::min_element(q.v.begin(), q.v.end());
    r.steps.push_back(x);
    ROS_INFO("%s: step %+.0f -> %+.0f V: %.0f -> %.0f kPa, dead time %.1f ms, time constant %.1f ms", kNode, s.from,
             s.to, x.p_initial / 1e3, x.p_final / 1e3, x.dead_time * 1e3, x.time_constant * 1e3);
    out << s.from << ',' << s.to << ',' << s.time << ',' << x.p_initial << ',' << x.p_final << ',' << x.first_change
        << ',' << x.dead_time << ',' << x.rise_time << ',' << x.time_constant << ',' << x.t63 << ',' << x.joint_motion
        << '\n';
  }
  writeSamples("step", t0, now(), {p.joint}, {p.flexor, p.extensor});
}

void Characteriser::chirp() {
  const auto& p = ch::findPair(pairs_, o_.valve_joint);
  const int flex = cylinder(p.flexor), ext = cylinder(p.extensor);
  report_.chirps.clear();
  report_.chirp_cylinder = p.flexor;
  report_.chirp_antagonist = p.extensor;
  report_.has_chirp = true;
  const double t_begin = now();
  std::ofstream out = open("chirp.csv");
  out << "offset_v,amplitude_v,start_s,frequency_hz,gain_pa_per_v,gain_db,phase_rad,critical_hz\n";
  for (double amplitude : o_.chirp_amplitudes) {
    ch::ChirpParams c = o_.chirp;
    c.amplitude = amplitude;
    const double t0 = runPlan("chirp", c.start() + c.duration, [&](double t, std::vector<double>& v) {
      const ch::PairVolts pv = ch::chirpPlanVolts(c, t);
      v[flex] = pv.flex;
      v[ext] = pv.ext;
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const double start = t0 + c.start();
    ch::ChirpResult result;
    result.params = c;
    result.points = ch::chirpGains(actuatorSeries(p.flexor, false, 0, 1e9), c, start);
    result.bandwidth = ch::criticalFrequency(result.points, 2 * c.f0);
    const ch::Series q = jointSeries(p.joint, start, start + c.duration);
    if (!q.empty())
      result.joint_motion = *std::max_element(q.v.begin(), q.v.end()) - *std::min_element(q.v.begin(), q.v.end());
    for (const auto& g : result.points)
      out << c.offset << ',' << c.amplitude << ',' << start - t_begin << ',' << g.frequency << ',' << g.gain << ','
          << 20 * std::log10(g.gain / result.bandwidth.reference_gain) << ',' << g.phase << ','
          << result.bandwidth.critical_hz << '\n';
    ROS_INFO("%s: chirp %.2f +- %.2f V: -3 dB at %.1f Hz", kNode, c.offset, c.amplitude, result.bandwidth.critical_hz);
    report_.chirps.push_back(result);
    rest(0.2);
  }
  writeSamples("chirp", t_begin, now(), {p.joint}, {p.flexor, p.extensor});
}

void Characteriser::force() {
  const auto& p = ch::findPair(pairs_, o_.force_joint);
  const int flex = cylinder(p.flexor), ext = cylinder(p.extensor);
  const ch::ForceParams& fp = o_.force;
  ch::ForceResult& r = report_.force;
  r = ch::ForceResult();
  r.joint = p.joint;
  r.flexor = p.flexor;
  r.extensor = p.extensor;
  r.lever = ch::fingertipLever(model_, p, ch::tipSiteFor(p.joint));
  report_.has_force = true;
  const double t0 = runPlan("force", fp.duration(), [&](double t, std::vector<double>& v) {
    const ch::PairVolts pv = ch::forceVolts(fp, t);
    v[flex] = pv.flex;
    v[ext] = pv.ext;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const double flex_end = t0 + fp.flexEnd(), ext_end = t0 + fp.extEnd();
  auto plateauOf = [&](const std::string& c, bool force, double end) {
    return ch::baselineOf(actuatorSeries(c, force, 0, 1e9), end - fp.plateau, end).mean;
  };
  r.flex_tension = plateauOf(p.flexor, true, flex_end);
  r.ext_tension = plateauOf(p.extensor, true, ext_end);
  r.flex_pressure = plateauOf(p.flexor, false, flex_end);
  r.ext_pressure = plateauOf(p.extensor, false, ext_end);
  {
    std::lock_guard<std::mutex> lock(data_mutex_);
    double supply = 0;
    int n = 0;
    for (std::size_t i = 0; i < act_t_.size(); ++i)
      if (act_t_[i] >= t0 && act_t_[i] <= ext_end) supply += act_supply_[i], ++n;
    r.supply = n ? supply / n : ch::kNaN;
    const std::string sensor = "ST_" + r.lever.site.substr(2);  // S_fftip -> ST_fftip
    const auto it = std::find(touch_names_.begin(), touch_names_.end(), sensor);
    if (it != touch_names_.end()) {
      const std::size_t k = static_cast<std::size_t>(it - touch_names_.begin());
      r.touch_sensor = sensor;
      r.touch_flex = r.touch_ext = 0;
      for (std::size_t i = 0; i < touch_t_.size(); ++i) {
        const double f = touch_f_[i * touch_names_.size() + k];
        if (touch_t_[i] >= t0 && touch_t_[i] <= flex_end) r.touch_flex = std::max(r.touch_flex, f);
        if (touch_t_[i] >= t0 + fp.extStart() && touch_t_[i] <= ext_end) r.touch_ext = std::max(r.touch_ext, f);
      }
    }
  }
  ch::summariseForce(&r);
  ROS_INFO("%s: fingertip force %s: flexing %.2f N (%.0f g), extending %.2f N (%.0f g)", kNode, p.joint.c_str(),
           r.flex_tip, r.flex_tip / ch::kStandardGravity * 1e3, r.ext_tip, r.ext_tip / ch::kStandardGravity * 1e3);
  std::ofstream out = open("force.csv");
  out << "joint,site,supply_pa,flex_pressure_pa,ext_pressure_pa,flex_tension_n,ext_tension_n,flexor_arm_m,"
         "extensor_arm_m,lever_m,flex_tip_n,ext_tip_n,touch_flex_n,touch_ext_n,flex_end_s,ext_end_s\n";
  out << r.joint << ',' << r.lever.site << ',' << r.supply << ',' << r.flex_pressure << ',' << r.ext_pressure << ','
      << r.flex_tension << ',' << r.ext_tension << ',' << r.lever.flexor_arm << ',' << r.lever.extensor_arm << ','
      << r.lever.lever << ',' << r.flex_tip << ',' << r.ext_tip << ',' << r.touch_flex << ',' << r.touch_ext << ','
      << fp.flexEnd() << ',' << fp.extEnd() << '\n';
  writeSamples("force", t0, now(), {p.joint}, {p.flexor, p.extensor});
}

void Characteriser::holdArm() {
  if (o_.arm_hold.empty()) return;
  std::vector<int> which;
  std::string what;
  for (const auto& [name, volts] : o_.arm_hold) {
    which.push_back(cylinder(name));
    char item[96];
    std::snprintf(item, sizeof item, "%s%s %+.1f V", what.empty() ? "" : ", ", name.c_str(), volts);
    what += item;
  }
  report_.arm_hold = "held " + what + " throughout (ramped over " + std::to_string(o_.arm_ramp).substr(0, 4) + " s)";
  const double settle = 1.0;
  const double t0 = runPlan("arm hold", o_.arm_ramp + settle, [&](double t, std::vector<double>& v) {
    const double w = std::min(1.0, t / o_.arm_ramp);
    for (std::size_t i = 0; i < which.size(); ++i) v[which[i]] = (1 - w) * o_.idle_volts + w * o_.arm_hold[i].second;
  });
  for (std::size_t i = 0; i < which.size(); ++i) idle_[which[i]] = o_.arm_hold[i].second;
  // Is the hand free? The fingers' experiments assume it.
  std::lock_guard<std::mutex> lock(data_mutex_);
  std::vector<double> peak(touch_names_.size(), 0.0);
  for (std::size_t i = 0; i < touch_t_.size(); ++i)
    if (touch_t_[i] >= t0 + o_.arm_ramp + settle - 0.3)
      for (std::size_t k = 0; k < peak.size(); ++k) peak[k] = std::max(peak[k], touch_f_[i * peak.size() + k]);
  report_.touch_checked = !touch_names_.empty();
  for (std::size_t k = 0; k < peak.size(); ++k)
    if (peak[k] > 0.05) report_.touch_at_rest.emplace_back(touch_names_[k], peak[k]);
  for (const auto& [name, force] : report_.touch_at_rest)
    ROS_INFO("%s: at rest before the experiments %s reads %.2f N", kNode, name.c_str(), force);
}

void Characteriser::releaseArm() {
  if (o_.arm_hold.empty()) return;
  std::vector<int> which;
  for (const auto& h : o_.arm_hold) which.push_back(cylinder(h.first));
  runPlan("arm release", o_.arm_ramp, [&](double t, std::vector<double>& v) {
    const double w = std::min(1.0, t / o_.arm_ramp);
    for (std::size_t i = 0; i < which.size(); ++i) v[which[i]] = (1 - w) * o_.arm_hold[i].second + w * o_.idle_volts;
  });
  for (int c : which) idle_[c] = o_.idle_volts;
}

// ---------------------------------------------------------------- recordings

ch::Series Characteriser::jointSeries(const std::string& joint, double t0, double t1) const {
  const int p = static_cast<int>(&ch::findPair(pairs_, joint) - pairs_.data());
  ch::Series s;
  std::lock_guard<std::mutex> lock(data_mutex_);
  for (std::size_t i = 0; i < joint_t_.size(); ++i) {
    const double q = joint_q_[i * pairs_.size() + p];
    if (joint_t_[i] >= t0 && joint_t_[i] <= t1 && std::isfinite(q)) s.add(joint_t_[i], q);
  }
  return s;
}

ch::Series Characteriser::actuatorSeries(const std::string& name, bool force, double t0, double t1) const {
  const int c = cylinder(name);
  ch::Series s;
  std::lock_guard<std::mutex> lock(data_mutex_);
  const auto& values = force ? act_f_ : act_p_;
  for (std::size_t i = 0; i < act_t_.size(); ++i) {
    const double x = values[i * cylinders_.size() + c];
    if (act_t_[i] >= t0 && act_t_[i] <= t1 && std::isfinite(x)) s.add(act_t_[i], x);
  }
  return s;
}

std::ofstream Characteriser::open(const std::string& file) const {
  std::ofstream out(o_.output_dir + "/" + file);
  if (!out) throw std::runtime_error("cannot write " + o_.output_dir + "/" + file);
  out.precision(9);
  return out;
}

// Three files per experiment, times from its start: <e>_joints.csv, <e>_actuators.csv, <e>_commands.csv.
void Characteriser::writeSamples(const std::string& e, double t0, double t1, const std::vector<std::string>& joints,
                                 const std::vector<std::string>& cylinders) const {
  std::vector<int> pj, pc;
  for (const auto& j : joints) pj.push_back(static_cast<int>(&ch::findPair(pairs_, j) - pairs_.data()));
  for (const auto& c : cylinders) pc.push_back(cylinder(c));
  // Copied under the locks, written without them: the callbacks and the command thread record meanwhile.
  std::vector<double> q, a, v;  // rows: time, then the columns
  {
    std::lock_guard<std::mutex> lock(data_mutex_);
    for (std::size_t i = 0; i < joint_t_.size(); ++i) {
      if (joint_t_[i] < t0 || joint_t_[i] > t1) continue;
      q.push_back(joint_t_[i] - t0);
      for (int p : pj) q.push_back(joint_q_[i * pairs_.size() + p]);
    }
    for (std::size_t i = 0; i < act_t_.size(); ++i) {
      if (act_t_[i] < t0 || act_t_[i] > t1) continue;
      a.push_back(act_t_[i] - t0);
      for (int c : pc) a.insert(a.end(), {act_p_[i * cylinders_.size() + c], act_f_[i * cylinders_.size() + c]});
      a.push_back(act_supply_[i]);
    }
  }
  {
    std::lock_guard<std::mutex> lock(cmd_mutex_);
    for (std::size_t i = 0; i < cmd_t_.size(); ++i) {
      if (cmd_t_[i] < t0 || cmd_t_[i] > t1) continue;
      v.push_back(cmd_t_[i] - t0);
      for (int c : pc) v.push_back(cmd_v_[i * cylinders_.size() + c]);
    }
  }
  auto write = [&](const std::string& file, const std::string& header, const std::vector<double>& rows,
                   std::size_t width) {
    std::ofstream out = open(file);
    out << header << '\n';
    for (std::size_t i = 0; i + width <= rows.size(); i += width) {
      out << rows[i];
      for (std::size_t k = 1; k < width; ++k) out << ',' << rows[i + k];
      out << '\n';
    }
  };
  std::string hq = "t", ha = "t", hv = "t";
  for (const auto& j : joints) hq += "," + j;
  for (const auto& c : cylinders) ha += ",p_" + c + ",f_" + c, hv += "," + c;
  write(e + "_joints.csv", hq, q, 1 + pj.size());
  write(e + "_actuators.csv", ha + ",supply", a, 2 + 2 * pc.size());
  write(e + "_commands.csv", hv, v, 1 + pc.size());
}

void Characteriser::writeReport() {
  report_.duration = now();
  report_.limiter_interventions = limiter_interventions_.load();
  {
    std::lock_guard<std::mutex> lock(data_mutex_);
    report_.driver = driver_kind_;
  }
  open("summary.csv") << ch::summaryCsv(report_);
  report_.plots.clear();
  if (o_.plot) {
    // An argument vector, never a shell: the paths come from parameters.
    adroit::ProgramOptions options;
    options.timeout_s = kPlotTimeout;
    options.capture_output = true;
    options.merge_stderr = true;
    const adroit::ProgramResult r = adroit::runProgram({"/usr/bin/python3", o_.plot_script, o_.output_dir}, options);
    open("plot.log") << r.output << (r.ok() ? "" : r.describe() + "\n");
    if (!r.ok()) report_.plot_error = "the plot script failed (" + r.describe() + "), see plot.log";
    for (const char* png : {"bang_bang.png", "limit_to_limit.png", "reflex.png", "step.png", "chirp.png"})
      if (std::filesystem::is_regular_file(o_.output_dir + "/" + png)) report_.plots.push_back(png);
  }
  open("report.md") << ch::reportMarkdown(report_);
}

int Characteriser::run() {
  std::error_code error;
  std::filesystem::create_directories(o_.output_dir, error);
  if (error || !std::filesystem::is_directory(o_.output_dir))
    throw Refused("cannot create ~output_dir " + o_.output_dir + (error ? " (" + error.message() + ")" : ""));
  char started[32];
  const std::time_t t = std::time(nullptr);
  std::strftime(started, sizeof started, "%Y-%m-%d %H:%M:%S", std::localtime(&t));
  report_.started = started;
  report_.quick = o_.quick;
  report_.rate = o_.rate;
  report_.scene = scene_;
  ROS_INFO("%s: driver up (%s), running %zu experiments into %s", kNode, driver_kind_.c_str(), o_.experiments.size(),
           o_.output_dir.c_str());
  int code = 0;
  startCommanding();
  try {
    current_ = "arm hold";
    holdArm();
    for (const auto& e : o_.experiments) {
      current_ = e;
      const auto others = otherCommanders();
      if (!others.empty()) throw Aborted(others.front() + " started publishing /adroit/valve_command before " + e);
      if (e == "bang_bang")
        bangBang();
      else if (e == "limit_to_limit")
        limitToLimit();
      else if (e == "reflex")
        reflex();
      else if (e == "step")
        step();
      else if (e == "chirp")
        chirp();
      else if (e == "force")
        force();
      report_.experiments_run.push_back(e);
      rest(0.5);
    }
    current_ = "arm release";
    releaseArm();
  } catch (const std::exception& a) {  // Aborted, or a file that cannot be written
    report_.aborted = a.what();
    ROS_ERROR("%s: aborted: %s", kNode, a.what());
    code = 2;
  }
  exhaust();
  writeReport();
  ROS_INFO("%s: report %s/report.md (%.1f s); the driver's watchdog takes over now that the commands stop", kNode,
           o_.output_dir.c_str(), now());
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, kNode, ros::init_options::NoSigintHandler);
  signal(SIGINT, onSignal);
  signal(SIGTERM, onSignal);
  ros::NodeHandle pnh("~");
  int code = 0;
  try {
    const Params prm(pnh);
    adroit::LoadedModel loaded;
    std::vector<ch::JointPair> pairs;
    try {
      loaded = adroit::loadModelFile(prm.modelPath("arm_hand"));
      pairs = ch::jointPairs(loaded.model.get());
    } catch (const adroit::rosutil::ParameterError&) {
      throw;
    } catch (const std::exception& e) {
      prm.fail(prm.has("model_file") ? "model_file" : "scene", e.what());
    }
    const Options options = readOptions(pnh, prm, loaded.model.get(), pairs);
    Characteriser tool(options, prm.has("model_file") ? prm.string("model_file", "") : prm.string("scene", "arm_hand"),
                       loaded.model.get(), pairs);
    tool.connect();
    code = tool.run();
  } catch (const std::exception& e) {
    // One line: a refusal or a bad parameter.
    std::fprintf(stderr, "[FATAL] %s: %s\n", kNode, e.what());
    code = 1;
  }
  ros::shutdown();
  return code;
}
