// Validation of incoming actuator commands (valve volts or tendon forces), ROS-free.
//
// Policy (README "Bad commands"):
//  * addressing: exactly one of name[] / index[] is non-empty and has the length of the
//    values; names must be known actuators, indices in range, no actuator twice -> else
//    the whole message is REJECTED (nothing applied);
//  * any NaN / Inf value -> REJECTED;
//  * a value outside [lower, upper] -> REJECTED for valve volts (a controller asking for
//    7 V has a bug; the valve amplifier cannot do it), CLAMPED for tendon forces above
//    the cylinder's maximum (saturation is what the actuator physically does) and
//    REJECTED for negative forces (tendons cannot push).
// A message may address a subset of the actuators (each pneumatic pool owns a subset).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "adroit_core/model_tables.h"

namespace adroit::driver {

enum class CommandVerdict {
  kAccepted,
  kClamped,           // accepted after clamping at least one value
  kBadAddressing,     // both / neither of name and index, or lengths differ
  kUnknownName,
  kIndexOutOfRange,
  kDuplicate,
  kNotFinite,
  kOutOfRange,
  kEmpty,
};

const char* verdictName(CommandVerdict verdict);
inline bool isApplied(CommandVerdict v) { return v == CommandVerdict::kAccepted || v == CommandVerdict::kClamped; }

struct CheckedCommand {
  CommandVerdict verdict = CommandVerdict::kEmpty;
  std::string error;               // human readable, empty when accepted
  std::vector<int> actuator;       // resolved actuator indices (model order)
  std::vector<double> value;       // values to apply (clamped if verdict is kClamped)
};

struct ValueLimits {
  std::vector<double> lower, upper;  // per actuator
  bool clamp_above = false;          // clamp values above upper instead of rejecting
};

CheckedCommand checkCommand(const NameIndex& actuators, const std::vector<std::string>& names,
                            const std::vector<std::uint16_t>& indices, const std::vector<double>& values,
                            const ValueLimits& limits);

// The same check writing into `out`, reusing its storage and that of `seen` (scratch, one
// flag per actuator): once they have grown to the largest command nothing is allocated,
// except the error text of a rejected command. For the simulation's hot path.
void checkCommand(const NameIndex& actuators, const std::vector<std::string>& names,
                  const std::vector<std::uint16_t>& indices, const std::vector<double>& values,
                  const ValueLimits& limits, CheckedCommand* out, std::vector<char>* seen);

}  // namespace adroit::driver
