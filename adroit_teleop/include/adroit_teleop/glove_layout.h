// Which ADROIT joint each CyberGlove sensor mostly measures, and the nominal calibration
// built from that table: each sensor's travel spread linearly over its joint's range. The
// nominal map is where a user starts (and what the emulator's synthetic glove is played
// through); the calibration procedure (thesis 10.3) replaces it with a regression on the
// user's own poses.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "adroit_teleop/calibration.h"

namespace adroit::teleop {

// Per sensor of an 18- or 22-sensor glove (CyberGlove sensor order: thumb roll, thumb MCP,
// thumb IP, thumb abduction, then per finger MCP, PIP (, DIP) and the abductions between
// fingers, palm arch, wrist pitch, wrist yaw), the ADROIT joint it drives ("" = none).
// Throws std::invalid_argument for another count.
std::vector<std::string> gloveSensorJoints(int sensors);

// Raw sensor values the nominal map spans: the synthetic emulator glove's 28..228 (of 255).
constexpr double kNominalSensorLow = 28.0 / 255.0, kNominalSensorHigh = 228.0 / 255.0;

// joints/ranges: the joints to map (e.g. the pose set's). A joint no sensor measures keeps
// its rest value (0 clamped into its range). Throws CalibrationError if a sensor's joint is
// not among `ranges`.
GloveCalibration nominalCalibration(int sensors, const std::vector<std::string>& joints,
                                    const std::map<std::string, JointRange>& ranges);

}  // namespace adroit::teleop
