// The pickup task's core (thesis 10.4, 11.3, 11.4): the success criterion on hand-built tube
// states, the initial-yaw helper, the cost terms on a hand-made trajectory (expected values
// worked out by hand below), and the task fields' one-line errors.
#include <adroit_learning/pickup.h>
#include <adroit_learning/trajectory_cost.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

namespace {

using adroit::ObjectGeometry;
using adroit::ObjectState;
using adroit::pickupSuccess;
using Eigen::Vector3d;

constexpr double kDeg = M_PI / 180.0;

// The scene's tube: capsule of radius 22 mm around a 24 cm axis along body x, table top at 0.
ObjectGeometry tube() {
  ObjectGeometry g;
  g.half_length = 0.12;
  g.radius = 0.022;
  g.axis_in_body = Vector3d::UnitX();
  return g;
}

Eigen::Quaterniond about(const Vector3d& axis, double degrees) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(degrees * kDeg, axis.normalized()));
}

// Held across the palm at the 12 cm of the 10.4 cost, at rest.
ObjectState lifted() {
  ObjectState s;
  s.position = Vector3d(0, -0.215, 0.12);
  return s;
}

}  // namespace

TEST(PickupSuccess, LiftedAndAlignedSucceeds) {
  const auto v = pickupSuccess(lifted(), tube());
  EXPECT_TRUE(v.success) << v.failure;
  EXPECT_NEAR(v.end_clearance[0], 0.12 - 0.022, 1e-12);  // both ends: centre height - radius
  EXPECT_NEAR(v.end_clearance[1], 0.12 - 0.022, 1e-12);
  EXPECT_NEAR(v.axis_angle, 0.0, 1e-9);
}

TEST(PickupSuccess, CentreLiftedWithOneEndOnTheTableFails) {
  // Tilted by 10 degrees (within the alignment tolerance) with the low end cap resting on the
  // table: that end's centre is at the radius, the tube's centre 0.12 sin(10 deg) = 21 mm higher.
  ObjectState s;
  s.orientation = about(Vector3d::UnitY(), -10);  // +x end up
  s.position = Vector3d(0, -0.2, 0.022 + 0.12 * std::sin(10 * kDeg));
  auto v = pickupSuccess(s, tube());
  EXPECT_FALSE(v.success);
  EXPECT_EQ(v.failure, "an end is below the lift height");
  EXPECT_NEAR(std::min(v.end_clearance[0], v.end_clearance[1]), 0.0, 1e-9);
  EXPECT_NEAR(std::max(v.end_clearance[0], v.end_clearance[1]), 2 * 0.12 * std::sin(10 * kDeg), 1e-9);
  // Lifted 5 cm higher, the same tilt passes: only the end on the table failed it.
  s.position.z() += 0.05;
  v = pickupSuccess(s, tube());
  EXPECT_TRUE(v.success) << v.failure;
  // Just under the 2 cm clearance fails, just over passes.
  s.position.z() = 0.022 + 0.12 * std::sin(10 * kDeg) + 0.019;
  EXPECT_FALSE(pickupSuccess(s, tube()).success);
  s.position.z() += 0.002;
  EXPECT_TRUE(pickupSuccess(s, tube()).success);
}

TEST(PickupSuccess, StillMovingFails) {
  ObjectState s = lifted();
  s.linear_velocity = Vector3d(0, 0, -0.2);  // falling out of the hand
  EXPECT_EQ(pickupSuccess(s, tube()).failure, "not stationary");
  s.linear_velocity = Vector3d(0.03, 0.03, 0);  // 4.2 cm/s: within 5 cm/s
  EXPECT_TRUE(pickupSuccess(s, tube()).success);
  s.linear_velocity.setZero();
  s.angular_velocity = Vector3d(0, 0, 1.0);  // spinning in the grasp
  EXPECT_EQ(pickupSuccess(s, tube()).failure, "not stationary");
  s.angular_velocity = Vector3d(0.3, 0.3, 0);  // 0.42 rad/s: within 0.5
  EXPECT_TRUE(pickupSuccess(s, tube()).success);
}

TEST(PickupSuccess, MisalignedFails) {
  ObjectState s = lifted();
  s.orientation = about(Vector3d::UnitZ(), 30);
  auto v = pickupSuccess(s, tube());
  EXPECT_EQ(v.failure, "not aligned with x");
  EXPECT_NEAR(v.axis_angle, 30 * kDeg, 1e-9);
  s.orientation = about(Vector3d::UnitZ(), 10);
  EXPECT_TRUE(pickupSuccess(s, tube()).success);
  // Along y (the forearm's direction): as far from aligned as can be.
  s.orientation = about(Vector3d::UnitZ(), 90);
  EXPECT_NEAR(pickupSuccess(s, tube()).axis_angle, 90 * kDeg, 1e-9);
}

