// nominal_calibration: writes the nominal glove calibration (glove_layout.h: each sensor's
// travel spread over its joint's range) for the joints of a pose file, with the ranges of a
// model. Run at build time for config/nominal_calibration.yaml, the calibration teleop.launch
// starts with (and the one the emulator's synthetic glove is meant to be played through).
//
//   nominal_calibration --model teleop_tube.xml --poses calibration_poses.yaml --sensors 22 --out nominal.yaml
#include <cstdio>

#include "adroit_core/command_line.h"
#include "adroit_core/mujoco_model.h"
#include "adroit_teleop/glove_layout.h"

int main(int argc, char** argv) {
  adroit::CommandLine args(argc, argv,
                           "usage: nominal_calibration --model MJCF --poses POSES.yaml --out FILE.yaml [--sensors 18|22]");
  std::string model_path, poses_path, out;
  int sensors = 22;
  while (args.next()) {
    if (args.is("--model")) model_path = args.text();
    else if (args.is("--poses")) poses_path = args.text();
    else if (args.is("--out")) out = args.text();
    else if (args.is("--sensors")) sensors = static_cast<int>(args.integer());
    else args.unknown();
  }
  if (model_path.empty() || poses_path.empty() || out.empty()) args.fail("--model, --poses and --out are required");
  try {
    const adroit::LoadedModel loaded = adroit::loadModelFile(model_path);  // throws, naming the file
    const auto ranges = adroit::teleop::jointRangesFromModel(loaded.model.get());
    const auto poses = adroit::teleop::loadCalibrationPoses(poses_path, ranges);
    adroit::teleop::GloveCalibration c = adroit::teleop::nominalCalibration(sensors, poses.joints, ranges);
    c.created = "1970-01-01T00:00:00Z";  // generated, not fitted: a fixed date keeps the file reproducible
    adroit::teleop::saveCalibration(out, c);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nominal_calibration: %s\n", e.what());
    return 1;
  }
  return 0;
}
