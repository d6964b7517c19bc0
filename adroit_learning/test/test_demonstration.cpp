// Demonstrations for learning from imitation (thesis 10.4): reading what `demos export` writes,
// the refusals that keep a wrong recording from training anything, and what imitation takes
// from it (q_hat_t, the first controls, the tube's initial yaw).
#include <adroit_learning/demonstration.h>
#include <adroit_learning/trainer.h>
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace {

using adroit::Demonstration;
using adroit::DemonstrationError;

const std::vector<std::string> kJoints = {"J_a", "J_b"};
const std::vector<std::string> kCylinders = {"C_1", "C_2", "C_3"};

adroit::TrainingTask pickupTask() {
  adroit::TrainingTask task;
  task.name = "pickup";
  task.scene = "tube";
  task.horizon = 3;
  task.control_dt = 0.04;
  task.initial_object_yaw = 0.0;
  task.object_height_weight = 50;
  task.success_criterion = "pickup";
  task.initial_variance = 0.2;
  task.imitation_variance = 0.005;
  return task;
}

adroit::StateLayout layoutOf(const adroit::TrainingTask& task) {
  return adroit::StateLayout(task, kJoints, kCylinders, true);
}

adroit::ObjectGeometry tube() {
  adroit::ObjectGeometry g;
  g.half_length = 0.12;
  g.radius = 0.022;
  return g;
}

struct ExportOptions {
  std::string task = "pickup", mode = "pneumatic", model = "/share/adroit_description/mjcf/tube.xml";
  std::string actions = "valve";
  double dt = 0.04;
  int samples = 5;
  double yaw_degrees = 30;
  std::string bad_value;  // replaces X's first number when set
};

// The text `demos export` writes (adroit_teleop/scripts/demos: export, matrix_file_text):
// the same header lines and blocks, written here from the format, not from that code.
std::string exportText(const ExportOptions& o) {
  std::ostringstream out;
  out.precision(17);
  out << "# adroit demonstration (x_t, u_t), written by adroit_teleop demos export\n"
      << "# source: /tmp/demo.bag\n# task: " << o.task << "\n# mode: " << o.mode << "\n# model: " << o.model << "\n"
      << "# joints (2): J_a J_b\n# cylinders (3): C_1 C_2 C_3\n# object: yes (/adroit/object/odom)\n"
      << "# actions: " << o.actions << " [V] from /adroit/valve_command, one column per cylinder in the order above\n";
  const double half = o.yaw_degrees * M_PI / 360.0;  // rotation vector about z by the yaw
  out << "X " << o.samples << " 19\n";
  for (int t = 0; t < o.samples; ++t) {
    // q (2) | object position (3) | rotation vector (3) | qdot (2) | object velocities (6) | pressures (3)
    out << (t == 0 && !o.bad_value.empty() ? o.bad_value : std::to_string(0.1 * t)) << " " << -0.2 * t
        << " 0 -0.2 0.022 0 0 " << 2 * half << " 0 0 0 0 0 0 0 0 1.5 1.5 1.5\n";
  }
  out << "U " << o.samples << " 3\n";
  for (int t = 0; t < o.samples; ++t) out << t << " " << -t << " 0.5\n";
  out << "t " << o.samples << " 1\n";
  for (int t = 0; t < o.samples; ++t) out << o.dt * t << "\n";
  out << "dt 1 1\n" << o.dt << "\n";
  return out.str();
}

std::string writeTemp(const std::string& text) {
  char name[] = "/tmp/test_demonstration_XXXXXX";
  const int fd = mkstemp(name);
  EXPECT_GE(fd, 0);
  EXPECT_EQ(write(fd, text.data(), text.size()), static_cast<ssize_t>(text.size()));
  close(fd);
  return name;
}

Demonstration readExport(const ExportOptions& o) {
  const std::string path = writeTemp(exportText(o));
  Demonstration demo = adroit::readDemonstrationFile(path);
  std::remove(path.c_str());
  return demo;
}

std::string mismatchOf(const ExportOptions& o) {
  const adroit::TrainingTask task = pickupTask();
  return adroit::demonstrationMismatch(readExport(o), task, layoutOf(task));
}

TEST(Demonstration, ReadsTheHeaderAndTheBlocksAsColumnsPerSample) {
  const Demonstration demo = readExport({});
  EXPECT_EQ(demo.task, "pickup");
  EXPECT_EQ(demo.mode, "pneumatic");
  EXPECT_EQ(demo.actions, "valve");
  EXPECT_EQ(demo.joints, kJoints);
  EXPECT_EQ(demo.cylinders, kCylinders);
  EXPECT_TRUE(demo.has_object);
  ASSERT_EQ(demo.samples(), 5);
  ASSERT_EQ(demo.x.rows(), 19);
  EXPECT_DOUBLE_EQ(demo.x(0, 2), 0.2);   // q of J_a at sample 2
  EXPECT_DOUBLE_EQ(demo.u(1, 3), -3.0);  // C_2 at sample 3
  EXPECT_DOUBLE_EQ(demo.dt, 0.04);
}

TEST(Demonstration, AFitDemonstrationHasNoMismatch) { EXPECT_EQ(mismatchOf({}), ""); }

TEST(Demonstration, RefusesAnotherTaskSceneModeOrStepOrAShortRecording) {
  ExportOptions other_task;
  other_task.task = "catch";
  EXPECT_NE(mismatchOf(other_task).find("recorded for task 'catch', not 'pickup'"), std::string::npos);
  ExportOptions other_scene;
  other_scene.model = "/share/adroit_description/mjcf/teleop_tube.xml";
  EXPECT_NE(mismatchOf(other_scene).find("scene 'teleop_tube'"), std::string::npos);
  ExportOptions force;
  force.actions = "force";
  EXPECT_NE(mismatchOf(force).find("force commands; the trainer learns valve commands"), std::string::npos);
  ExportOptions coarse;
  coarse.dt = 0.1;
  EXPECT_NE(mismatchOf(coarse).find("export with --dt 0.04"), std::string::npos);
  ExportOptions short_one;
  short_one.samples = 3;  // T = 3 needs 4 samples
  EXPECT_NE(mismatchOf(short_one).find("too short: 0.08 s, the task needs 0.12 s"), std::string::npos);
}

TEST(Demonstration, RefusesNonFiniteValuesAndFilesThatAreNotExports) {
  ExportOptions nan;
  nan.bad_value = "nan";
  EXPECT_THROW(readExport(nan), DemonstrationError);
  EXPECT_THROW(adroit::readDemonstrationFile(writeTemp("X 1 1\n0\n")), DemonstrationError);
  EXPECT_THROW(adroit::readDemonstrationFile("/nonexistent/demo.txt"), DemonstrationError);
  const std::string fifo = "/tmp/test_demonstration_fifo_" + std::to_string(getpid());
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_THROW(adroit::readDemonstrationFile(fifo), DemonstrationError);  // refused, not waited on
  std::remove(fifo.c_str());
  try {
    adroit::readDemonstrationFile(writeTemp("# task: pickup\nX 1 1\n0\n"));
    FAIL() << "a header without mode was read";
  } catch (const DemonstrationError& e) {
    EXPECT_NE(std::string(e.what()).find("no 'mode' line"), std::string::npos) << e.what();
  }
}

TEST(Demonstration, ImitationTakesQHatTheFirstControlsAndTheTubeYaw) {
  adroit::TrainingTask task = pickupTask();
  const adroit::StateLayout layout = layoutOf(task);
  const Demonstration demo = readExport({});
  adroit::imitateDemonstration(demo, layout, tube(), task);
  ASSERT_EQ(task.joint_reference.size(), 4u);  // T + 1
  EXPECT_DOUBLE_EQ(task.joint_reference[3][0], 0.3);
  EXPECT_DOUBLE_EQ(task.joint_reference[3][1], -0.6);
  EXPECT_NEAR(*task.initial_object_yaw, 30.0, 1e-9);
  EXPECT_DOUBLE_EQ(task.initial_variance, 0.005);  // "small random noise" around its controls
  const Eigen::MatrixXd u = adroit::demonstrationActions(demo, layout, task.horizon);
  ASSERT_EQ(u.rows(), 3);
  ASSERT_EQ(u.cols(), 3);
  EXPECT_DOUBLE_EQ(u(1, 2), -2.0);
}

TEST(Demonstration, YawOfTheSymmetricTubeWrapsIntoZeroTo180) {
  adroit::TrainingTask task = pickupTask();
  ExportOptions o;
  o.yaw_degrees = -20;  // the same lying tube as 160 degrees
  adroit::imitateDemonstration(readExport(o), layoutOf(task), tube(), task);
  EXPECT_NEAR(*task.initial_object_yaw, 160.0, 1e-9);
}

}  // namespace
