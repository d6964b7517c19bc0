// The trainer's loop on a small linear "robot" (two joints driven through first-order
// pressure chambers): it learns to reach the targets, aborts an iteration whose rollouts fail
// without touching the controller or the saved policies, and stops when cancelled.
#include <adroit_learning/trainer.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <string>

namespace {

constexpr double kAtm = 101325.0;

// x: joint angles q, velocities v, chamber gauge pressures s (bar). Per control step dt:
//   s' = s + 0.5 u,  v' = 0.8 v + dt (3 s_0 - 1.5 s_1, 2 s_1 - 1 q_1),  q' = q + dt v'.
class LinearRobot : public adroit::RolloutBackend {
 public:
  std::string name() const override { return "linear"; }
  std::vector<std::string> jointNames() const override { return {"J0", "J1"}; }
  std::vector<std::string> cylinderNames() const override { return {"C0", "C1"}; }
  bool hasObject() const override { return false; }
  std::vector<double> jointRanges() const override { return {2.0, 2.0}; }
  Eigen::VectorXd initialState(const adroit::TrainingTask&, const adroit::StateLayout& layout) override {
    Eigen::VectorXd x(layout.nx());
    layout.state(observation(State{}), x);
    return x;
  }
  std::vector<adroit::RolloutResult> run(const adroit::TrainingTask& task, const adroit::StateLayout& layout,
                                         const adroit::LgController& controller,
                                         const std::vector<adroit::RolloutRequest>& requests,
                                         const std::atomic<bool>& cancel) override {
    ++calls;
    std::vector<adroit::RolloutResult> out;
    for (const auto& r : requests) {
      State s;
      int step = 0;
      out.push_back(adroit::runControlLoop(
          layout, controller, r.noise, cancel,
          [&](adroit::Observation& obs, std::string&) {
            obs = observation(s);
            if (calls == nan_on_call && step == 3) obs.joint_position[1] = std::numeric_limits<double>::quiet_NaN();
            return true;
          },
          [&](const std::vector<double>& volts, std::string&) {
            u0 = volts[0], u1 = volts[1];
            return true;
          },
          [&](std::string&) {
            const double dt = task.control_dt;
            s.p0 += 0.5 * u0, s.p1 += 0.5 * u1;
            s.v0 = 0.8 * s.v0 + dt * (3 * s.p0 - 1.5 * s.p1);
            s.v1 = 0.8 * s.v1 + dt * (2 * s.p1 - s.q1);
            s.q0 += dt * s.v0, s.q1 += dt * s.v1;
            ++step;
            return true;
          }));
    }
    return out;
  }
  int calls = 0, nan_on_call = -1;

 private:
  struct State {
    double q0 = 0, q1 = 0, v0 = 0, v1 = 0, p0 = 0, p1 = 0;
  };
  static adroit::Observation observation(const State& s) {
    adroit::Observation o;
    o.joint_position = {s.q0, s.q1};
    o.joint_velocity = {s.v0, s.v1};
    o.pressure = {kAtm + 1e5 * s.p0, kAtm + 1e5 * s.p1};
    return o;
  }
  double u0 = 0, u1 = 0;
};

adroit::TrainingTask linearTask() {
  adroit::TrainingTask t;
  t.name = "reach";
  t.scene = "linear";
  t.horizon = 20;
  t.control_dt = 0.05;
  t.target_joints = {{"J0", 0.5}, {"J1", -0.3}};
  t.initial_variance = 0.1;
  t.epsilon = 1.0;
  return t;
}

std::string outDir(const std::string& name) {
  const std::string dir = std::string(::testing::TempDir()) + "/" + name;
  ::mkdir(dir.c_str(), 0755);
  return dir;
}

int lines(const std::string& path) {
  std::ifstream in(path);
  int n = 0;
  for (std::string line; std::getline(in, line);) ++n;
  return n;
}

}  // namespace

