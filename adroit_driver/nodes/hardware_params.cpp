// ~parameters of the hardware driver -> DriverParams + CanRobotConfig, refusing bad values with
// one line that names the parameter; makeHardwareDriver builds the hardware driver from them.
#include <chrono>
#include <set>
#include <thread>

#include "adroit_driver/can_calibration.h"
#include "adroit_driver/can_robot.h"
#include "adroit_driver/simulated_robot.h"
#include "robot_driver.h"

namespace adroit::driver {

namespace {

// The buses in the layout's order (docs/can_protocol.md section 1): palm, act0, act1, ...
// No defaults: a hardware port is never guessed (DESIGN §4).
std::vector<std::string> readBuses(const rosutil::Params& p) {
  std::vector<std::string> names{"palm"};
  for (int i = 0; p.has("buses/act" + std::to_string(i)); ++i) names.push_back("act" + std::to_string(i));
  std::set<std::string> allowed(names.begin(), names.end());
  if (!p.has("buses")) p.fail("buses", "is required: one endpoint per bus, e.g. {palm: can0, act0: can1, ...}");
  p.checkKeys("buses", allowed);
  std::vector<std::string> endpoints;
  for (const auto& n : names) {
    const std::string endpoint = p.string("buses/" + n, "");
    if (endpoint.empty()) p.fail("buses/" + n, "is required: the interface (can0) or emulator bus (unix:<path>)");
    endpoints.push_back(endpoint);
  }
  return endpoints;
}

// The calibration file names joints and cylinders: their names come from the model, as the
// robot will list them (the simulation of the same model lists the same names).
can::Calibration readCalibration(const rosutil::Params& p, const std::string& model_path) {
  const std::string file = p.string("calibration", "");
  SimConfig names_only;
  names_only.model_path = model_path;
  names_only.sensors.enabled = false;
  const SimulatedRobot model(names_only);
  if (file.empty()) return can::identityCalibration(model.jointNames().size(), model.cylinderNames().size());
  try {
    return can::loadCalibration(file, model.jointNames(), model.cylinderNames());
  } catch (const std::invalid_argument& e) {
    p.fail("calibration", e.what());
  }
}

}  // namespace

// The keys readCanRobotConfig and makeHardwareDriver read (modelPath: scene, model_file; the
// wrapper's are driverKeys(false)); keep in step with them.
const std::set<std::string> kHardwareKeys{
    "scene", "model_file", "buses", "calibration", "timestep", "control_period", "watchdog_timeout",
    "startup_timeout", "start_in_safe_state", "joint_velocity_cutoff", "length_rate_cutoff", "supply_pressure",
    "joint_period", "silent_periods", "sensor_period", "connect_timeout"};

CanRobotConfig readCanRobotConfig(const rosutil::Params& p) {
  CanRobotConfig c;
  c.model_path = p.modelPath("arm_hand");
  c.buses = readBuses(p);
  c.timestep = p.number("timestep", c.timestep);
  c.control_period = p.number("control_period", c.control_period);
  c.watchdog_timeout = p.number("watchdog_timeout", c.watchdog_timeout);
  c.startup_timeout = p.number("startup_timeout", c.startup_timeout, 0.1, 60);
  c.start_in_safe_state = p.boolean("start_in_safe_state", c.start_in_safe_state);
  c.joint_velocity_cutoff = p.number("joint_velocity_cutoff", c.joint_velocity_cutoff);
  c.length_rate_cutoff = p.number("length_rate_cutoff", c.length_rate_cutoff);
  c.supply_pressure = p.number("supply_pressure", c.supply_pressure);
  c.joint_period = p.number("joint_period", c.joint_period);
  c.silent_periods = p.integer("silent_periods", c.silent_periods, 3, 20);
  c.sensor_period = p.number("sensor_period", c.sensor_period);
  const std::string invalid = validate(c);
  if (!invalid.empty()) throw ParameterError("bad parameter " + invalid);
  try {
    c.calibration = readCalibration(p, c.model_path);
  } catch (const std::runtime_error& e) {
    if (dynamic_cast<const ParameterError*>(&e)) throw;
    throw ParameterError(std::string("bad parameter ~scene/~model_file: ") + e.what());
  }
  return c;
}

std::unique_ptr<RobotDriver> makeHardwareDriver(ros::NodeHandle nh, ros::NodeHandle pnh) {
  const rosutil::Params p(pnh);
  // A misspelt key would silently run at its default: refuse every key nobody reads.
  std::set<std::string> keys = driverKeys(false);
  keys.insert(kHardwareKeys.begin(), kHardwareKeys.end());
  p.checkKeys("", keys);
  CanRobotConfig config = readCanRobotConfig(p);
  DriverParams params = readDriverParams(p, false);
  // The buses may come up after the driver (an emulator starting in the same launch, an
  // interface being configured): retry opening them for ~connect_timeout, then report why not.
  const double connect_timeout = p.number("connect_timeout", 10.0, 0, 600);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(connect_timeout);
  std::unique_ptr<Robot> robot;
  for (int attempt = 1;; ++attempt) {
    try {
      robot = std::make_unique<CanRobot>(config);
      break;
    } catch (const std::invalid_argument& e) {
      throw ParameterError(std::string("bad parameter ") + e.what());
    } catch (const std::exception& e) {
      if (std::chrono::steady_clock::now() >= deadline)
        throw std::runtime_error(std::string("the robot did not come up within ~connect_timeout ") +
                                 std::to_string(connect_timeout) + " s: " + e.what());
      ROS_WARN_THROTTLE(2.0, "adroit_hw: attempt %d: %s (retrying)", attempt, e.what());
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  }
  return std::make_unique<RobotDriver>(nh, std::move(params), std::move(robot), "adroit_hw");
}

}  // namespace adroit::driver
