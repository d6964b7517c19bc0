#include "adroit_teleop/calibration_session.h"

#include "adroit_teleop/glove_protocol.h"

namespace adroit::teleop {

CalibrationSession::CalibrationSession(CalibrationPoseSet poses, int sensors)
    : poses_(std::move(poses)), sensors_(sensors) {
  if (poses_.poses.empty()) throw CalibrationError("calibration: the pose set has no pose");
  if (!validSensorCount(sensors_)) throw CalibrationError("calibration: a glove has 18 or 22 sensors");
  sum_ = Eigen::VectorXd::Zero(sensors_);
}

const CalibrationPose* CalibrationSession::current() const {
  return complete() ? nullptr : &poses_.poses[next_];
}

std::vector<std::string> CalibrationSession::remaining() const {
  std::vector<std::string> names;
  for (std::size_t i = next_; i < poses_.poses.size(); ++i) names.push_back(poses_.poses[i].name);
  return names;
}

void CalibrationSession::addReading(const Eigen::VectorXd& sensors) {
  if (sensors.size() != sensors_)
    throw CalibrationError("calibration: a reading of " + std::to_string(sensors.size()) + " sensors, the glove has " +
                           std::to_string(sensors_));
  if (!sensors.allFinite()) throw CalibrationError("calibration: a reading is not finite");
  sum_ += sensors;
  ++readings_;
}

void CalibrationSession::clearReadings() {
  sum_.setZero();
  readings_ = 0;
}

void CalibrationSession::record() {
  if (complete()) throw CalibrationError("calibration: every pose is already recorded; call fit");
  if (readings_ == 0)
    throw CalibrationError("calibration: no glove reading while holding '" + poses_.poses[next_].name +
                           "' (is the glove streaming?)");
  samples_.push_back(poseSample(poses_.poses[next_], sum_ / static_cast<double>(readings_)));
  sum_.setZero();
  readings_ = 0;
  ++next_;
}

GloveCalibration CalibrationSession::fit(double lambda) const {
  if (!complete())
    throw CalibrationError("calibration: " + std::to_string(poses_.poses.size() - next_) +
                           " pose(s) not recorded yet, next '" + poses_.poses[next_].name + "'");
  return fitCalibration(sensors_, poses_.joints, poses_.ranges, samples_, lambda);
}

}  // namespace adroit::teleop
