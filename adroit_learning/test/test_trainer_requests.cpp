// The trainer's request checks and its learning-curve plot: a count over int range is named
// with its value, durations that are not finite or out of range are refused before any
// conversion, and the plot runs as an argument vector: a request's output directory is never
// shell text.
#include <adroit_learning/trainer_requests.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

namespace fs = std::filesystem;

TEST(TrainerRequests, CountsOutOfRangeGiveTheirValue) {
  EXPECT_EQ(adroit::countProblem("iterations", 3000000000u, 1, adroit::kMaxTrainIterations),
            "iterations must be in [1, 10000], got 3000000000");  // was "iterations must be positive"
  EXPECT_EQ(adroit::countProblem("iterations", 0, 1, 10), "iterations must be in [1, 10], got 0");
  EXPECT_EQ(adroit::countProblem("iterations", 10, 1, 10), "");
}

TEST(TrainerRequests, DurationMustBeFiniteAndInRange) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(adroit::executeDurationProblem(0), "");
  EXPECT_EQ(adroit::executeDurationProblem(2.5), "");
  EXPECT_EQ(adroit::executeDurationProblem(inf), "duration must be 0 (the whole policy) or in (0, 3600] s, got inf");
  EXPECT_EQ(adroit::executeDurationProblem(std::nan("")),
            "duration must be 0 (the whole policy) or in (0, 3600] s, got nan");
  EXPECT_EQ(adroit::executeDurationProblem(-1), "duration must be 0 (the whole policy) or in (0, 3600] s, got -1");
  EXPECT_EQ(adroit::executeDurationProblem(1e300),
            "duration must be 0 (the whole policy) or in (0, 3600] s, got 1e+300");
  EXPECT_EQ(adroit::executeHorizon(50, 0.04, 0), 50);
  EXPECT_EQ(adroit::executeHorizon(50, 0.04, 1.0), 25);
  EXPECT_EQ(adroit::executeHorizon(50, 0.04, 1e-9), 1);
  EXPECT_EQ(adroit::executeHorizon(50, 0.001, 3600), 50);
}

TEST(TrainerRequests, PlotOutputDirectoryIsNeverShellText) {
  const fs::path base = fs::temp_directory_path() / ("plot_injection_" + std::to_string(::getpid()));
  fs::remove_all(base);
  const fs::path marker = base / "marker";
  // The probe's output_dir: in single quotes through a shell this ran `touch`.
  const std::string dir = base.string() + "/q'; touch " + marker.string() + "; echo '";
  fs::create_directories(dir);
  std::ofstream(dir + "/learning_curve.csv")
      << "iteration,ok,cost_mean,cost_std,joint_rms_mean\n0,1,10,1,0.5\n1,1,5,1,0.2\n";
  const std::vector<std::string> argv = adroit::learningCurvePlotCommand(PLOT_SCRIPT, dir);
  ASSERT_EQ(argv.size(), 4u);
  EXPECT_EQ(argv[2], dir + "/learning_curve.csv");  // one argument, as it is
  const adroit::ProgramResult r = adroit::plotLearningCurve(PLOT_SCRIPT, dir);
  EXPECT_TRUE(r.started) << r.describe();
  EXPECT_FALSE(fs::exists(marker));
  EXPECT_TRUE(r.ok()) << r.describe();  // the plot is still written
  EXPECT_TRUE(fs::exists(dir + "/learning_curve.png"));
  fs::remove_all(base);
}
