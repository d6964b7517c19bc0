#include "adroit_teleop/glove_layout.h"

#include <algorithm>
#include <stdexcept>

#include "adroit_teleop/glove_protocol.h"

namespace adroit::teleop {

std::vector<std::string> gloveSensorJoints(int sensors) {
  // THJ2 and MFJ3 have no sensor of their own; the DIPs (J0) of the 18-sensor glove follow
  // their PIPs through ADROIT's tendon coupling anyway.
  if (sensors == kSensors22)
    return {"THJ4", "THJ1", "THJ0", "THJ3",          // thumb roll, MCP, IP, abduction
            "FFJ2", "FFJ1", "FFJ0",                  // index MCP, PIP, DIP
            "MFJ2", "MFJ1", "MFJ0", "FFJ3",          // middle MCP, PIP, DIP; middle-index abduction
            "RFJ2", "RFJ1", "RFJ0", "RFJ3",          // ring ...; ring-middle abduction
            "LFJ2", "LFJ1", "LFJ0", "LFJ3",          // little ...; little-ring abduction
            "LFJ4", "WRJ0", "WRJ1"};                 // palm arch, wrist pitch, wrist yaw
  if (sensors == kSensors18)
    return {"THJ4", "THJ1", "THJ0", "THJ3", "FFJ2", "FFJ1", "MFJ2", "MFJ1", "FFJ3",
            "RFJ2", "RFJ1", "RFJ3", "LFJ2", "LFJ1", "LFJ3", "LFJ4", "WRJ0", "WRJ1"};
  throw std::invalid_argument("a glove has 18 or 22 sensors, not " + std::to_string(sensors));
}

GloveCalibration nominalCalibration(int sensors, const std::vector<std::string>& joints,
                                    const std::map<std::string, JointRange>& ranges) {
  std::vector<JointRange> joint_ranges;
  for (const auto& j : joints) {
    const auto it = ranges.find(j);
    if (it == ranges.end()) throw CalibrationError("nominal calibration: joint '" + j + "' has no range in the model");
    joint_ranges.push_back(it->second);
  }
  GloveCalibration c(sensors, joints, joint_ranges);
  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(c.joints(), sensors);
  Eigen::VectorXd b = c.b();
  const std::vector<std::string> layout = gloveSensorJoints(sensors);
  for (int s = 0; s < sensors; ++s) {
    const auto it = std::find(joints.begin(), joints.end(), layout[s]);
    if (it == joints.end()) continue;
    const int j = static_cast<int>(it - joints.begin());
    const JointRange r = joint_ranges[j];
    W(j, s) = (r.hi - r.lo) / (kNominalSensorHigh - kNominalSensorLow);
    b(j) = r.lo - W(j, s) * kNominalSensorLow;
  }
  c.setMap(W, b);
  c.note = "nominal: each sensor's travel " + std::to_string(static_cast<int>(kNominalSensorLow * 255)) + ".." +
           std::to_string(static_cast<int>(kNominalSensorHigh * 255)) + " spread over its joint's range";
  return c;
}

}  // namespace adroit::teleop
