// Configuration of the simulated robot (ROS-free). Every field has the name of the ROS
// parameter that sets it, so validation errors name the parameter the user must fix.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "adroit_pneumatics/sensor_model.h"

namespace adroit::driver {

enum class ActuationMode {
  kPneumatic,  // valve volts -> plant -> tension (p - p_atm) * bore area
  kForce,      // ideal pull-only tendon-force actuators (thesis 6.3 / 7.4)
};

// "pneumatic" / "force"; nullopt for anything else.
std::optional<ActuationMode> parseMode(const std::string& text);
const char* modeName(ActuationMode mode);

// Sensor realism (on by default, seeded). Pressure and piston length use the plant
// package's sensor model (table 3.1: SMC PSE540 and SICK MPS); the values below are for
// the sensors table 3.1 does not cover and are documented assumptions (README).
struct SensorRealism {
  bool enabled = true;                  // ~sensor_realism
  std::uint64_t seed = 1;               // ~seed (plant valve spread uses seed + 1)
  pneumatics::SensorParams cylinder;    // ~sensors/pressure_noise_std, ~sensors/length_noise_std
  double joint_rate = 500.0;            // Hz, palm MCU joint sampling (thesis 3.7)
  double joint_noise_std = 0.0035;      // rad, ShadowHand Hall sensors (~0.2 deg)
  double joint_quantum = 6.283185307179586 / 4096;  // rad, 12-bit over a full turn
  double joint_velocity_noise_std = 0.05;  // rad/s
  double joint_delay = 0.002;           // s, MCU -> CAN -> driver, one 500 Hz frame
  // Slide joints (the keypad's keys, not the hand's) read in metres by a linear sensor: the
  // hand's Hall-sensor noise and 12-bit steps in radians would be 3.5 mm and 1.5 mm on a key
  // of 6 mm travel. Assumed: the piston-length sensor's figures (SICK MPS, table 3.1).
  double slide_noise_std = 1e-4;        // m
  double slide_quantum = 5e-5;          // m
  double slide_velocity_noise_std = 0.002;  // m/s
  double cylinder_delay = 0.001;        // s, DAQ acquisition and transfer
  double touch_noise_std = 0.01;        // N
  double touch_delay = 0.002;           // s
  double object_noise_std = 0.0005;     // m, PhaseSpace mocap position noise
  double object_delay = 0.005;          // s, mocap latency
};

struct SimConfig {
  std::string model_path;               // resolved from ~scene (or ~model_file)
  ActuationMode mode = ActuationMode::kPneumatic;  // ~mode
  double timestep = 0.002;              // ~timestep, s; overrides the model's option
  double watchdog_timeout = 0.05;       // ~watchdog_timeout, s, bounded to [0.01, 0.2]
  double min_tension = 0.3;             // ~min_tension, N: slack-avoiding lower bound (6.3)
  double supply_pressure = 620e3;       // ~supply_pressure, Pa absolute (fig. 5.9)
  std::string initial_keyframe = "home";  // ~initial_keyframe ("" = model default)
  // Bounds of the states a reset or set_object_pose accepts: a finite but absurd state
  // (an object 1e300 m away, a joint spinning at 1e6 rad/s) would only fault in the next step.
  double max_reset_distance = 10.0;     // ~max_reset_distance, m: free joints (the object) from the origin
  double max_reset_velocity = 50.0;     // ~max_reset_velocity, rad/s or m/s: every velocity coordinate
  // A limited joint may be placed beyond a limit by this fraction of its range: MuJoCo's
  // limits are soft and the simulation itself goes beyond them (measured on arm_hand with
  // every flexor at full supply: 0.01-0.025 rad while pressing, up to 8.6 % of a joint's
  // range on impact, test StatesTheSimulationProducesAreAcceptedBack), and a state saved
  // there must be accepted back.
  double reset_range_margin = 0.15;     // ~reset_range_margin, fraction of the joint's range, in [0, 1]
  // Teleop scenes: the hand base's mocap target moves towards the latest target pose at no
  // more than these speeds, so a tracking glitch (a jump of the mocap stream) cannot fling the
  // hand through the weld.
  double max_base_speed = 2.0;          // ~max_base_speed, m/s
  double max_base_angular_speed = 6.0;  // ~max_base_angular_speed, rad/s
  SensorRealism sensors;
};

constexpr double kMinWatchdogTimeout = 0.010;
constexpr double kMaxWatchdogTimeout = 0.200;

// Empty when valid, else one line naming the offending parameter (e.g.
// "~watchdog_timeout must be in [0.01, 0.2] s, got 0.5").
std::string validate(const SimConfig& config);

}  // namespace adroit::driver