TEST(PickupSuccess, AntiParallelAndRolledCountAsAligned) {
  // The tube is symmetric end to end (11.3 covers its orientations with 180 degrees) and about
  // its own axis: turned end for end or rolled, it is still across the palm along x.
  ObjectState s = lifted();
  s.orientation = about(Vector3d::UnitZ(), 180);
  EXPECT_TRUE(pickupSuccess(s, tube()).success);
  s.orientation = about(Vector3d::UnitZ(), 170);  // 10 degrees from -x
  EXPECT_NEAR(pickupSuccess(s, tube()).axis_angle, 10 * kDeg, 1e-9);
  s.orientation = about(Vector3d::UnitX(), 77);
  EXPECT_TRUE(pickupSuccess(s, tube()).success);
}

TEST(PickupSuccess, UnknownGeometryIsRefused) {
  EXPECT_THROW(pickupSuccess(lifted(), ObjectGeometry{}), std::invalid_argument);
}

TEST(PickupYaw, TheAxisIsWhereTheAngleSays) {
  for (double deg : {0.0, 30.0, 90.0, 135.0, 179.0}) {
    const Vector3d axis = adroit::objectAxis(adroit::tubeOrientationFromYaw(deg, tube()), tube());
    EXPECT_NEAR(axis.x(), std::cos(deg * kDeg), 1e-12) << deg;
    EXPECT_NEAR(axis.y(), std::sin(deg * kDeg), 1e-12) << deg;
    EXPECT_NEAR(axis.z(), 0.0, 1e-12) << deg;  // lying flat
  }
  // A geometry whose axis is the body's z (an unrotated capsule) lies flat too.
  ObjectGeometry upright = tube();
  upright.axis_in_body = Vector3d::UnitZ();
  const Vector3d axis = adroit::objectAxis(adroit::tubeOrientationFromYaw(90, upright), upright);
  EXPECT_NEAR(axis.y(), 1.0, 1e-12);
  for (double bad : {-1.0, 180.0, 400.0, std::nan("")})
    EXPECT_THROW(adroit::tubeOrientationFromYaw(bad, tube()), std::invalid_argument) << bad;
}

namespace {

// Two joints, one cylinder, the object: x = [q0 q1 | p(3) | rv(3) | qd0 qd1 | v(3) w(3) | p0].
struct TinyPickup {
  TinyPickup() {
    task.name = "tiny";
    task.scene = "tube";
    task.horizon = 2;
    task.joint_weight = 1.0;
    task.final_joint_weight = 1.0;
    task.action_weight = 0.1;
    task.object_height_weight = 50.0;
    task.object_height_target = 0.12;
    task.final_scale = 1.0;
    layout = adroit::StateLayout(task, {"J0", "J1"}, {"C0"}, true);
  }
  Eigen::VectorXd state(double q0, double q1, double z) const {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(layout.nx());
    x[0] = q0, x[1] = q1;
    x[layout.objectPosition() + 2] = z;
    return x;
  }
  adroit::TrainingTask task;
  adroit::StateLayout layout;
};

}  // namespace

TEST(PickupCost, RunningAndFinalTermsOfThesis104) {
  TinyPickup f;
  ASSERT_EQ(f.layout.nx(), 17);
  f.task.joint_reference = {{0, 0}, {0.1, 0.2}, {0.3, 0.3}};  // q_hat_t
  adroit::Rollout r;
  r.x.resize(17, 3);
  r.x.col(0) = f.state(0, 0, 0.022);
  r.x.col(1) = f.state(0.2, 0.2, 0.10);
  r.x.col(2) = f.state(0.3, 0.5, 0.12);
  r.u.resize(1, 2);
  r.u << 1.0, -2.0;
  const adroit::TrajectoryCost cost(f.task, f.layout, r.x.col(0));
  // t = 0: 0 + 0.1 * 1 + 50 * 0.098^2 = 0.1 + 0.4802
  // t = 1: 0.1^2 + 0.1 * 4 + 50 * 0.02^2 = 0.01 + 0.4 + 0.02
  // T = 2: 0.2^2 + 0 (no control, same weights)
  EXPECT_NEAR(cost.rolloutCost(r), 0.5802 + 0.43 + 0.04, 1e-12);
  // Without a reference the joint term pulls to the constant q* (here the initial pose 0, 0).
  f.task.joint_reference.clear();
  const adroit::TrajectoryCost constant(f.task, f.layout, r.x.col(0));
  // joints: 0 + (0.04 + 0.04) + (0.09 + 0.25)
  EXPECT_NEAR(constant.rolloutCost(r), 0.1 + 0.4802 + 0.08 + 0.4 + 0.02 + 0.34, 1e-12);
  // The quadratic expansion has the same minimum: a rollout on the reference with z = 0.12 and
  // u = 0 costs nothing.
  f.task.joint_reference = {{0, 0}, {0.1, 0.2}, {0.3, 0.3}};
  const adroit::TrajectoryCost shaped(f.task, f.layout, r.x.col(0));
  adroit::Rollout ideal = r;
  ideal.x.col(0) = f.state(0, 0, 0.12);
  ideal.x.col(1) = f.state(0.1, 0.2, 0.12);
  ideal.x.col(2) = f.state(0.3, 0.3, 0.12);
  ideal.u.setZero();
  EXPECT_NEAR(shaped.rolloutCost(ideal), 0.0, 1e-12);
}

