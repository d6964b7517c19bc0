#include "adroit_driver/robot.h"

namespace adroit::driver {

namespace {
bool refuse(const char* what, std::string* error) {
  *error = std::string(what) + " exists only in simulation: this robot is real";
  return false;
}
}  // namespace

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
