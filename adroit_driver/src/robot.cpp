#include "adroit_driver/robot.h"

namespace adroit::driver {

namespace {
bool refuse(const char* what, std::string* error) {
  *error = std::string(what) + " exists only in simulation: this robot is real";
  return false;
}
}  // namespace

CommandResult countCommand(const CheckedCommand& checked, bool safe_state, Counters* counters) {
  CommandResult result{checked.verdict, false, checked.error};
  switch (checked.verdict) {
    case CommandVerdict::kAccepted: break;
    case CommandVerdict::kClamped: ++counters->clamped; break;
    case CommandVerdict::kBadAddressing:
    case CommandVerdict::kDuplicate:
    case CommandVerdict::kEmpty: ++counters->rejected_addressing; return result;
    case CommandVerdict::kUnknownName:
    case CommandVerdict::kIndexOutOfRange: ++counters->rejected_name; return result;
    case CommandVerdict::kNotFinite: ++counters->rejected_not_finite; return result;
    case CommandVerdict::kOutOfRange: ++counters->rejected_range; return result;
  }
  if (safe_state) {
    ++counters->ignored_while_safe;
    result.error = "ignored: robot is in the safe state (release required)";
    return result;
  }
  ++counters->accepted;
  result.applied = true;
  return result;
}

bool latchSafeState(SafetyEvent* event, SafetyStatus* safety, Counters* counters, SafetyEvents* events) {
  switch (event->cause) {
    case SafeCause::kEstop:
      safety->estop_latched = true;
      ++counters->estops;
      break;
    case SafeCause::kWatchdog:
      safety->watchdog_latched = true;
      ++counters->watchdog_trips;
      break;
    case SafeCause::kFault:
      if (safety->fault_latched) return false;
      safety->fault_latched = true;
      ++counters->faults;
      break;
    case SafeCause::kNone: return false;
  }
  safety->safe_state = true;
  event->sequence = ++counters->safety_events;
  events->last = *event;
  switch (event->cause) {
    case SafeCause::kEstop: events->estop = *event; break;
    case SafeCause::kWatchdog: events->watchdog = *event; break;
    default: events->fault = *event; break;
  }
  return true;
}

bool Robot::resetToKeyframe(const std::string&, std::string* error) { return refuse("reset", error); }
bool Robot::resetToState(const std::vector<double>&, const std::vector<double>&, const std::vector<double>&,
                         std::string* error) {
  return refuse("reset", error);
}
bool Robot::setObjectPose(const std::array<double, 3>&, const std::array<double, 4>&, const std::array<double, 3>&,
                          const std::array<double, 3>&, std::string* error) {
  return refuse("set_object_pose", error);
}
bool Robot::setBaseTarget(const std::array<double, 3>&, const std::array<double, 4>&, std::string* error) {
  return refuse("hand_base/target", error);
}

}  // namespace adroit::driver
