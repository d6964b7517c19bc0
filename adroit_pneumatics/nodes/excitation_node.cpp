// excitation_node: publishes identification commands (steps from either extreme, slow
// sweep, low-passed random, chirp; adroit_pneumatics/excitation.h) as ValveCommand for a
// set of cylinders at ~rate, for ~duration seconds, then commands exhaust and exits.
// Record with: rosbag record /adroit/actuator_states /adroit/valve_command
#include <algorithm>
#include <exception>
#include <stdexcept>
#include <string>
#include <vector>

#include <ros/ros.h>

#include <adroit_msgs/ValveCommand.h>

#include "adroit_pneumatics/excitation.h"
#include "adroit_pneumatics/pool.h"
#include "adroit_ros/params.h"

using namespace adroit::pneumatics;
using adroit::rosutil::Params;

namespace {

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
    const Params prm(pnh);
    const std::string model_file = prm.modelPath("arm_hand");
    std::vector<std::string> known;
    try {
      for (const auto& c : loadModelCylinders(model_file)) known.push_back(c.name);
    } catch (const std::exception& e) {
      prm.fail(prm.has("model_file") ? "model_file" : "scene", e.what());
    }
    names = prm.strings("cylinders");
    if (names.empty()) prm.fail("cylinders", "required (list of names)");
    for (const auto& n : names) {
      if (std::find(known.begin(), known.end(), n) == known.end()) prm.fail("cylinders", "unknown cylinder '" + n + "'");
    }
    ExcitationParams p;
    p.kind = prm.string("kind", p.kind);
    p.amplitude = prm.number("amplitude", p.amplitude);
    p.step_hold = prm.number("step_hold", p.step_hold);
    p.sweep_period = prm.number("sweep_period", p.sweep_period);
    p.cutoff_hz = prm.number("cutoff_hz", p.cutoff_hz);
    p.random_hold = prm.number("random_hold", p.random_hold);
    p.chirp_f0 = prm.number("chirp_f0", p.chirp_f0);
    p.chirp_f1 = prm.number("chirp_f1", p.chirp_f1);
    p.chirp_duration = prm.number("chirp_duration", p.chirp_duration);
    const int seed = prm.integer("seed", 1);
    try {
      p.validate();
    } catch (const std::exception& e) {
      // The core names the field after an "excitation: " prefix.
      std::string what = e.what();
      if (what.rfind("excitation: ", 0) == 0) what = what.substr(12);
      throw std::runtime_error("bad parameter " + pnh.getNamespace() + "/" + what);
    }
    rate = prm.number("rate", rate, 1e-3, 2000.0);
    duration = prm.number("duration", duration, 0.0, 1e9);  // 0 = until shutdown
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
