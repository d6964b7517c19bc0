// ~parameters of the simulation driver -> DriverParams + SimConfig, refusing bad values with
// one line that names the parameter; makeSimDriver builds the simulation driver from them.
#include <ros/param.h>

#include <cmath>
#include <cstdio>

#include "adroit_driver/simulated_robot.h"
#include "robot_driver.h"
#include "adroit_core/number_text.h"

namespace adroit::driver {

using adroit::shortNumber;  // a huge value stays a short line

int stepsPerPublication(const std::string& name, double rate, double timestep) {
  if (!(rate > 0) || !std::isfinite(rate))
    throw ParameterError("bad parameter ~" + name + ": must be > 0 Hz, got " + shortNumber(rate));
  const double ratio = 1.0 / (rate * timestep);
  const int steps = static_cast<int>(std::lround(ratio));
  if (steps < 1 || std::abs(ratio - steps) > 1e-6)
    throw ParameterError("bad parameter ~" + name + ": must be the step rate " + shortNumber(1.0 / timestep) +
                         " Hz divided by a whole number, got " + shortNumber(rate));
  return steps;
}

// The keys readSimConfig reads (modelPath: scene, model_file); keep in step with it.
const std::set<std::string> kSimConfigKeys{
    "scene", "model_file", "mode", "timestep", "watchdog_timeout", "min_tension", "supply_pressure",
    "initial_keyframe", "max_reset_distance", "max_reset_velocity", "reset_range_margin", "max_base_speed",
    "max_base_angular_speed", "sensor_realism", "seed", "sensors"};
const std::set<std::string> kSensorKeys{
    "joint_rate", "joint_noise_std", "joint_velocity_noise_std", "joint_quantum", "joint_delay", "slide_noise_std",
    "slide_velocity_noise_std", "slide_quantum", "cylinder_delay", "pressure_noise_std", "length_noise_std",
    "touch_noise_std", "touch_delay", "object_noise_std", "object_delay"};

SimConfig readSimConfig(const rosutil::Params& p) {
  SimConfig c;
  c.model_path = p.modelPath("arm_hand");
  const std::string mode = p.string("mode", "pneumatic");
  const auto parsed = parseMode(mode);
  if (!parsed) p.fail("mode", "must be 'pneumatic' or 'force', got '" + mode + "'");
  c.mode = *parsed;
  c.timestep = p.number("timestep", c.timestep);
  c.watchdog_timeout = p.number("watchdog_timeout", c.watchdog_timeout);
  c.min_tension = p.number("min_tension", c.min_tension);
  c.supply_pressure = p.number("supply_pressure", c.supply_pressure);
  c.initial_keyframe = p.string("initial_keyframe", c.initial_keyframe);
  c.max_reset_distance = p.number("max_reset_distance", c.max_reset_distance);
  c.max_reset_velocity = p.number("max_reset_velocity", c.max_reset_velocity);
  c.reset_range_margin = p.number("reset_range_margin", c.reset_range_margin);
  c.max_base_speed = p.number("max_base_speed", c.max_base_speed);
  c.max_base_angular_speed = p.number("max_base_angular_speed", c.max_base_angular_speed);
  SensorRealism& s = c.sensors;
  s.enabled = p.boolean("sensor_realism", s.enabled);
  s.seed = static_cast<std::uint64_t>(p.integer("seed", static_cast<int>(s.seed), 0, 2147483647));
  s.joint_rate = p.number("sensors/joint_rate", s.joint_rate);
  s.joint_noise_std = p.number("sensors/joint_noise_std", s.joint_noise_std);
  s.joint_velocity_noise_std = p.number("sensors/joint_velocity_noise_std", s.joint_velocity_noise_std);
  s.joint_quantum = p.number("sensors/joint_quantum", s.joint_quantum);
  s.joint_delay = p.number("sensors/joint_delay", s.joint_delay);
  s.slide_noise_std = p.number("sensors/slide_noise_std", s.slide_noise_std);
  s.slide_velocity_noise_std = p.number("sensors/slide_velocity_noise_std", s.slide_velocity_noise_std);
  s.slide_quantum = p.number("sensors/slide_quantum", s.slide_quantum);
  s.cylinder_delay = p.number("sensors/cylinder_delay", s.cylinder_delay);
  s.cylinder.pressure_noise_std = p.number("sensors/pressure_noise_std", s.cylinder.pressure_noise_std);
  s.cylinder.length_noise_std = p.number("sensors/length_noise_std", s.cylinder.length_noise_std);
  s.touch_noise_std = p.number("sensors/touch_noise_std", s.touch_noise_std);
  s.touch_delay = p.number("sensors/touch_delay", s.touch_delay);
  s.object_noise_std = p.number("sensors/object_noise_std", s.object_noise_std);
  s.object_delay = p.number("sensors/object_delay", s.object_delay);
  const std::string invalid = validate(c);
  if (!invalid.empty()) throw ParameterError("bad parameter " + invalid);
  return c;
}

// The keys readDriverParams reads; keep in step with it.
std::set<std::string> driverKeys(bool simulated) {
  std::set<std::string> keys{"joint_state_rate", "actuator_state_rate", "touch_rate", "object_rate", "marker_rate",
                             "realtime_priority", "lockstep_nice", "diagnostics_period", "never_commanded_grace"};
  if (simulated) keys.insert({"realtime", "start_paused", "physics_priority"});
  return keys;
}

DriverParams readDriverParams(const rosutil::Params& p, bool simulated) {
  DriverParams out;
  if (simulated) {
    out.realtime = p.boolean("realtime", out.realtime);
    out.start_paused = p.boolean("start_paused", out.start_paused);
    out.physics_priority = p.integer("physics_priority", out.physics_priority, 0, 99);
    ros::param::param<bool>("/use_sim_time", out.use_sim_time, false);
    if (!out.realtime && !out.use_sim_time)
      p.fail("realtime", "false (lockstep) needs /use_sim_time: true so that every node follows /clock");
  } else {
    bool sim_time = false;
    ros::param::param<bool>("/use_sim_time", sim_time, false);
    if (sim_time) throw ParameterError("bad parameter /use_sim_time: true, but a real robot runs on wall time");
  }
  out.joint_state_rate = p.number("joint_state_rate", out.joint_state_rate);
  out.actuator_state_rate = p.number("actuator_state_rate", out.actuator_state_rate);
  out.touch_rate = p.number("touch_rate", out.touch_rate);
  out.object_rate = p.number("object_rate", out.object_rate);
  out.marker_rate = p.number("marker_rate", out.marker_rate, 0, 100);
  out.realtime_priority = p.integer("realtime_priority", out.realtime_priority, 0, 99);
  out.lockstep_nice = p.integer("lockstep_nice", out.lockstep_nice, -20, 0);
  out.diagnostics_period = p.number("diagnostics_period", out.diagnostics_period, 0.05, 60);
  out.never_commanded_grace = p.number("never_commanded_grace", out.never_commanded_grace, 0, 3600);
  return out;
}

std::unique_ptr<RobotDriver> makeSimDriver(ros::NodeHandle nh, ros::NodeHandle pnh) {
  const rosutil::Params p(pnh);
  // A misspelt key would silently run at its default: refuse every key nobody reads.
  std::set<std::string> keys = driverKeys(true);
  keys.insert(kSimConfigKeys.begin(), kSimConfigKeys.end());
  p.checkKeys("", keys);
  p.checkKeys("sensors", kSensorKeys);
  const SimConfig config = readSimConfig(p);
  DriverParams params = readDriverParams(p, true);
  std::unique_ptr<Robot> robot;
  try {
    robot = std::make_unique<SimulatedRobot>(config);
  } catch (const std::invalid_argument& e) {
    throw ParameterError(std::string("bad parameter ") + e.what());
  } catch (const std::runtime_error& e) {  // ModelLoadError and cylinder table errors
    throw ParameterError(std::string("bad parameter ~scene/~model_file: ") + e.what());
  }
  ROS_INFO("adroit_sim: sensor realism %s (seed %lu)", config.sensors.enabled ? "on" : "off",
           static_cast<unsigned long>(config.sensors.seed));
  return std::make_unique<RobotDriver>(nh, std::move(params), std::move(robot), "adroit_sim");
}

}  // namespace adroit::driver
