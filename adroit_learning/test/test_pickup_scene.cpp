// The pickup tasks on the real pickup scene (adroit_description): the geometry the criterion
// reads from the model, the initial tube pose the task files ask for (clear of the zero-pose
// hand, resting on the table), and the trainer's outcome from a real initial state.
#include <adroit_learning/pickup.h>
#include <adroit_learning/sim_rollouts.h>
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <cmath>
#include <memory>

namespace {

struct Model {
  Model() {
    char error[1000] = "";
    m = mj_loadXML((std::string(ADROIT_MJCF_DIR) + "/pickup.xml").c_str(), nullptr, error, sizeof(error));
    if (m) d = mj_makeData(m);
    load_error = error;
  }
  ~Model() {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
  }
  mjModel* m = nullptr;
  mjData* d = nullptr;
  std::string load_error;
};

// Deepest penetration (m, negative) of the tube into any hand geom, and whether it touches the table.
double handPenetration(const Model& model, const std::vector<double>& qpos, bool& on_table) {
  std::copy(qpos.begin(), qpos.end(), model.d->qpos);
  mj_forward(model.m, model.d);
  const int tube = mj_name2id(model.m, mjOBJ_GEOM, "C_object"), table = mj_name2id(model.m, mjOBJ_GEOM, "table");
  double worst = 0;
  on_table = false;
  for (int c = 0; c < model.d->ncon; ++c) {
    const mjContact& k = model.d->contact[c];
    const int other = k.geom1 == tube ? k.geom2 : k.geom2 == tube ? k.geom1 : -1;
    if (other == table) on_table = true;
    else if (other >= 0 && model.m->geom_bodyid[other] != 0) worst = std::min(worst, k.dist);
  }
  return worst;
}

}  // namespace

TEST(PickupScene, GeometryComesFromTheModel) {
  Model model;
  ASSERT_NE(model.m, nullptr) << model.load_error;
  const adroit::ObjectGeometry g = adroit::objectGeometry(model.m);
  ASSERT_TRUE(g.valid());
  // generate_model.py: capsule of radius 22 mm and half-length 12 cm, turned onto body x; the
  // table's top is at z = 0.
  EXPECT_DOUBLE_EQ(g.half_length, 0.12);
  EXPECT_DOUBLE_EQ(g.radius, 0.022);
  EXPECT_NEAR(g.axis_in_body.x(), 1.0, 1e-4);
  EXPECT_NEAR(g.table_top, 0.0, 1e-12);
  // The tube scene's hand has no free object geometry in the hand-only scene.
  char error[1000] = "";
  mjModel* hand = mj_loadXML((std::string(ADROIT_MJCF_DIR) + "/hand.xml").c_str(), nullptr, error, sizeof(error));
  ASSERT_NE(hand, nullptr) << error;
  EXPECT_FALSE(adroit::objectGeometry(hand).valid());
  mj_deleteModel(hand);
}

TEST(PickupScene, TaskFilesStartTheTubeOnTheTableClearOfTheZeroPoseHand) {
  Model model;
  ASSERT_NE(model.m, nullptr) << model.load_error;
  const int adr = model.m->jnt_qposadr[model.m->body_jntadr[mj_name2id(model.m, mjOBJ_BODY, "object")]];
  for (const char* name : {"pickup", "pickup_from_scratch"}) {
    SCOPED_TRACE(name);
    const adroit::TrainingTask task = adroit::findTrainingTask(TASK_DIR, name);
    EXPECT_TRUE(task.pickupSuccessCriterion());
    ASSERT_TRUE(task.initial_object_yaw.has_value());
    const std::vector<double> qpos = adroit::initialQpos(model.m, task, {}, {});
    for (int j = 0; j < adr; ++j) EXPECT_EQ(qpos[j], 0.0) << j;  // the zero pose (10.2)
    bool on_table = false;
    EXPECT_GE(handPenetration(model, qpos, on_table), 0.0);
    EXPECT_TRUE(on_table);
    // 11.3 varies the tube's orientation over 180 degrees: the zero-pose hand clears it at every one.
    for (int yaw = 0; yaw < 180; yaw += 5) {
      const std::vector<double> turned = adroit::initialQpos(model.m, task, {}, {}, yaw);
      EXPECT_GE(handPenetration(model, turned, on_table), 0.0) << yaw << " deg";
      EXPECT_TRUE(on_table) << yaw << " deg";
    }
    EXPECT_NEAR(qpos[adr + 2], 0.022, 1e-12);  // resting: centre at the radius
  }
  // pickup.yaml's 10.4 weights.
  const adroit::TrainingTask pickup = adroit::findTrainingTask(TASK_DIR, "pickup");
  EXPECT_DOUBLE_EQ(pickup.joint_weight, 1.0);
  EXPECT_DOUBLE_EQ(pickup.action_weight, 0.1);
  EXPECT_DOUBLE_EQ(pickup.object_height_weight, 50.0);
  EXPECT_DOUBLE_EQ(pickup.object_height_target, 0.12);
  EXPECT_DOUBLE_EQ(pickup.final_scale * pickup.final_joint_weight, pickup.joint_weight);  // l_T = l_t without u
}