TEST(PickupCost, ReferenceOfTheWrongShapeIsRefused) {
  TinyPickup f;
  f.task.joint_reference = {{0, 0}, {0.1, 0.2}};  // T + 1 = 3 needed
  EXPECT_THROW(adroit::TrajectoryCost(f.task, f.layout, f.state(0, 0, 0.022)), adroit::TaskError);
  f.task.joint_reference = {{0, 0}, {0.1}, {0.3, 0.3}};
  EXPECT_THROW(adroit::TrajectoryCost(f.task, f.layout, f.state(0, 0, 0.022)), adroit::TaskError);
}

TEST(PickupCost, FromScratchGoalPosition) {
  TinyPickup f;
  f.task.object_height_weight = 0;
  f.task.object_position_weight = 50;
  f.task.object_position_target = {0.0, -0.215, 0.12};
  adroit::Rollout r;
  r.x = Eigen::MatrixXd::Zero(17, 3);
  r.u = Eigen::MatrixXd::Zero(1, 2);
  for (int t = 0; t < 3; ++t) r.x(f.layout.objectPosition() + 1, t) = -0.215;
  r.x(f.layout.objectPosition() + 2, 2) = 0.02;  // z at T; 0 before
  const adroit::TrajectoryCost cost(f.task, f.layout, r.x.col(0));
  // 50 * 0.12^2 at t = 0 and 1, 50 * 0.1^2 at T (the goal, not the initial position)
  EXPECT_NEAR(cost.rolloutCost(r), 2 * 50 * 0.0144 + 50 * 0.01, 1e-12);
}

TEST(PickupCost, OutcomeUsesThe114Criterion) {
  TinyPickup f;
  f.task.success_criterion = "pickup";
  EXPECT_THROW(adroit::TrajectoryCost(f.task, f.layout, f.state(0, 0, 0.022)), adroit::TaskError);  // no geometry
  const adroit::TrajectoryCost cost(f.task, f.layout, f.state(0, 0, 0.022), tube());
  adroit::Rollout r;
  r.x.resize(17, 3);
  r.u = Eigen::MatrixXd::Zero(1, 2);
  for (int t = 0; t < 3; ++t) r.x.col(t) = f.state(0, 0, 0.022);
  auto o = cost.outcome(r);  // still on the table
  EXPECT_FALSE(o.success);
  EXPECT_EQ(o.failure, "an end is below the lift height");
  r.x.col(2) = f.state(0, 0, 0.12);
  // Yawed by 90 degrees (rotation vector along z): lifted but along y.
  r.x(f.layout.objectRotation() + 2, 2) = M_PI / 2;
  EXPECT_EQ(cost.outcome(r).failure, "not aligned with x");
  r.x(f.layout.objectRotation() + 2, 2) = 0;
  r.x(f.layout.qdot() + 2 + 2, 2) = -0.5;  // object falling at 0.5 m/s
  EXPECT_EQ(cost.outcome(r).failure, "not stationary");
  r.x(f.layout.qdot() + 2 + 2, 2) = 0;
  o = cost.outcome(r);
  EXPECT_TRUE(o.success) << o.failure;
  EXPECT_NEAR(o.object_height, 0.12, 1e-12);
}

namespace {

std::string loadError(const std::string& extra, const std::string& criterion = "pickup") {
  const std::string path = std::string(::testing::TempDir()) + "/pickup_bad.yaml";
  std::ofstream(path) << "name: t\nscene: tube\nhorizon: 10\ncontrol_dt: 0.04\nsuccess_criterion: " << criterion << "\n"
                      << extra;
  try {
    adroit::loadTrainingTask(path);
  } catch (const adroit::TaskError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(PickupTaskFile, BadFieldsGiveOneLine) {
  EXPECT_EQ(loadError(""), "");
  std::string e = loadError("initial_object_yaw: 180\n");
  EXPECT_NE(e.find("initial_object_yaw: must be in [0, 180) degrees, got 180"), std::string::npos) << e;
  e = loadError("initial_object_yaw: -5\n");
  EXPECT_NE(e.find("initial_object_yaw: must be in [0, 180)"), std::string::npos) << e;
  e = loadError("initial_object_yaw: .nan\n");
  EXPECT_NE(e.find("initial_object_yaw: not finite"), std::string::npos) << e;
  e = loadError("object_height_target: .inf\n");
  EXPECT_NE(e.find("object_height_target: not finite"), std::string::npos) << e;
  e = loadError("object_position_target: [0, 0]\n");
  EXPECT_NE(e.find("object_position_target: expected [x, y, z]"), std::string::npos) << e;
  e = loadError("initial_object_yaww: 10\n");
  EXPECT_NE(e.find("initial_object_yaww: unknown field"), std::string::npos) << e;
  e = loadError("", "pikup");
  EXPECT_NE(e.find("success_criterion: expected 'pickup'"), std::string::npos) << e;
  EXPECT_EQ(e.find('\n'), std::string::npos) << e;
}
