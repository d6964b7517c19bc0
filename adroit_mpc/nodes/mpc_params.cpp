// ~parameters of the MPC node -> MpcParams, refusing bad values with one line that names
// the parameter (defaults in config/mpc.yaml, task parameters in config/tasks/<task>.yaml).
#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

#include "mpc_ros.h"

namespace adroit::mpc_node {

namespace {

const std::vector<std::string> kTasks = {"catch", "relocate", "type"};

// The scene each task is built for (its objects and sites).
std::string sceneOfTask(const std::string& task) {
  if (task == "catch") return "bottle";
  if (task == "relocate") return "ball";
  return "keypad";
}

// ~tasks/<name>: a flat map of numbers, number lists and strings (the task validates keys).
adroit_mpc::TaskParams readTaskParams(const rosutil::Params& p, const ros::NodeHandle& pnh, const std::string& ns) {
  adroit_mpc::TaskParams out;
  XmlRpc::XmlRpcValue v;
  if (!pnh.getParam(ns, v)) return out;
  if (v.getType() != XmlRpc::XmlRpcValue::TypeStruct) p.fail(ns, "expected a map of task parameters");
  for (auto& kv : v) {
    XmlRpc::XmlRpcValue& x = kv.second;
    const std::string key = ns + "/" + kv.first;
    switch (x.getType()) {
      case XmlRpc::XmlRpcValue::TypeDouble:
        out.numbers[kv.first] = static_cast<double>(x);
        break;
      case XmlRpc::XmlRpcValue::TypeInt:
        out.numbers[kv.first] = static_cast<int>(x);
        break;
      case XmlRpc::XmlRpcValue::TypeBoolean:
        out.numbers[kv.first] = static_cast<bool>(x) ? 1.0 : 0.0;
        break;
      case XmlRpc::XmlRpcValue::TypeString:
        out.strings[kv.first] = static_cast<std::string>(x);
        break;
      case XmlRpc::XmlRpcValue::TypeArray: {
        std::vector<double> values;
        for (int i = 0; i < x.size(); ++i) {
          if (x[i].getType() == XmlRpc::XmlRpcValue::TypeDouble)
            values.push_back(static_cast<double>(x[i]));
          else if (x[i].getType() == XmlRpc::XmlRpcValue::TypeInt)
            values.push_back(static_cast<int>(x[i]));
          else
            p.fail(key, "expected a list of numbers");
        }
        out.vectors[kv.first] = values;
        break;
      }
      default:
        p.fail(key, "expected a number, a list of numbers or a string");
    }
  }
  return out;
}

}  // namespace

MpcParams readParams(const ros::NodeHandle& pnh) {
  const rosutil::Params p(pnh);
  std::set<std::string> keys = {"scene", "model_file", "task", "tasks", "planner", "mode", "threads", "horizon", "dt",
                                 "iterations", "synergies", "derivative_skip", "samples", "noise_scale",
                                 "cem_elites", "cem_std_initial", "cem_std_min",
                                 "control_rate", "state_timeout", "feedback_scale", "marker_rate",
                                 "diagnostics_period", "nice", "control_priority", "lockstep", "physics_timestep", "lockstep_controls_per_plan",
                                 "min_tension", "latency_compensation", "fd_warmstart", "fd_force_space",
                                 "derivative_max_age", "derivative_reuse_tolerance",
                                 "tension_step_weight"};
  // dynamic_reconfigure keeps its values (task weights) among the private parameters too.
  for (const auto& d : adroit_mpc::MpcConfig::__getParamDescriptions__()) keys.insert(d->name);
  p.checkKeys("", keys);
  MpcParams out;
  out.task = p.string("task", "relocate");
  if (std::find(kTasks.begin(), kTasks.end(), out.task) == kTasks.end())
    p.fail("task", "unknown task '" + out.task + "' (known: catch, relocate, type)");
  out.scene = p.string("scene", sceneOfTask(out.task));
  out.model_file = p.modelPath(out.scene, true);

  out.planner = p.string("planner", "ilqg");
  try {
    adroit_mpc::makePlanner(out.planner);  // the core's names, in its one-line refusal
  } catch (const std::invalid_argument& e) {
    p.fail("planner", e.what());
  }
  const std::string mode = p.string("mode", "force");
  if (mode != "force" && mode != "pneumatic") p.fail("mode", "must be 'force' or 'pneumatic', got '" + mode + "'");
  out.force_mode = mode == "force";

  adroit_mpc::PlannerSettings& s = out.settings;
  s.threads = p.integer("threads", s.threads, 0, 64);
  // The task's hints (config/tasks/<task>.yaml: typing plans 0.2 s at 10 ms) unless set here.
  p.checkKeys("tasks", std::set<std::string>(kTasks.begin(), kTasks.end()));
  for (const auto& t : kTasks) out.tasks[t] = readTaskParams(p, pnh, "tasks/" + t);
  const auto& hints = out.tasks[out.task].numbers;
  const auto hint = [&](const char* key, double fallback) {
    const auto it = hints.find(key);
    return it == hints.end() ? fallback : it->second;
  };
  s.horizon = p.number("horizon", hint("horizon", s.horizon), 0.01, 5.0);
  s.dt = p.number("dt", hint("planner_dt", s.dt), 1e-4, 0.1);
  if (s.horizon < 2 * s.dt) p.fail("horizon", "must span at least two knots of ~dt");
  s.iterations = p.integer("iterations", s.iterations, 1, 100);
  s.synergies = p.boolean("synergies", s.synergies);
  s.derivative_skip = p.integer("derivative_skip", static_cast<int>(hint("derivative_skip", s.derivative_skip)), 1, 100);
  s.fd_warmstart = p.boolean("fd_warmstart", s.fd_warmstart);
  s.fd_force_space = p.boolean("fd_force_space", s.fd_force_space);
  s.derivative_max_age = p.number("derivative_max_age", s.derivative_max_age, 0.0, 10.0);
  s.derivative_reuse_tolerance = p.number("derivative_reuse_tolerance", s.derivative_reuse_tolerance, 1e-9, 1e3);
  s.samples = p.integer("samples", s.samples, 1, 4096);
  s.noise_scale = p.number("noise_scale", s.noise_scale, 0.0, 10.0);
  s.cem_elites = p.integer("cem_elites", s.cem_elites, 1, s.samples);
  s.cem_std_initial = p.number("cem_std_initial", s.cem_std_initial, 1e-4, 10.0);
  s.cem_std_min = p.number("cem_std_min", s.cem_std_min, 1e-4, s.cem_std_initial);
  s.tension_step_weight = p.number("tension_step_weight", s.tension_step_weight, 0.0, 1e6);
  out.feedback_scale = p.number("feedback_scale", hint("feedback_scale", out.feedback_scale), 0.0, 1.0);
  s.feedback_scale = out.feedback_scale;
  out.latency_compensation = p.boolean("latency_compensation", hint("latency_compensation", 0.0) > 0.5);

  out.control_rate = p.number("control_rate", out.control_rate, 1.0, 2000.0);
  out.state_timeout = p.number("state_timeout", out.state_timeout, 0.005, 10.0);
  out.marker_rate = p.number("marker_rate", out.marker_rate, 0.0, 60.0);
  out.diagnostics_period = p.number("diagnostics_period", out.diagnostics_period, 0.05, 60.0);
  out.nice = p.integer("nice", out.nice, 0, 19);
  out.control_priority = p.integer("control_priority", out.control_priority, 0, 98);
  out.lockstep = p.boolean("lockstep", out.lockstep);
  out.physics_timestep = p.number("physics_timestep", out.physics_timestep, 1e-5, 0.1);
  out.lockstep_controls_per_plan = p.integer("lockstep_controls_per_plan", out.lockstep_controls_per_plan, 1, 1000);
  out.min_tension = p.number("min_tension", out.min_tension, 0.0, 5.0);

  return out;
}

}  // namespace adroit::mpc_node