TEST(PickupScene, YawTurnsTheTubeInTheModel) {
  Model model;
  ASSERT_NE(model.m, nullptr) << model.load_error;
  adroit::TrainingTask task = adroit::findTrainingTask(TASK_DIR, "pickup");
  task.initial_object_position = {0.0, 0.1, 0.022};  // in front of the hand, clear at any yaw
  const int body = mj_name2id(model.m, mjOBJ_BODY, "object");
  const int geom = mj_name2id(model.m, mjOBJ_GEOM, "C_object");
  for (double deg : {0.0, 60.0, 90.0, 150.0}) {
    task.initial_object_yaw = deg;
    const std::vector<double> qpos = adroit::initialQpos(model.m, task, {}, {});
    std::copy(qpos.begin(), qpos.end(), model.d->qpos);
    mj_kinematics(model.m, model.d);
    // MuJoCo's own pose of the capsule: its axis is the geom frame's z (column 2 of geom_xmat).
    const double* R = model.d->geom_xmat + 9 * geom;
    const double ax = R[2], ay = R[5], az = R[8];
    EXPECT_NEAR(ax, std::cos(deg * M_PI / 180), 1e-4) << deg;
    EXPECT_NEAR(ay, std::sin(deg * M_PI / 180), 1e-4) << deg;
    EXPECT_NEAR(az, 0.0, 1e-4) << deg;
    EXPECT_NEAR(model.d->xpos[3 * body + 1], 0.1, 1e-12);
  }
}

TEST(PickupScene, OutcomeFromTheRealInitialState) {
  adroit::driver::SimConfig config;
  config.model_path = std::string(ADROIT_MJCF_DIR) + "/pickup.xml";
  config.mode = adroit::driver::ActuationMode::kPneumatic;
  adroit::SimRollouts sim(config, 1);
  adroit::TrainingTask task = adroit::findTrainingTask(TASK_DIR, "pickup");
  const adroit::StateLayout layout(task, sim.jointNames(), sim.cylinderNames(), sim.hasObject());
  ASSERT_TRUE(layout.hasObject());
  const Eigen::VectorXd x0 = sim.initialState(task, layout);
  const adroit::TrajectoryCost cost(task, layout, x0, sim.objectGeometry());
  adroit::Rollout r;
  r.x = x0.replicate(1, task.horizon + 1);
  r.u = Eigen::MatrixXd::Zero(layout.nu(), task.horizon);
  EXPECT_NEAR(x0[layout.objectPosition() + 2], 0.022, 0.003);  // the sensed tube, on the table
  adroit::TaskOutcome o = cost.outcome(r);  // never lifted
  EXPECT_FALSE(o.success);
  EXPECT_EQ(o.failure, "an end is below the lift height");
  // The same state with the tube lifted to 12 cm and at rest: success, and the height term
  // is zero there (101 steps of 50 (0.022 - 0.12)^2 before).
  const double before = cost.rolloutCost(r);
  r.x.col(task.horizon)[layout.objectPosition() + 2] = 0.12;
  r.x.col(task.horizon).segment(layout.qdot() + layout.joints(), 6).setZero();
  o = cost.outcome(r);
  EXPECT_TRUE(o.success) << o.failure;
  const double z0 = x0[layout.objectPosition() + 2];
  EXPECT_NEAR(before - cost.rolloutCost(r), 50 * std::pow(z0 - 0.12, 2), 1e-9);
}
