// In-process rollouts on the simulated robot (adroit_driver's SimulatedRobot, hand scene,
// pneumatic plant): rollouts depend only on their request, the initial state is the task's,
// and a controller that produces non-finite commands is reported, not run.
#include <adroit_learning/sim_rollouts.h>
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <limits>

namespace {

adroit::driver::SimConfig handConfig() {
  adroit::driver::SimConfig config;
  config.model_path = std::string(ADROIT_MJCF_DIR) + "/hand.xml";
  config.mode = adroit::driver::ActuationMode::kPneumatic;
  return config;
}

struct Fixture {
  Fixture() : task(adroit::findTrainingTask(TASK_DIR, "position_with_gravity")), sim(handConfig(), 2),
              layout(task, sim.jointNames(), sim.cylinderNames(), sim.hasObject()),
              controller(adroit::LgController::initial(layout.nx(), task.horizon,
                                                       Eigen::VectorXd::Zero(layout.nu()),
                                                       Eigen::VectorXd::Constant(layout.nu(), 1.0))) {
    task.horizon = 10;  // short rollouts keep the test quick
    controller = adroit::LgController::initial(layout.nx(), task.horizon, Eigen::VectorXd::Zero(layout.nu()),
                                               Eigen::VectorXd::Constant(layout.nu(), 1.0));
  }
  adroit::RolloutRequest request(std::uint64_t seed) {
    adroit::NormalNoise rng(seed);
    return {adroit::smoothedNoise(rng, layout.nu(), task.horizon, 1.0), {}};
  }
  adroit::TrainingTask task;
  adroit::SimRollouts sim;
  adroit::StateLayout layout;
  adroit::LgController controller;
  std::atomic<bool> cancel{false};
};

}  // namespace

TEST(SimRollouts, ResultsDependOnlyOnTheRequest) {
  Fixture f;
  EXPECT_EQ(f.layout.nu(), 40);                          // the hand's 40 cylinders
  EXPECT_EQ(f.layout.nx(), 2 * 24 + 40);                 // q, qdot, pressures
  // Requests 0 and 2 are the same and run on different workers, after different histories.
  const std::vector<adroit::RolloutRequest> requests = {f.request(1), f.request(2), f.request(1), f.request(3)};
  const auto results = f.sim.run(f.task, f.layout, f.controller, requests, f.cancel);
  ASSERT_EQ(results.size(), 4u);
  for (const auto& r : results) {
    ASSERT_TRUE(r.ok) << r.error;
    EXPECT_EQ(r.sample.x.cols(), f.task.horizon + 1);
    EXPECT_EQ(r.sample.u.cols(), f.task.horizon);
    EXPECT_TRUE(r.sample.x.allFinite());
    EXPECT_LE(r.sample.u.cwiseAbs().maxCoeff(), 5.0);  // clamped to the valves' range
  }
  EXPECT_EQ(results[0].sample.x, results[2].sample.x);
  EXPECT_NE(results[0].sample.x, results[1].sample.x);
  // The exploration moved the pressures away from the initial 250 kPa.
  const int p = f.layout.pressures();
  EXPECT_GT((results[1].sample.x.col(f.task.horizon).segment(p, 40).array() - 1.487).abs().maxCoeff(), 0.1);
}

TEST(SimRollouts, StartsAtTheTasksInitialState) {
  Fixture f;
  f.task.initial_joints = {{"FFJ2", 0.7}};
  const Eigen::VectorXd x0 = f.sim.initialState(f.task, f.layout);
  const int ffj2 = static_cast<int>(std::find(f.layout.joint_names.begin(), f.layout.joint_names.end(), "FFJ2") -
                                    f.layout.joint_names.begin());
  EXPECT_NEAR(x0[ffj2], 0.7, 0.01);  // sensor noise and quantisation only
  EXPECT_NEAR(x0[f.layout.pressures()], (250e3 - 101325.0) / 1e5, 0.05);
  adroit::RolloutRequest offset = f.request(4);
  offset.joint_offset.assign(f.layout.joints(), 0.0);
  offset.joint_offset[ffj2] = 0.2;
  const auto results = f.sim.run(f.task, f.layout, f.controller, {f.request(4), offset}, f.cancel);
  ASSERT_TRUE(results[0].ok && results[1].ok);
  EXPECT_NEAR(results[1].sample.x(ffj2, 0) - results[0].sample.x(ffj2, 0), 0.2, 0.01);
}

TEST(SimRollouts, NonFiniteControllerAndCancelAreReported) {
  Fixture f;
  f.controller.k[4](0) = std::numeric_limits<double>::quiet_NaN();
  auto results = f.sim.run(f.task, f.layout, f.controller, {f.request(5)}, f.cancel);
  EXPECT_FALSE(results[0].ok);
  EXPECT_NE(results[0].error.find("non-finite action at step 4"), std::string::npos) << results[0].error;
  f.cancel = true;
  results = f.sim.run(f.task, f.layout, f.controller, {f.request(5), f.request(6)}, f.cancel);
  for (const auto& r : results) EXPECT_EQ(r.error, "cancelled");
}

TEST(SimRollouts, InitialObjectPositionMovesTheObjectOnly) {
  char error[1000] = "";
  mjModel* model = mj_loadXML((std::string(ADROIT_MJCF_DIR) + "/tube.xml").c_str(), nullptr, error, sizeof(error));
  ASSERT_NE(model, nullptr) << error;
  adroit::TrainingTask task;
  task.name = "t";
  const std::vector<double> keyframe = adroit::initialQpos(model, task, {}, {});
  task.initial_object_position = {0.01, -0.2, 0.3};
  const std::vector<double> moved = adroit::initialQpos(model, task, {}, {});
  const int body = mj_name2id(model, mjOBJ_BODY, "object");
  ASSERT_GE(body, 0);
  const int adr = model->jnt_qposadr[model->body_jntadr[body]];
  for (int i = 0; i < model->nq; ++i) {
    if (i >= adr && i < adr + 3) EXPECT_DOUBLE_EQ(moved[i], task.initial_object_position[i - adr]);
    else EXPECT_DOUBLE_EQ(moved[i], keyframe[i]) << i;  // joints and the object's orientation
  }
  mjModel* hand = mj_loadXML((std::string(ADROIT_MJCF_DIR) + "/hand.xml").c_str(), nullptr, error, sizeof(error));
  ASSERT_NE(hand, nullptr) << error;
  EXPECT_THROW(adroit::initialQpos(hand, task, {}, {}), adroit::TaskError);
  mj_deleteModel(hand);
  mj_deleteModel(model);
}
