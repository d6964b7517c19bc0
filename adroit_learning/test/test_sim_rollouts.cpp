// In-process rollouts on the simulated robot (adroit_driver's SimulatedRobot, hand scene,
// pneumatic plant): rollouts depend only on their request, the initial state is the task's,
// and a controller that produces non-finite commands is reported, not run. Policies run
// through the same loop: a TVLG policy's rollout is the trainer's with zero noise, and a
// request's object yaw turns the tube (tube scene).
#include <adroit_learning/policy_library.h>
#include <adroit_learning/sim_rollouts.h>
#include <adroit_learning/tvlg_policy.h>
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <limits>

namespace {

adroit::driver::SimConfig sceneConfig(const std::string& scene) {
  adroit::driver::SimConfig config;
  config.model_path = std::string(ADROIT_MJCF_DIR) + "/" + scene + ".xml";
  config.mode = adroit::driver::ActuationMode::kPneumatic;
  return config;
}

struct Fixture {
  explicit Fixture(const std::string& task_name = "position_with_gravity")
      : task(adroit::findTrainingTask(TASK_DIR, task_name)), sim(sceneConfig(task.scene), 2),
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
    adroit::RolloutRequest r;
    r.noise = adroit::smoothedNoise(rng, layout.nu(), task.horizon, 1.0);
    return r;
  }
  // A policy file of this task and robot around `c` (what the trainer writes).
  adroit::PolicyFile policyFile(const adroit::LgController& c) const {
    adroit::PolicyFile p;
    p.task = task.name;
    p.scene = task.scene;
    p.state_layout = layout.describe();
    p.control_dt = task.control_dt;
    p.joints = layout.joint_names;
    p.cylinders = layout.cylinder_names;
    for (int i : layout.action_cylinders) p.actions.push_back(layout.cylinder_names[i]);
    p.locked_command = layout.locked_command;
    p.controller = c;
    return p;
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

TEST(SimRollouts, TvlgPolicyRunsAsTheTrainersControllerWithZeroNoise) {
  Fixture f;
  for (int t = 0; t < f.task.horizon; ++t) {  // gains on the state, so the feedback path counts
    f.controller.K[t] = 0.02 * Eigen::MatrixXd::Random(f.layout.nu(), f.layout.nx());
    f.controller.k[t] = Eigen::VectorXd::Random(f.layout.nu());
  }
  adroit::RolloutRequest zero;
  zero.noise = Eigen::MatrixXd::Zero(f.layout.nu(), f.task.horizon);
  const auto trainer = f.sim.run(f.task, f.layout, f.controller, {zero}, f.cancel);
  const auto file = std::make_shared<const adroit::PolicyFile>(f.policyFile(f.controller));
  const adroit::PolicyFactory tvlg = [&] { return std::make_unique<adroit::TvlgPolicy>(file, "test.tvlg"); };
  const auto policy = f.sim.runPolicy(f.task, f.layout, tvlg, {adroit::RolloutRequest{}, adroit::RolloutRequest{}}, 0,
                                      f.cancel);
  ASSERT_TRUE(trainer[0].ok) << trainer[0].error;
  for (const auto& r : policy) {
    ASSERT_TRUE(r.ok) << r.error;
    EXPECT_EQ(r.sample.x, trainer[0].sample.x);  // exactly: the same loop, the same products
    EXPECT_EQ(r.sample.u, trainer[0].sample.u);
  }
  EXPECT_GT((trainer[0].sample.x.col(f.task.horizon) - trainer[0].sample.x.col(0)).norm(), 0.1);  // it moved
  // Fewer steps than the horizon run; more are refused, as is a policy for another robot.
  EXPECT_EQ(f.sim.runPolicy(f.task, f.layout, tvlg, {adroit::RolloutRequest{}}, 3, f.cancel)[0].sample.u.cols(), 3);
  EXPECT_EQ(f.sim.runPolicy(f.task, f.layout, tvlg, {adroit::RolloutRequest{}}, 11, f.cancel)[0].error,
            "the tvlg policy is defined for 10 steps, asked for 11");
  adroit::PolicyFile other = *file;
  other.joints[0] = "XXJ0";
  const adroit::PolicyFactory foreign = [&] { return std::make_unique<adroit::TvlgPolicy>(other, "other.tvlg"); };
  EXPECT_NE(f.sim.runPolicy(f.task, f.layout, foreign, {adroit::RolloutRequest{}}, 0, f.cancel)[0].error.find("other.tvlg: joints differ"),
            std::string::npos);
}

namespace {

// The tube's yaw (degrees) in state x of the tube task's layout.
double tubeYawIn(const Fixture& f, const Eigen::VectorXd& x) {
  const Eigen::Vector3d rv = x.segment<3>(f.layout.objectRotation());
  const Eigen::Quaterniond q(Eigen::AngleAxisd(rv.norm(), rv.normalized()));
  return adroit::tubeYawDegrees(q, f.sim.objectGeometry());
}

// A library of two constant-command local policies of the tube task: `volts[i]` at yaw `yaws[i]`.
adroit::PolicyLibrary constantLibrary(const Fixture& f, const std::vector<double>& yaws, const std::vector<double>& volts) {
  adroit::PolicyLibrary library;
  library.task = f.task.name;
  library.scene = f.task.scene;
  for (std::size_t i = 0; i < yaws.size(); ++i) {
    adroit::LgController c(f.layout.nx(), f.layout.nu(), f.task.horizon);
    for (auto& k : c.k) k.setConstant(volts[i]);
    adroit::PolicyLibraryEntry e{yaws[i], "local" + std::to_string(i) + ".tvlg", nullptr, ""};
    e.policy = std::make_shared<const adroit::PolicyFile>(f.policyFile(c));
    library.entries.push_back(e);
  }
  return library;
}

}  // namespace

TEST(SimRollouts, ObjectYawOverrideTurnsTheTubeAndTheLibraryFollows) {
  Fixture f("pickup");
  f.task.horizon = 2;
  const auto library = std::make_shared<const adroit::PolicyLibrary>(constantLibrary(f, {0, 90}, {0.5, -0.5}));
  const adroit::LibraryPolicy prototype(library, f.sim.objectGeometry(), "tube.library");
  const adroit::PolicyFactory make = [&] { return std::make_unique<adroit::LibraryPolicy>(prototype); };
  std::vector<adroit::RolloutRequest> requests(5);
  const std::vector<double> yaws = {12, 80, 168, 100};
  for (std::size_t i = 0; i < yaws.size(); ++i) requests[i].object_yaw_deg = yaws[i];
  requests[4].object_yaw_deg = 180;  // outside [0, 180)
  const auto results = f.sim.runPolicy(f.task, f.layout, make, requests, 0, f.cancel);
  for (std::size_t i = 0; i < yaws.size(); ++i) {
    ASSERT_TRUE(results[i].ok) << yaws[i] << ": " << results[i].error;
    EXPECT_NEAR(tubeYawIn(f, results[i].sample.x.col(0)), yaws[i], 0.5);
    // 12 and 168 are nearest to 0 (across 180), 80 and 100 to 90.
    const double expected = (yaws[i] < 45 || yaws[i] > 135) ? 0.5 : -0.5;
    EXPECT_TRUE((results[i].sample.u.array() == expected).all()) << yaws[i];
  }
  EXPECT_EQ(results[4].error, "object_yaw_deg must be in [0, 180) degrees, got 180");
  // Without an override the task's own yaw (0) holds.
  const auto own = f.sim.runPolicy(f.task, f.layout, make, {adroit::RolloutRequest{}}, 0, f.cancel);
  ASSERT_TRUE(own[0].ok) << own[0].error;
  const double yaw = tubeYawIn(f, own[0].sample.x.col(0));
  EXPECT_LT(std::min(yaw, 180.0 - yaw), 0.5);
}
