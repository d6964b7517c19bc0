#include "adroit_driver/can_mapping.h"

#include <algorithm>
#include <stdexcept>

#include "adroit_driver/can_protocol.h"

namespace adroit::driver::can {

namespace {
bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }
bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}
void addOnce(std::vector<std::uint8_t>* boards, std::uint8_t board) {
  if (std::find(boards->begin(), boards->end(), board) == boards->end()) boards->push_back(board);
}
}  // namespace

Mapping defaultMapping(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                       const std::vector<std::string>& model_touch) {
  constexpr int kCylindersPerBoard = 8, kCylindersPerBus = 16;
  const std::size_t max_cylinders = static_cast<std::size_t>(kMaxBoards) * kCylindersPerBoard;
  if (joints.size() > static_cast<std::size_t>(kMaxJoints))
    throw std::invalid_argument("the CAN protocol carries at most " + std::to_string(kMaxJoints) + " joints, the model has " +
                                std::to_string(joints.size()));
  if (cylinders.size() > max_cylinders)
    throw std::invalid_argument("the CAN protocol's boards carry at most " + std::to_string(max_cylinders) +
                                " cylinders, the model has " + std::to_string(cylinders.size()));
  Mapping m;
  const int actuation_buses = static_cast<int>((cylinders.size() + kCylindersPerBus - 1) / kCylindersPerBus);
  m.buses.push_back("palm");
  for (int b = 0; b < std::max(actuation_buses, 1); ++b) m.buses.push_back("act" + std::to_string(b));
  m.valve_boards.resize(m.buses.size());
  m.sensor_boards.resize(m.buses.size());

  int hand = 0, arm = 0;
  for (const auto& j : joints) (startsWith(j, "ARJ") ? arm : hand)++;
  if (hand > 24 || arm > kMaxJoints - 24)
    throw std::invalid_argument("the default CAN layout has 24 hand joints and up to 8 arm joints; the model has " +
                                std::to_string(hand) + " and " + std::to_string(arm));
  int next_hand = 0, next_arm = 24;
  for (const auto& j : joints) m.joint.push_back(startsWith(j, "ARJ") ? next_arm++ : next_hand++);

  for (std::size_t c = 0; c < cylinders.size(); ++c) {
    CylinderChannel ch;
    ch.bus = 1 + static_cast<int>(c / kCylindersPerBus);
    ch.board = static_cast<std::uint8_t>(c / kCylindersPerBoard);
    ch.channel = static_cast<std::uint8_t>(c % kCylindersPerBoard);
    m.cylinder.push_back(ch);
    addOnce(&m.valve_boards[ch.bus], ch.board);
    addOnce(&m.sensor_boards[ch.bus], ch.board);
  }
  for (const auto& t : model_touch)
    if (endsWith(t, "tip")) m.touch.push_back(t);
  if (m.touch.size() > static_cast<std::size_t>(kMaxTouchSensors))
    throw std::invalid_argument("too many fingertip touch sensors for the CAN protocol");
  m.supply_bus = 1;
  m.supply_board = 0;
  return m;
}

Calibration identityCalibration(std::size_t joints, std::size_t cylinders) {
  Calibration c;
  c.joint.assign(joints, Affine{});
  c.pressure.assign(cylinders, Affine{});
  c.length.assign(cylinders, Affine{});
  return c;
}

}  // namespace adroit::driver::can