TEST(Trainer, LearnsToReachOnALinearRobot) {
  LinearRobot robot;
  adroit::TrainerSettings settings;
  settings.iterations = 10;
  settings.seed = 3;
  settings.output_dir = outDir("trainer_reach");
  adroit::Trainer trainer(linearTask(), settings, robot);
  std::vector<adroit::IterationReport> reports;
  while (!trainer.finished()) {
    reports.push_back(trainer.iterate());
    ASSERT_TRUE(reports.back().ok) << reports.back().message;
    EXPECT_LE(reports.back().kl, 1.1 * reports.back().epsilon + 1e-9);
  }
  EXPECT_LT(reports.back().cost_mean, 0.2 * reports.front().cost_mean);
  EXPECT_LT(reports.back().joint_rms_mean, 0.5 * reports.front().joint_rms_mean);
  EXPECT_EQ(lines(settings.output_dir + "/learning_curve.csv"), 1 + settings.iterations);
  const adroit::PolicyFile last = adroit::readPolicyFile(reports.back().policy_path);
  EXPECT_EQ(last.iteration, settings.iterations - 1);
  EXPECT_DOUBLE_EQ(last.cost_mean, reports.back().cost_mean);
}

TEST(Trainer, FailedRolloutAbortsTheIterationAndKeepsPolicies) {
  LinearRobot robot;
  robot.nan_on_call = 3;  // the third iteration's rollouts see a NaN joint angle
  adroit::TrainerSettings settings;
  settings.iterations = 4;
  settings.output_dir = outDir("trainer_abort");
  adroit::Trainer trainer(linearTask(), settings, robot);
  trainer.iterate();
  const adroit::IterationReport second = trainer.iterate();
  ASSERT_TRUE(second.ok);
  const std::string saved = second.policy_path;
  const adroit::LgController before = trainer.controller();
  const adroit::IterationReport failed = trainer.iterate();
  EXPECT_FALSE(failed.ok);
  EXPECT_NE(failed.message.find("non-finite state at step 3"), std::string::npos) << failed.message;
  for (int t = 0; t < before.horizon(); ++t) EXPECT_EQ(trainer.controller().k[t], before.k[t]);
  EXPECT_EQ(adroit::readPolicyFile(saved).iteration, 1);
  EXPECT_TRUE(trainer.iterate().ok);  // training goes on after the failed iteration
}

TEST(Trainer, CancelEndsTheIteration) {
  LinearRobot robot;
  adroit::TrainerSettings settings;
  settings.iterations = 3;
  adroit::Trainer trainer(linearTask(), settings, robot);
  trainer.cancel();
  const adroit::IterationReport r = trainer.iterate();
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.message, "cancelled");
}

TEST(Trainer, SettingsAreChecked) {
  adroit::TrainerSettings s;
  EXPECT_EQ(adroit::validate(s), "");
  s.samples = 0;
  EXPECT_NE(adroit::validate(s).find("samples"), std::string::npos);
  s = {};
  s.iterations = 0;
  EXPECT_NE(adroit::validate(s).find("iterations"), std::string::npos);
  s = {};
  s.initial_state_noise = 1.5;
  EXPECT_NE(adroit::validate(s).find("initial-state noise"), std::string::npos);
  LinearRobot robot;
  adroit::TrainingTask task = linearTask();
  task.target_joints["J7"] = 0.1;
  EXPECT_THROW(adroit::Trainer(task, {}, robot), adroit::TaskError);
}

TEST(Trainer, InitialStateOffsetsSpanTheLevelOfEachJointsRange) {
  adroit::NormalNoise rng(7);
  const std::vector<double> range = {1.0, 0.2, 3.0};
  const double level = 0.1;
  std::vector<double> lowest(range.size(), 0), highest(range.size(), 0);
  for (int draw = 0; draw < 2000; ++draw) {
    const std::vector<double> offset = adroit::initialStateOffsets(rng, range, level);
    ASSERT_EQ(offset.size(), range.size());
    for (std::size_t j = 0; j < range.size(); ++j) {
      lowest[j] = std::min(lowest[j], offset[j]);
      highest[j] = std::max(highest[j], offset[j]);
    }
  }
  for (std::size_t j = 0; j < range.size(); ++j) {
    // Uniform in +-level/2 of the range: never outside, and 2000 draws reach close to both ends.
    EXPECT_GE(lowest[j], -0.5 * level * range[j]);
    EXPECT_LE(highest[j], 0.5 * level * range[j]);
    EXPECT_LT(lowest[j], -0.48 * level * range[j]);
    EXPECT_GT(highest[j], 0.48 * level * range[j]);
  }
  EXPECT_TRUE(adroit::initialStateOffsets(rng, range, 0.0) == std::vector<double>(range.size(), 0.0));
}
