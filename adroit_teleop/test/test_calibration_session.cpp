// The calibration procedure (start, record each pose, fit) with a simulated glove whose
// sensors are a known affine function of the hand's joints: the fitted calibration gives the
// poses back. And the nominal calibration spreads each sensor's travel over its joint's range.
#include <adroit_core/mujoco_model.h>
#include <adroit_teleop/calibration_session.h>
#include <adroit_teleop/glove_protocol.h>
#include <adroit_teleop/glove_layout.h>
#include <gtest/gtest.h>

#include <random>

using namespace adroit;
using namespace adroit::teleop;

namespace {

std::map<std::string, JointRange> handRanges() {
  const LoadedModel loaded = loadModelFile(std::string(ADROIT_MJCF_DIR) + "/hand.xml");
  return jointRangesFromModel(loaded.model.get());
}

CalibrationPoseSet shippedPoses() { return loadCalibrationPoses(POSE_FILE, handRanges()); }

TEST(CalibrationSession, RecoversThePosesOfASimulatedGlove) {
  const CalibrationPoseSet poses = shippedPoses();
  const int n = kSensors22, J = static_cast<int>(poses.joints.size());
  // The glove: each sensor mostly one joint (its layout), plus cross-talk, an offset, noise.
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 1.0 / 255);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, J);
  const auto layout = gloveSensorJoints(n);
  for (int s = 0; s < n; ++s) {
    const auto it = std::find(poses.joints.begin(), poses.joints.end(), layout[s]);
    A(s, it - poses.joints.begin()) = 0.3;
    A(s, (it - poses.joints.begin() + 1) % J) = 0.03;
  }
  const Eigen::VectorXd offset = Eigen::VectorXd::Constant(n, 0.3);
  CalibrationSession session(poses, n);
  EXPECT_THROW(session.record(), CalibrationError);  // no reading yet
  EXPECT_THROW(session.fit(), CalibrationError);     // not complete
  EXPECT_THROW(session.addReading(Eigen::VectorXd::Zero(18)), CalibrationError);
  while (const CalibrationPose* pose = session.current()) {
    session.addReading(Eigen::VectorXd::Constant(n, 0.9));  // while moving into the pose
    session.clearReadings();
    for (int k = 0; k < 30; ++k) {
      Eigen::VectorXd s = A * pose->targets + offset;
      for (int i = 0; i < n; ++i) s(i) += noise(rng);
      session.addReading(s);
    }
    session.record();
  }
  EXPECT_TRUE(session.remaining().empty());
  const GloveCalibration c = session.fit();
  // Every pose comes back within a few hundredths of a radian on the joints it constrains
  // (the unsensed THJ2 and MFJ3 cannot be, and are not asked for).
  for (const CalibrationPose& pose : poses.poses) {
    const Eigen::VectorXd q = c.apply(A * pose.targets + offset);
    for (int j = 0; j < J; ++j) {
      if (!pose.constrained[j] || poses.joints[j] == "THJ2" || poses.joints[j] == "MFJ3") continue;
      EXPECT_NEAR(q(j), pose.targets(j), 0.05) << pose.name << " " << poses.joints[j];
    }
  }
}

TEST(NominalCalibration, SpreadsEachSensorOverItsJointsRange) {
  const auto ranges = handRanges();
  const CalibrationPoseSet poses = shippedPoses();
  for (int n : {kSensors18, kSensors22}) {
    const GloveCalibration c = nominalCalibration(n, poses.joints, ranges);
    const auto layout = gloveSensorJoints(n);
    ASSERT_EQ(static_cast<int>(layout.size()), n);
    const Eigen::VectorXd low = c.apply(Eigen::VectorXd::Constant(n, kNominalSensorLow));
    const Eigen::VectorXd high = c.apply(Eigen::VectorXd::Constant(n, kNominalSensorHigh));
    for (int j = 0; j < c.joints(); ++j) {
      const std::string& name = c.jointNames()[j];
      const bool sensed = std::find(layout.begin(), layout.end(), name) != layout.end();
      const JointRange r = ranges.at(name);
      if (sensed) {
        EXPECT_NEAR(low(j), r.lo, 1e-9) << name;
        EXPECT_NEAR(high(j), r.hi, 1e-9) << name;
      } else {
        EXPECT_DOUBLE_EQ(low(j), high(j)) << name << " has no sensor and must not move";
      }
    }
  }
  EXPECT_THROW(gloveSensorJoints(20), std::invalid_argument);
  EXPECT_THROW(nominalCalibration(22, {"FFJ2", "NOPE"}, ranges), CalibrationError);
}

}  // namespace
