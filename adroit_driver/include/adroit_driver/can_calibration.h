// The hardware's sensor calibration as a YAML file (docs/can_protocol.md, "Calibration
// file"): per joint, per cylinder's pressure and piston length, and the supply pressure, an
// offset and a gain (can::Affine: physical = gain * bus value + offset). ROS-free.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "adroit_driver/can_mapping.h"

namespace adroit::driver::can {

// Plausibility bounds a loaded calibration must respect: a gain far from 1 or an offset this
// large is a wrong file or a broken sensor, not a calibration.
constexpr double kMinCalibrationGain = 0.5;
constexpr double kMaxCalibrationGain = 2.0;
constexpr double kMaxJointOffset = 0.5;         // rad
constexpr double kMaxPressureOffset = 50e3;     // Pa (pressure and supply)
constexpr double kMaxLengthOffset = 0.02;       // m
constexpr int kCalibrationVersion = 1;
// A complete file of the 28-joint, 48-cylinder robot is about 7 kB: anything near this limit
// is not a calibration.
constexpr std::size_t kMaxCalibrationFileBytes = 1024 * 1024;

// Reads `path`:
//   version: 1                                   # optional
//   joints:   {<joint>: {offset: <rad>, gain: <g>}, ...}
//   pressure: {<cylinder>: {offset: <Pa>, gain: <g>}, ...}
//   length:   {<cylinder>: {offset: <m>, gain: <g>}, ...}
//   supply:   {offset: <Pa>, gain: <g>}
// Every section, entry and field is optional: what is not listed is the identity. Only a
// regular file of at most kMaxCalibrationFileBytes is read (a FIFO or device is refused
// without blocking). Throws
// std::invalid_argument with one line naming the file, the key path and the value, e.g.
// "calibration /x.yaml: pressure.A_FFJ3_flex.gain must be in [0.5, 2], got 7".
Calibration loadCalibration(const std::string& path, const std::vector<std::string>& joint_names,
                            const std::vector<std::string>& cylinder_names);

// The same from YAML text; `source` names it in errors.
Calibration parseCalibration(const std::string& text, const std::string& source,
                             const std::vector<std::string>& joint_names,
                             const std::vector<std::string>& cylinder_names);

// Every joint and cylinder listed (a complete template), numbers written exactly (round trip).
// The sizes of `calibration` must match the names (std::invalid_argument otherwise).
std::string formatCalibration(const Calibration& calibration, const std::vector<std::string>& joint_names,
                              const std::vector<std::string>& cylinder_names);

// Empty when `calibration` fits the names and the bounds above, else one line naming the
// first offending entry (what loadCalibration checks, for a calibration built in code).
std::string validateCalibration(const Calibration& calibration, const std::vector<std::string>& joint_names,
                                const std::vector<std::string>& cylinder_names);

}  // namespace adroit::driver::can
