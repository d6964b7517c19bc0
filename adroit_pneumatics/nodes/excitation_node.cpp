// excitation_node: publishes identification commands (steps from either extreme, slow
// sweep, low-passed random, chirp; adroit_pneumatics/excitation.h) as ValveCommand for a
// set of cylinders at ~rate, for ~duration seconds, then commands exhaust and exits.
// Record with: rosbag record /adroit/actuator_states /adroit/valve_command
#include <algorithm>
#include <exception>
#include <stdexcept>
#include <string>
#include <vector>

#include <ros/package.h>
#include <ros/ros.h>

#include <adroit_msgs/ValveCommand.h>

#include "adroit_description/scenes.h"
#include "adroit_pneumatics/excitation.h"
#include "adroit_pneumatics/pool.h"

using namespace adroit::pneumatics;

namespace {

// Reads ~key with a type check; a wrong type throws one line naming the parameter.
template <typename T>
T param(const ros::NodeHandle& pnh, const std::string& key, const T& fallback) {
  if (!pnh.hasParam(key)) return fallback;
  T value;
  if (!pnh.getParam(key, value)) throw std::runtime_error("bad parameter " + pnh.resolveName(key) + ": wrong type");
  return value;
}
// Integer parameters are accepted where a number is expected.
double number(const ros::NodeHandle& pnh, const std::string& key, double fallback) {
  if (!pnh.hasParam(key)) return fallback;
  double d;
  if (pnh.getParam(key, d)) return d;
  int i;
  if (pnh.getParam(key, i)) return i;
  throw std::runtime_error("bad parameter " + pnh.resolveName(key) + ": expected a number");
}

void publish(ros::Publisher& pub, const std::vector<std::string>& names, const std::vector<double>& volts) {
  adroit_msgs::ValveCommand msg;
  msg.header.stamp = ros::Time::now();
  msg.name = names;
  msg.volts = volts;
  pub.publish(msg);
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "excitation");
  ros::NodeHandle nh, pnh("~");
  std::vector<std::string> names;
  std::vector<Excitation> generators;
  double rate = 200, duration = 0;
  try {
    std::string model_file = param<std::string>(pnh, "model_file", "");
    if (model_file.empty())
      model_file = adroit::description::sceneFile(ros::package::getPath("adroit_description"),
                                                  param<std::string>(pnh, "scene", "arm_hand"));
    std::vector<std::string> known;
    for (const auto& c : loadModelCylinders(model_file)) known.push_back(c.name);
    names = param<std::vector<std::string>>(pnh, "cylinders", {});
    if (names.empty()) throw std::runtime_error("bad parameter " + pnh.resolveName("cylinders") + ": required (list of names)");
    for (const auto& n : names) {
      if (std::find(known.begin(), known.end(), n) == known.end())
        throw std::runtime_error("bad parameter " + pnh.resolveName("cylinders") + ": unknown cylinder '" + n + "'");
    }
    ExcitationParams p;
    p.kind = param<std::string>(pnh, "kind", p.kind);
    p.amplitude = number(pnh, "amplitude", p.amplitude);
    p.step_hold = number(pnh, "step_hold", p.step_hold);
    p.sweep_period = number(pnh, "sweep_period", p.sweep_period);
    p.cutoff_hz = number(pnh, "cutoff_hz", p.cutoff_hz);
    p.random_hold = number(pnh, "random_hold", p.random_hold);
    p.chirp_f0 = number(pnh, "chirp_f0", p.chirp_f0);
    p.chirp_f1 = number(pnh, "chirp_f1", p.chirp_f1);
    p.chirp_duration = number(pnh, "chirp_duration", p.chirp_duration);
    const int seed = param<int>(pnh, "seed", 1);
    try {
      p.validate();
    } catch (const std::exception& e) {
      // The core names the field after an "excitation: " prefix.
      std::string what = e.what();
      if (what.rfind("excitation: ", 0) == 0) what = what.substr(12);
      throw std::runtime_error("bad parameter " + pnh.getNamespace() + "/" + what);
    }
    rate = number(pnh, "rate", rate);
    duration = number(pnh, "duration", duration);
    if (!(rate > 0 && rate <= 2000)) throw std::runtime_error("bad parameter " + pnh.resolveName("rate") + ": must be in (0, 2000]");
    if (!(duration >= 0)) throw std::runtime_error("bad parameter " + pnh.resolveName("duration") + ": must be >= 0 (0 = until shutdown)");
    // Independent random streams per cylinder, reproducible from the seed.
    for (std::size_t i = 0; i < names.size(); ++i) {
      p.seed = static_cast<std::uint64_t>(seed) + i;
      generators.emplace_back(p);
    }
    ROS_INFO("%s: %s excitation of %zu cylinders at %.0f Hz%s", ros::this_node::getName().c_str(), p.kind.c_str(),
             names.size(), rate, duration > 0 ? (" for " + std::to_string(duration) + " s").c_str() : "");
  } catch (const std::exception& e) {
    ROS_FATAL("%s: %s", ros::this_node::getName().c_str(), e.what());
    return 1;
  }

  ros::Publisher pub = nh.advertise<adroit_msgs::ValveCommand>("/adroit/valve_command", 10);
  const double dt = 1.0 / rate;
  std::vector<double> volts(names.size(), 0.0);
  ros::Rate loop(rate);
  const ros::Time start = ros::Time::now();
  for (long k = 0; ros::ok(); ++k) {
    const double t = k * dt;
    if (duration > 0 && t >= duration) break;
    for (std::size_t i = 0; i < names.size(); ++i) volts[i] = std::clamp(generators[i].next(t, dt), -5.0, 5.0);
    publish(pub, names, volts);
    ros::spinOnce();
    loop.sleep();
  }
  // Leave the cylinders vented, not at the last excitation level.
  std::fill(volts.begin(), volts.end(), -5.0);
  if (ros::ok()) publish(pub, names, volts);
  ROS_INFO("%s: done after %.1f s", ros::this_node::getName().c_str(), (ros::Time::now() - start).toSec());
  ros::Duration(0.2).sleep();  // let the last message go out
  return 0;
}
