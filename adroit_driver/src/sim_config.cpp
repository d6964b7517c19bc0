#include "adroit_driver/sim_config.h"

#include <cmath>
#include <sstream>

namespace adroit::driver {

std::optional<ActuationMode> parseMode(const std::string& text) {
  if (text == "pneumatic") return ActuationMode::kPneumatic;
  if (text == "force") return ActuationMode::kForce;
  return std::nullopt;
}

const char* modeName(ActuationMode mode) { return mode == ActuationMode::kPneumatic ? "pneumatic" : "force"; }

namespace {
template <typename T>
std::string describe(const std::string& param, const std::string& rule, T value) {
  std::ostringstream out;
  out << param << " must be " << rule << ", got " << value;
  return out.str();
}
bool positiveFinite(double v) { return std::isfinite(v) && v > 0; }
bool nonNegativeFinite(double v) { return std::isfinite(v) && v >= 0; }
}  // namespace

std::string validate(const SimConfig& c) {
  if (c.model_path.empty()) return "~scene (or ~model_file) must name a model";
  if (!positiveFinite(c.timestep) || c.timestep > 0.01) return describe("~timestep", "in (0, 0.01] s", c.timestep);
  if (!(c.watchdog_timeout >= kMinWatchdogTimeout && c.watchdog_timeout <= kMaxWatchdogTimeout))
    return describe("~watchdog_timeout", "in [0.01, 0.2] s", c.watchdog_timeout);
  if (!nonNegativeFinite(c.min_tension) || c.min_tension > 5.0)
    return describe("~min_tension", "in [0, 5] N", c.min_tension);
  if (!(c.supply_pressure > 150e3 && c.supply_pressure <= 1e6))
    return describe("~supply_pressure", "in (150e3, 1e6] Pa absolute", c.supply_pressure);
  if (!positiveFinite(c.max_reset_distance))
    return describe("~max_reset_distance", "> 0 and finite (m)", c.max_reset_distance);
  if (!positiveFinite(c.max_reset_velocity))
    return describe("~max_reset_velocity", "> 0 and finite (rad/s or m/s)", c.max_reset_velocity);
  if (!(c.reset_range_margin >= 0 && c.reset_range_margin <= 1))
    return describe("~reset_range_margin", "in [0, 1] (fraction of a joint's range)", c.reset_range_margin);
  if (!positiveFinite(c.max_base_speed)) return describe("~max_base_speed", "> 0 and finite (m/s)", c.max_base_speed);
  if (!positiveFinite(c.max_base_angular_speed))
    return describe("~max_base_angular_speed", "> 0 and finite (rad/s)", c.max_base_angular_speed);
  const SensorRealism& s = c.sensors;
  if (!positiveFinite(s.joint_rate) || s.joint_rate > 10000)
    return describe("~sensors/joint_rate", "in (0, 10000] Hz", s.joint_rate);
  const struct {
    const char* name;
    double value;
  } non_negative[] = {
      {"~sensors/joint_noise_std", s.joint_noise_std},
      {"~sensors/joint_velocity_noise_std", s.joint_velocity_noise_std},
      {"~sensors/joint_quantum", s.joint_quantum},
      {"~sensors/slide_noise_std", s.slide_noise_std},
      {"~sensors/slide_velocity_noise_std", s.slide_velocity_noise_std},
      {"~sensors/slide_quantum", s.slide_quantum},
      {"~sensors/joint_delay", s.joint_delay},
      {"~sensors/cylinder_delay", s.cylinder_delay},
      {"~sensors/touch_noise_std", s.touch_noise_std},
      {"~sensors/touch_delay", s.touch_delay},
      {"~sensors/object_noise_std", s.object_noise_std},
      {"~sensors/object_delay", s.object_delay},
      {"~sensors/pressure_noise_std", s.cylinder.pressure_noise_std},
      {"~sensors/length_noise_std", s.cylinder.length_noise_std},
  };
  for (const auto& p : non_negative)
    if (!nonNegativeFinite(p.value)) return describe(p.name, ">= 0 and finite", p.value);
  for (double delay : {s.joint_delay, s.cylinder_delay, s.touch_delay, s.object_delay})
    if (delay > 0.5) return describe("~sensors/*_delay", "<= 0.5 s", delay);
  return "";
}

}  // namespace adroit::driver
