// Where each of the robot's joints, cylinders and touch sensors is on the CAN buses
// (docs/can_protocol.md, sections 1 and 5), and the sensor calibration. Shared by the
// hardware driver (CanRobot) and the hardware emulator, so both read the same layout.
// ROS-free and MuJoCo-free.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace adroit::driver::can {

// The buses, in the order of Mapping::buses: the palm bus, then the actuation buses.
constexpr int kPalmBus = 0;

struct CylinderChannel {
  int bus = 1;              // index into Mapping::buses
  std::uint8_t board = 0;   // valve board and sensor board number (global, 0..7)
  std::uint8_t channel = 0; // on both boards
};

struct Mapping {
  std::vector<std::string> buses;            // "palm", "act0", "act1", "act2"
  std::vector<int> joint;                    // per robot joint: protocol joint index 0..31
  std::vector<CylinderChannel> cylinder;     // per robot cylinder
  std::vector<std::string> touch;            // the model's touch sensors the palm reads, protocol index = position
  int supply_bus = 1;                        // the sensor board that reads the supply pressure
  std::uint8_t supply_board = 0;
  // Boards present on each bus (derived from the cylinders): the nodes whose heartbeats
  // the host expects there. valve_boards[bus] lists board numbers.
  std::vector<std::vector<std::uint8_t>> valve_boards, sensor_boards;
};

// The default layout of docs/can_protocol.md: hand joints (model order, names not starting
// with "ARJ") at protocol indices 0..23, arm joints at 24..; cylinder c on board c / 8,
// channel c % 8, bus act<c / 16>; the five fingertip sensors (names ending in "tip") at touch
// indices 0..4 in model order; supply on sensor board 0. Throws std::invalid_argument
// naming what does not fit (more than 32 joints, 64 cylinders...).
Mapping defaultMapping(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                       const std::vector<std::string>& model_touch);

// Per-channel sensor calibration: physical = gain * value_on_the_bus + offset. The boards
// send values in physical units already (section 5.1); this corrects each sensor's own
// offset and gain, measured on the robot. Identity by default.
struct Affine {
  double gain = 1, offset = 0;
  double apply(double bus_value) const { return gain * bus_value + offset; }
  double invert(double physical) const { return (physical - offset) / gain; }  // what a board would send
};
struct Calibration {
  std::vector<Affine> joint;     // per robot joint (rad); offset = the joint's zero
  std::vector<Affine> pressure;  // per cylinder (Pa absolute)
  std::vector<Affine> length;    // per cylinder (m)
  Affine supply;                 // Pa absolute
};
Calibration identityCalibration(std::size_t joints, std::size_t cylinders);

}  // namespace adroit::driver::can
