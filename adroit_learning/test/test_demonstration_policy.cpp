// A demonstration replayed open loop as a TVLG policy (demonstration_policy.h): its mean action
// is the demonstration's command u_t of the action cylinders whatever the state, its metadata is
// the task's, it survives a policy file round trip, and a demonstration that cannot be replayed
// (too short, another task) is refused with demonstrationMismatch's line.
#include <adroit_learning/demonstration_policy.h>
#include <adroit_learning/tvlg_policy.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

namespace {

const std::vector<std::string> kJoints = {"J_a", "J_b"};
const std::vector<std::string> kCylinders = {"C_1", "C_2", "C_3"};

adroit::TrainingTask pickupTask() {
  adroit::TrainingTask task;
  task.name = "pickup";
  task.scene = "tube";
  task.horizon = 4;
  task.control_dt = 0.04;
  task.initial_object_yaw = 0.0;
  task.object_height_weight = 50;
  task.success_criterion = "pickup";
  task.locked_cylinders = {"C_2"};  // u has the action cylinders C_1, C_3 only
  task.locked_command = 0.5;
  return task;
}

adroit::StateLayout layoutOf(const adroit::TrainingTask& task) {
  return adroit::StateLayout(task, kJoints, kCylinders, true);
}

// A valve-command recording of `samples` steps on the task's control step; u(c, t) = 10 c + t / 10.
adroit::Demonstration demonstration(const adroit::StateLayout& layout, int samples) {
  adroit::Demonstration demo;
  demo.path = "/tmp/demo.txt";
  demo.task = "pickup";
  demo.mode = "pneumatic";
  demo.model = "/share/adroit_description/mjcf/tube.xml";
  demo.joints = kJoints;
  demo.cylinders = kCylinders;
  demo.has_object = true;
  demo.actions = "valve";
  demo.dt = 0.04;
  demo.x = Eigen::MatrixXd::Random(layout.nx(), samples);
  demo.u.resize(static_cast<Eigen::Index>(kCylinders.size()), samples);
  for (int c = 0; c < demo.u.rows(); ++c)
    for (int t = 0; t < samples; ++t) demo.u(c, t) = 10.0 * c + 0.1 * t;
  return demo;
}

TEST(DemonstrationPolicy, MeanActionIsTheDemonstrationsCommandWhateverTheState) {
  const adroit::TrainingTask task = pickupTask();
  const adroit::StateLayout layout = layoutOf(task);
  const adroit::Demonstration demo = demonstration(layout, task.horizon + 3);  // longer than T: its first T
  const adroit::PolicyFile file = adroit::demonstrationReplayPolicy(demo, task, layout);
  ASSERT_EQ(file.controller.horizon(), task.horizon);
  ASSERT_EQ(file.controller.nu(), 2);
  ASSERT_EQ(file.controller.nx(), layout.nx());
  EXPECT_EQ(file.actions, (std::vector<std::string>{"C_1", "C_3"}));
  adroit::TvlgPolicy policy(file, "replay");
  Eigen::VectorXd u(2);
  const Eigen::VectorXd touch;
  for (int t = 0; t < task.horizon; ++t) {
    const Eigen::VectorXd x = Eigen::VectorXd::Random(layout.nx()) * 100.0;
    policy.action(t, x, touch, u);
    EXPECT_DOUBLE_EQ(u[0], demo.u(0, t)) << t;
    EXPECT_DOUBLE_EQ(u[1], demo.u(2, t)) << t;
    EXPECT_TRUE(file.controller.K[t].isZero()) << t;
    EXPECT_TRUE(file.controller.covariance(t).isApprox(1e-6 * Eigen::MatrixXd::Identity(2, 2))) << t;
  }
  EXPECT_EQ(policy.mismatch(kJoints, kCylinders, {}, layout), "");
}

TEST(DemonstrationPolicy, MetadataIsTheTasksAndTheFileRoundTrips) {
  const adroit::TrainingTask task = pickupTask();
  const adroit::StateLayout layout = layoutOf(task);
  const adroit::PolicyFile file = adroit::demonstrationReplayPolicy(demonstration(layout, task.horizon + 1), task, layout);
  EXPECT_EQ(file.task, "pickup");
  EXPECT_EQ(file.scene, "tube");
  EXPECT_EQ(file.state_layout, layout.describe());
  EXPECT_DOUBLE_EQ(file.control_dt, 0.04);
  EXPECT_EQ(file.joints, kJoints);
  EXPECT_EQ(file.cylinders, kCylinders);
  EXPECT_DOUBLE_EQ(file.locked_command, 0.5);
  EXPECT_EQ(file.iteration, 0);
  EXPECT_TRUE(std::isnan(file.cost_mean));
  const std::string path = std::string(::testing::TempDir()) + "/demonstration_policy.tvlg";
  adroit::writePolicyFile(path, file);
  const adroit::PolicyFile back = adroit::readPolicyFile(path);
  for (int t = 0; t < task.horizon; ++t) EXPECT_TRUE(back.controller.k[t].isApprox(file.controller.k[t])) << t;
  std::filesystem::remove(path);
}

TEST(DemonstrationPolicy, TooShortOrForeignDemonstrationsAreRefused) {
  const adroit::TrainingTask task = pickupTask();
  const adroit::StateLayout layout = layoutOf(task);
  try {
    adroit::demonstrationReplayPolicy(demonstration(layout, task.horizon), task, layout);  // T samples, needs T + 1
    FAIL() << "a too-short demonstration was accepted";
  } catch (const adroit::DemonstrationError& e) {
    EXPECT_NE(std::string(e.what()).find("too short"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/tmp/demo.txt"), std::string::npos) << e.what();
  }
  adroit::Demonstration other = demonstration(layout, task.horizon + 1);
  other.task = "rotate_vertical_cw";
  EXPECT_THROW(adroit::demonstrationReplayPolicy(other, task, layout), adroit::DemonstrationError);
  adroit::Demonstration force = demonstration(layout, task.horizon + 1);
  force.actions = "force";
  EXPECT_THROW(adroit::demonstrationReplayPolicy(force, task, layout), adroit::DemonstrationError);
}

}  // namespace
