// The calibration procedure behind /adroit_teleop/calibrate (thesis 10.3), ROS-free: the
// user holds each pose of the pose set in turn; for each, the glove's sensor values are
// averaged over a short window and kept; once every pose is recorded the regression is
// fitted (fitCalibration).
#pragma once

#include <string>
#include <vector>

#include "adroit_teleop/calibration.h"

namespace adroit::teleop {

class CalibrationSession {
 public:
  // Throws CalibrationError for an empty pose set or sensors other than 18/22.
  CalibrationSession(CalibrationPoseSet poses, int sensors);

  // The pose to hold for the next record(); nullptr once every pose is recorded.
  const CalibrationPose* current() const;
  std::vector<std::string> remaining() const;  // names, current first
  bool complete() const { return next_ == poses_.poses.size(); }

  // Adds one glove reading (sensors() values in (0, 1]) to the current pose's window.
  // Throws CalibrationError for a wrong size or a non-finite value.
  void addReading(const Eigen::VectorXd& sensors);
  std::size_t readings() const { return readings_; }
  void clearReadings();  // empties the current pose's window
  // Keeps the mean of the window as the current pose's sample and moves to the next pose.
  // Throws CalibrationError when there is no pose left or no reading in the window.
  void record();
  // Fits on every recorded pose. Throws CalibrationError unless complete().
  GloveCalibration fit(double lambda = kDefaultRidgeLambda) const;

  int sensors() const { return sensors_; }
  const CalibrationPoseSet& poses() const { return poses_; }

 private:
  CalibrationPoseSet poses_;
  int sensors_;
  std::size_t next_ = 0;
  Eigen::VectorXd sum_;
  std::size_t readings_ = 0;
  std::vector<CalibrationSample> samples_;
};

}  // namespace adroit::teleop
