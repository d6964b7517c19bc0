// Task files: the shipped ones load; a bad file is refused with its name and the field.
#include <adroit_core/bounded_file.h>
#include <adroit_learning/training_task.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

std::string writeTemp(const std::string& name, const std::string& text) {
  const std::string path = std::string(::testing::TempDir()) + "/" + name;
  std::ofstream(path) << text;
  return path;
}

const char* kMinimal =
    "name: t\nscene: hand\nhorizon: 10\ncontrol_dt: 0.04\ntarget_joints: {FFJ2: 0.5}\n";

std::string loadError(const std::string& text) {
  const std::string path = writeTemp("bad.yaml", text);
  try {
    adroit::loadTrainingTask(path);
  } catch (const adroit::TaskError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(TrainingTask, ShippedTasksLoad) {
  const auto names = adroit::trainingTaskNames(TASK_DIR);
  ASSERT_GE(names.size(), 2u);
  for (const auto& name : names) {
    const adroit::TrainingTask task = adroit::findTrainingTask(TASK_DIR, name);
    EXPECT_EQ(task.name, name);
    EXPECT_GT(task.horizon, 0);
    EXPECT_GT(task.control_dt, 0);
    EXPECT_FALSE(task.target_joints.empty() && !task.uses_object()) << name;
  }
  const auto gravity = adroit::findTrainingTask(TASK_DIR, "position_with_gravity");
  EXPECT_DOUBLE_EQ(gravity.action_weight, 1e-3);   // thesis 8.4.1
  EXPECT_DOUBLE_EQ(gravity.final_joint_weight, 10.0);
}

TEST(TrainingTask, MinimalFileTakesDefaults) {
  const auto task = adroit::loadTrainingTask(writeTemp("ok.yaml", kMinimal));
  EXPECT_EQ(task.horizon, 10);
  EXPECT_DOUBLE_EQ(task.target_joints.at("FFJ2"), 0.5);
  EXPECT_DOUBLE_EQ(task.rotation_target.at(5, 10), 0.0);
}

TEST(TrainingTask, ErrorsNameFileAndField) {
  std::string e = loadError("name: t\nscene: hand\ncontrol_dt: 0.04\ntarget_joints: {FFJ2: 0.5}\n");
  EXPECT_NE(e.find("bad.yaml: horizon: missing"), std::string::npos) << e;
  e = loadError(std::string(kMinimal) + "action_weight: .nan\n");
  EXPECT_NE(e.find("action_weight: not finite"), std::string::npos) << e;
  e = loadError(std::string(kMinimal) + "epsilon: -1\n");
  EXPECT_NE(e.find("epsilon: must be in"), std::string::npos) << e;
  e = loadError(std::string(kMinimal) + "wieght: 1\n");
  EXPECT_NE(e.find("wieght: unknown field"), std::string::npos) << e;
  e = loadError("name: t\nscene: hand\nhorizon: 2.5\ncontrol_dt: 0.04\ntarget_joints: {FFJ2: 0.5}\n");
  EXPECT_NE(e.find("horizon: must be a whole number"), std::string::npos) << e;
  e = loadError(std::string(kMinimal) + "rotation_target: [[0, 1], [0.5, 2], [0.4, 0]]\n");
  EXPECT_NE(e.find("rotation_target[2]"), std::string::npos) << e;
  e = loadError("{{{");
  EXPECT_NE(e.find("not valid YAML"), std::string::npos) << e;
}

TEST(TrainingTask, UnknownTaskListsKnownOnes) {
  try {
    adroit::findTrainingTask(TASK_DIR, "juggle");
    FAIL() << "no error";
  } catch (const adroit::TaskError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("unknown task 'juggle'"), std::string::npos) << what;
    EXPECT_NE(what.find("position_with_gravity"), std::string::npos) << what;
  }
}

TEST(TrainingTask, ScheduleSwitchesAtItsFractions) {
  adroit::TargetSchedule s{{0.0, 0.5}, {1.0, -1.0}};
  EXPECT_DOUBLE_EQ(s.at(0, 10), 1.0);
  EXPECT_DOUBLE_EQ(s.at(4, 10), 1.0);
  EXPECT_DOUBLE_EQ(s.at(5, 10), -1.0);
  EXPECT_DOUBLE_EQ(s.at(10, 10), -1.0);
}

TEST(TrainingTask, InitialObjectPositionIsOptionalAndChecked) {
  const std::string object = "name: t\nscene: tube\nhorizon: 10\ncontrol_dt: 0.04\nobject_rotation_weight: 10\n";
  EXPECT_TRUE(adroit::loadTrainingTask(writeTemp("ok.yaml", object)).initial_object_position.empty());
  const auto task = adroit::loadTrainingTask(writeTemp("ok.yaml", object + "initial_object_position: [0.1, -0.2, 0.3]\n"));
  ASSERT_EQ(task.initial_object_position.size(), 3u);
  EXPECT_DOUBLE_EQ(task.initial_object_position[1], -0.2);
  std::string e = loadError(object + "initial_object_position: [0.1, 0.2]\n");
  EXPECT_NE(e.find("initial_object_position: expected [x, y, z]"), std::string::npos) << e;
  e = loadError(object + "initial_object_position: [0, 0, .inf]\n");
  EXPECT_NE(e.find("initial_object_position: not finite"), std::string::npos) << e;
  e = loadError(std::string(kMinimal) + "initial_object_position: [0, 0, 0.1]\n");
  EXPECT_NE(e.find("initial_object_position: only for tasks with object"), std::string::npos) << e;
}

TEST(TrainingTask, OnlyRegularFilesWithinTheLimitAreRead) {
  const auto error = [](const std::string& path) {
    try {
      adroit::loadTrainingTask(path);
    } catch (const adroit::TaskError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string dir = ::testing::TempDir() + "/task_files";
  std::filesystem::create_directories(dir);
  const std::string fifo = dir + "/fifo.yaml";
  ::unlink(fifo.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(error(fifo), fifo + ": not a regular file (a FIFO)");  // before: blocked for good
  EXPECT_EQ(error("/dev/zero"), "/dev/zero: not a regular file (a character device)");
  EXPECT_EQ(error(dir), dir + ": not a regular file (a directory)");
  const std::string big = dir + "/big.yaml";
  std::ofstream(big) << kMinimal;
  std::filesystem::resize_file(big, 2 * adroit::kMiB);
  EXPECT_EQ(error(big), big + ": 2 MB, over the limit of 1 MB");
  std::filesystem::remove_all(dir);
}

TEST(TrainingTask, UnknownTaskSuggestsTheNearestName) {
  try {
    adroit::findTrainingTask(TASK_DIR, "position_with_gravty");
    FAIL() << "no error";
  } catch (const adroit::TaskError& e) {
    EXPECT_NE(std::string(e.what()).find("(did you mean position_with_gravity?)"), std::string::npos) << e.what();
  }
}
