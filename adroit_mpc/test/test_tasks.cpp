// The three behaviour tasks on the installed planning scenes (bottle, ball, keypad): analytic
// cost derivatives against finite differences, cost shape, goals and phases, the factory, and
// that config/tasks/*.yaml holds the factory's defaults.
#include <gtest/gtest.h>

#include <adroit_core/mujoco_model.h>
#include <adroit_description/scenes.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "adroit_mpc/catch_task.h"
#include "adroit_mpc/planning_model.h"
#include "adroit_mpc/relocate_task.h"
#include "adroit_mpc/task.h"
#include "adroit_mpc/task_params.h"
#include "adroit_mpc/type_task.h"

namespace {

using adroit_mpc::CostDerivatives;
using adroit_mpc::Task;
using adroit_mpc::TaskParams;

constexpr int kSynergies = 5;

adroit::ModelPtr planningScene(const std::string& scene) {
  return adroit::loadModelFile(adroit::description::sceneFile(adroit_mpc::descriptionShareDir(), scene, true)).model;
}

void setKeyframe(const mjModel* m, mjData* d, const char* name) {
  const int key = mj_name2id(m, mjOBJ_KEY, name);
  ASSERT_GE(key, 0);
  mju_copy(d->qpos, m->key_qpos + key * m->nq, m->nq);
  mju_zero(d->qvel, m->nv);
}

// A control inside every actuator range and synergies in [-1, 1].
Eigen::VectorXd someControl(const mjModel* m) {
  Eigen::VectorXd u(m->nu + kSynergies);
  for (int i = 0; i < m->nu; ++i) {
    const double lo = m->actuator_ctrlrange[2 * i], hi = m->actuator_ctrlrange[2 * i + 1];
    u[i] = lo + (hi - lo) * (0.5 + 0.4 * std::sin(1.3 * i));
  }
  for (int j = 0; j < kSynergies; ++j) u[m->nu + j] = 0.8 * std::cos(2.1 * j);
  return u;
}

void addVelocities(const mjModel* m, mjData* d, double scale) {
  for (int i = 0; i < m->nv; ++i) d->qvel[i] = scale * std::sin(0.9 * i + 0.3);
}

// H + tolerance I has a Cholesky factor <=> every eigenvalue of H is above -tolerance.
bool positiveSemiDefinite(const Eigen::MatrixXd& H, double tolerance) {
  Eigen::MatrixXd shifted = H;
  shifted.diagonal().array() += tolerance;
  return shifted.llt().info() == Eigen::Success;
}

// Running and terminal cost derivatives of `task` at the state in `d` against central
// differences of the cost (dq through mj_integratePos, dv, u); Hessians symmetric PSD.
void checkDerivatives(const Task& task, const mjModel* m, mjData* d, const Eigen::VectorXd& u, double t,
                      const std::string& what) {
  auto scratch = task.makeScratch(m);
  const int nv = m->nv, nx = 2 * nv + m->na, nu = static_cast<int>(u.size());
  const Eigen::VectorXd qpos0 = Eigen::Map<Eigen::VectorXd>(d->qpos, m->nq);
  const Eigen::VectorXd qvel0 = Eigen::Map<Eigen::VectorXd>(d->qvel, nv);
  auto setState = [&](const Eigen::VectorXd& dx) {
    mju_copy(d->qpos, qpos0.data(), m->nq);
    mj_integratePos(m, d->qpos, dx.data(), 1.0);
    for (int i = 0; i < nv; ++i) d->qvel[i] = qvel0[i] + dx[nv + i];
    mj_forward(m, d);
  };
  for (const bool terminal : {false, true}) {
    const std::string label = what + (terminal ? " terminal" : " running");
    auto cost = [&](const Eigen::VectorXd& dx, const Eigen::VectorXd& du) {
      setState(dx);
      return terminal ? task.terminalCost(m, d, t, *scratch) : task.runningCost(m, d, u + du, t, *scratch);
    };
    CostDerivatives out;
    out.resize(nx, nu);
    out.lx.setConstant(7.0);  // the task must overwrite, not accumulate
    setState(Eigen::VectorXd::Zero(nx));
    const double value = terminal ? task.terminalCostDerivatives(m, d, t, *scratch, out)
                                  : task.runningCostDerivatives(m, d, u, t, *scratch, out);
    EXPECT_NEAR(value, cost(Eigen::VectorXd::Zero(nx), Eigen::VectorXd::Zero(nu)), 1e-9 * std::abs(value)) << label;
    const double eps = 1e-6;
    Eigen::VectorXd dx = Eigen::VectorXd::Zero(nx), du = Eigen::VectorXd::Zero(nu);
    int checked = 0;
    for (int i = 0; i < nx; ++i) {
      dx[i] = eps;
      const double plus = cost(dx, du);
      dx[i] = -eps;
      const double minus = cost(dx, du);
      dx[i] = 0;
      const double fd = (plus - minus) / (2 * eps);
      EXPECT_NEAR(out.lx[i], fd, 2e-5 * std::max(1.0, std::abs(fd))) << label << " dx " << i;
      checked += std::abs(fd) > 1e-6;
    }
    EXPECT_GT(checked, 3) << label << ": the state should make several terms active";
    for (int i = 0; i < nu && !terminal; ++i) {
      du[i] = eps;
      const double plus = cost(dx, du);
      du[i] = -eps;
      const double minus = cost(dx, du);
      du[i] = 0;
      EXPECT_NEAR(out.lu[i], (plus - minus) / (2 * eps), 1e-6) << label << " du " << i;
    }
    if (terminal) {
      EXPECT_EQ(out.lu.cwiseAbs().maxCoeff(), 0.0) << label;
      EXPECT_EQ(out.luu.cwiseAbs().maxCoeff(), 0.0) << label;
    }
    Eigen::MatrixXd H(nx + nu, nx + nu);
    H << out.lxx, out.lux.transpose(), out.lux, out.luu;
    EXPECT_LT((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-9 * std::max(1.0, H.norm())) << label;
    EXPECT_TRUE(positiveSemiDefinite(H, 1e-8 * std::max(1.0, H.norm()))) << label;
    setState(Eigen::VectorXd::Zero(nx));
  }
}

// ---------------------------------------------------------------------------------- catch

class CatchOnBottle : public ::testing::Test {
 protected:
  void SetUp() override {
    model = planningScene("bottle");
    data = adroit::makeData(model.get());
    task = adroit_mpc::makeTask("catch", {});
    task->bind(model.get(), kSynergies);
    setKeyframe(model.get(), data.get(), "rest");
    object_qpos = model->jnt_qposadr[mj_name2id(model.get(), mjOBJ_JOINT, "object_root")];
  }
  void placeObject(const Eigen::Vector3d& p, const Eigen::Quaterniond& q = Eigen::Quaterniond::Identity()) {
    for (int i = 0; i < 3; ++i) data->qpos[object_qpos + i] = p[i];
    data->qpos[object_qpos + 3] = q.w();
    data->qpos[object_qpos + 4] = q.x();
    data->qpos[object_qpos + 5] = q.y();
    data->qpos[object_qpos + 6] = q.z();
    mj_forward(model.get(), data.get());
  }
  adroit::ModelPtr model;
  adroit::DataPtr data;
  std::unique_ptr<Task> task;
  int object_qpos = 0;
  const Eigen::Vector3d goal{0.007, -0.19, 0.26};  // catch.yaml
};

TEST_F(CatchOnBottle, DerivativesMatchFiniteDifferences) {
  placeObject({0.02, -0.17, 0.30}, Eigen::Quaterniond(0.95, 0.1, 0.2, -0.15).normalized());
  addVelocities(model.get(), data.get(), 0.4);
  checkDerivatives(*task, model.get(), data.get(), someControl(model.get()), 0.0, "catch");
}

TEST_F(CatchOnBottle, CostFallsAsTheObjectApproachesTheGoal) {
  auto scratch = task->makeScratch(model.get());
  const Eigen::VectorXd u = someControl(model.get());
  double previous = INFINITY;
  for (double height : {0.12, 0.08, 0.04, 0.01, 0.0}) {
    placeObject(goal + Eigen::Vector3d(0, 0, height));
    const double cost = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
    EXPECT_LT(cost, previous) << height;
    EXPECT_NEAR(task->error(model.get(), data.get()), height, 1e-12);
    previous = cost;
  }
  // Velocity and orientation errors cost too.
  placeObject(goal);
  const double still = task->terminalCost(model.get(), data.get(), 0.0, *scratch);
  data->qvel[model->jnt_dofadr[mj_name2id(model.get(), mjOBJ_JOINT, "object_root")] + 2] = -1.0;
  mj_forward(model.get(), data.get());
  EXPECT_GT(task->terminalCost(model.get(), data.get(), 0.0, *scratch), still + 1.0);
  mju_zero(data->qvel, model->nv);
  placeObject(goal, Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ())));
  EXPECT_GT(task->terminalCost(model.get(), data.get(), 0.0, *scratch), still + 0.1);
  // ... but a spin about the bottle's own axis (body x) does not (orientation_axes 0 1 1).
  placeObject(goal, Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitX())));
  EXPECT_NEAR(task->terminalCost(model.get(), data.get(), 0.0, *scratch), still, 1e-9);
}

TEST_F(CatchOnBottle, ControlCostsAndSynergiesAreCheaper) {
  auto scratch = task->makeScratch(model.get());
  placeObject(goal);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(model->nu + kSynergies);
  const double base = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
  u[model->nu] = 1.0;  // one synergy fully on
  const double synergy = task->runningCost(model.get(), data.get(), u, 0.0, *scratch) - base;
  u.setZero();
  u[0] = model->actuator_ctrlrange[1];  // one actuator at its maximum
  const double actuator = task->runningCost(model.get(), data.get(), u, 0.0, *scratch) - base;
  EXPECT_NEAR(actuator, 0.5 * task->weight("w_control"), 1e-12);
  EXPECT_NEAR(synergy, 0.5 * task->weight("w_synergy"), 1e-12);
  EXPECT_LT(synergy, actuator);
  EXPECT_THROW(task->runningCost(model.get(), data.get(), Eigen::VectorXd::Zero(model->nu), 0.0, *scratch),
               std::invalid_argument);
}

TEST_F(CatchOnBottle, GoalChecks) {
  std::string why;
  EXPECT_TRUE(task->setGoal({0.0, -0.2, 0.3}, Eigen::Quaterniond(2, 0, 0, 0), &why)) << why;
  placeObject({0.0, -0.2, 0.3});
  EXPECT_NEAR(task->error(model.get(), data.get()), 0.0, 1e-12);
  EXPECT_FALSE(task->setGoal({0.0, -0.2, 1.0}, Eigen::Quaterniond::Identity(), &why));
  EXPECT_NE(why.find("outside the workspace"), std::string::npos) << why;
  EXPECT_FALSE(task->release(&why));
  EXPECT_FALSE(task->setSequence("12", &why));
}

TEST(CatchBinding, NeedsTheObjectAndTheGraspSite) {
  auto hand = planningScene("hand");
  auto task = adroit_mpc::makeTask("catch", {});
  try {
    task->bind(hand.get(), 0);
    FAIL() << "bound a scene without an object";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'object'"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------- relocate

class RelocateOnBall : public ::testing::Test {
 protected:
  void SetUp() override {
    model = planningScene("ball");
    data = adroit::makeData(model.get());
    task = adroit_mpc::makeTask("relocate", {});
    task->bind(model.get(), kSynergies);
    relocate = dynamic_cast<adroit_mpc::RelocateTask*>(task.get());
    ASSERT_NE(relocate, nullptr);
    setKeyframe(model.get(), data.get(), "rest");
    object_qpos = model->jnt_qposadr[mj_name2id(model.get(), mjOBJ_JOINT, "object_root")];
    mj_forward(model.get(), data.get());
  }
  void placeObject(const Eigen::Vector3d& p) {
    for (int i = 0; i < 3; ++i) data->qpos[object_qpos + i] = p[i];
    mj_forward(model.get(), data.get());
  }
  Eigen::Vector3d graspSite() const {
    return Eigen::Vector3d(data->site_xpos + 3 * mj_name2id(model.get(), mjOBJ_SITE, "S_grasp"));
  }
  adroit::ModelPtr model;
  adroit::DataPtr data;
  std::unique_ptr<Task> task;
  adroit_mpc::RelocateTask* relocate = nullptr;
  int object_qpos = 0;
};

// The scene is set up for a caught object (thesis 6.5): palm up at rest, the ball dropped from
// above the grasp envelope, the hold position just above the palm.
TEST_F(RelocateOnBall, TheBallFallsIntoThePalmUpHandAndIsHeldThere) {
  const int palm = mj_name2id(model.get(), mjOBJ_BODY, "palm");
  const double* R = data->xmat + 9 * palm;
  EXPECT_LT(R[7], -0.9);  // the palm's -y (its inner face) points up at rest
  const Eigen::Vector3d start(data->qpos + object_qpos);
  const Eigen::Vector3d grasp = graspSite();
  EXPECT_LT(std::hypot(start.x() - grasp.x(), start.y() - grasp.y()), 0.01);
  EXPECT_GT(start.z(), grasp.z() + 0.05);
  EXPECT_LT((relocate->holdPosition() - grasp).norm(), 0.03);
}

TEST_F(RelocateOnBall, HoldsUntilAGoalThenGoesThere) {
  EXPECT_EQ(relocate->phase(), adroit_mpc::RelocateTask::Phase::kHold);
  const Eigen::Vector3d hold = relocate->holdPosition();
  placeObject(hold + Eigen::Vector3d(0.03, 0, 0.04));
  EXPECT_NEAR(task->error(model.get(), data.get()), 0.05, 1e-12);
  std::string why;
  const Eigen::Vector3d goal = hold + Eigen::Vector3d(0.08, -0.05, -0.1);
  ASSERT_TRUE(task->setGoal(goal, Eigen::Quaterniond::Identity(), &why)) << why;
  EXPECT_EQ(relocate->phase(), adroit_mpc::RelocateTask::Phase::kGoal);
  placeObject(goal);
  EXPECT_NEAR(task->error(model.get(), data.get()), 0.0, 1e-12);
  const auto events = task->observe(model.get(), data.get(), 0.0);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind, "phase");
  EXPECT_EQ(events[0].detail, "goal");
  EXPECT_EQ(events[1].kind, "goal_reached");
  EXPECT_TRUE(task->observe(model.get(), data.get(), 0.1).empty());  // reported once
}

TEST_F(RelocateOnBall, SetGoalRejectsBadGoalsWithAReason) {
  std::string why;
  EXPECT_FALSE(task->setGoal({NAN, -0.2, 0.3}, Eigen::Quaterniond::Identity(), &why));
  EXPECT_NE(why.find("not finite"), std::string::npos) << why;
  EXPECT_FALSE(task->setGoal({0.0, -0.2, 0.3}, Eigen::Quaterniond(NAN, 0, 0, 0), &why));
  EXPECT_NE(why.find("orientation"), std::string::npos) << why;
  EXPECT_FALSE(task->setGoal({0.0, -0.2, 0.3}, Eigen::Quaterniond(0, 0, 0, 0), &why));
  EXPECT_NE(why.find("cannot be normalised"), std::string::npos) << why;
  // 10 cm beyond the box's far side (y 0), out of the arm's reach.
  EXPECT_FALSE(task->setGoal({0.0, 0.1, 0.3}, Eigen::Quaterniond::Identity(), &why));
  EXPECT_NE(why.find("outside the workspace box"), std::string::npos) << why;
  EXPECT_FALSE(task->setGoal({0.0, -0.2, 0.0}, Eigen::Quaterniond::Identity(), &why));  // at the table
  EXPECT_EQ(why.find('\n'), std::string::npos);
  EXPECT_EQ(relocate->phase(), adroit_mpc::RelocateTask::Phase::kHold);  // nothing taken
}

TEST_F(RelocateOnBall, ReleaseDropsTheGoalAndGraspTermsAndOpensTheHand) {
  auto scratch = task->makeScratch(model.get());
  std::string why;
  // Held at the grasp site, far from a goal: the goal term costs before the release only.
  ASSERT_TRUE(task->setGoal(relocate->holdPosition() + Eigen::Vector3d(0.1, 0, 0), Eigen::Quaterniond::Identity(),
                            &why));
  placeObject(graspSite());
  const double holding = task->terminalCost(model.get(), data.get(), 0.0, *scratch);
  ASSERT_TRUE(task->release(&why)) << why;
  EXPECT_EQ(relocate->phase(), adroit_mpc::RelocateTask::Phase::kRelease);
  EXPECT_FALSE(task->release(&why));
  EXPECT_NE(why.find("already released"), std::string::npos);
  const double released = task->terminalCost(model.get(), data.get(), 0.0, *scratch);
  EXPECT_GT(holding, released + 1.0);
  // At the rest keyframe and still, the released object costs nothing wherever it is...
  EXPECT_NEAR(released, 0.0, 1e-12);
  placeObject(graspSite() + Eigen::Vector3d(0, 0, -0.2));
  EXPECT_NEAR(task->terminalCost(model.get(), data.get(), 0.0, *scratch), 0.0, 1e-12);
  // ... and fingers curled away from rest do (the hand opens).
  data->qpos[mj_name2id(model.get(), mjOBJ_JOINT, "FFJ2")] += 0.5;
  mj_forward(model.get(), data.get());
  EXPECT_GT(task->terminalCost(model.get(), data.get(), 0.0, *scratch), 0.1);
  // A new goal takes the object there again.
  ASSERT_TRUE(task->setGoal(relocate->holdPosition(), Eigen::Quaterniond::Identity(), &why));
  EXPECT_EQ(relocate->phase(), adroit_mpc::RelocateTask::Phase::kGoal);
}

TEST_F(RelocateOnBall, ArmPostureTermHoldsTheArmAndOnlyTheArm) {
  auto scratch = task->makeScratch(model.get());
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(model->nu + kSynergies);
  // What the posture term adds for one joint turned away from rest (the same state with the
  // term's weight on and off).
  const auto added = [&](const char* joint, double by) {
    setKeyframe(model.get(), data.get(), "rest");
    data->qpos[model->jnt_qposadr[mj_name2id(model.get(), mjOBJ_JOINT, joint)]] += by;
    mj_forward(model.get(), data.get());
    placeObject(graspSite());
    task->setWeight("w_arm_posture", 1.0);
    const double on = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
    task->setWeight("w_arm_posture", 0.0);
    const double off = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
    return on - off;
  };
  EXPECT_NEAR(added("ARJ3", 0.0), 0.0, 1e-12);
  EXPECT_GT(added("ARJ3", 0.2), 0.01);
  EXPECT_GT(added("ARJ1", -0.2), 0.01);
  EXPECT_NEAR(added("FFJ2", 0.5), 0.0, 1e-12);  // a finger is free to curl
  EXPECT_NEAR(added("WRJ0", 0.3), 0.0, 1e-12);  // the wrist has its own term
}

TEST_F(RelocateOnBall, WristPostureTermKeepsThePalmLevelAndOnlyThat) {
  auto scratch = task->makeScratch(model.get());
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(model->nu + kSynergies);
  const auto added = [&](const char* joint, double by, double weight) {
    setKeyframe(model.get(), data.get(), "rest");
    data->qpos[model->jnt_qposadr[mj_name2id(model.get(), mjOBJ_JOINT, joint)]] += by;
    mj_forward(model.get(), data.get());
    placeObject(graspSite());
    task->setWeight("w_wrist_posture", weight);
    const double on = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
    task->setWeight("w_wrist_posture", 0.0);
    const double off = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
    return on - off;
  };
  EXPECT_NEAR(added("WRJ0", 0.0, 5.0), 0.0, 1e-12);
  EXPECT_GT(added("WRJ0", 0.3, 5.0), 0.01);
  EXPECT_GT(added("WRJ1", -0.2, 5.0), 0.01);
  EXPECT_NEAR(added("WRJ0", 0.3, 10.0), 2 * added("WRJ0", 0.3, 5.0), 1e-9);  // linear in its weight
  EXPECT_NEAR(added("ARJ1", 0.2, 5.0), 0.0, 1e-12);  // the arm is the other term's
  EXPECT_NEAR(added("FFJ2", 0.5, 5.0), 0.0, 1e-12);  // a finger is free to curl
}

TEST_F(RelocateOnBall, AnObjectOutOfReachIsLeftAlone) {
  auto scratch = task->makeScratch(model.get());
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(model->nu + kSynergies);
  std::string why;
  // In the hand: the goal counts (a goal further away costs more).
  placeObject(graspSite());
  EXPECT_TRUE(task->observe(model.get(), data.get(), 0.0).size() == 1u);  // the phase only
  EXPECT_TRUE(relocate->objectInReach());
  const double near_goal = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
  ASSERT_TRUE(task->setGoal(relocate->holdPosition() + Eigen::Vector3d(0.1, 0, 0), Eigen::Quaterniond::Identity(),
                            &why));
  EXPECT_GT(task->runningCost(model.get(), data.get(), u, 0.0, *scratch), near_goal + 0.1);
  // On the floor, 1 m away: out of reach, reported once; neither goal nor grasp hint pulls.
  placeObject({0.3, 0.5, -0.7});
  auto events = task->observe(model.get(), data.get(), 0.1);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().kind, "object");
  EXPECT_EQ(events.back().detail, "out of reach");
  EXPECT_FALSE(relocate->objectInReach());
  EXPECT_TRUE(task->observe(model.get(), data.get(), 0.2).empty());
  const double away = task->runningCost(model.get(), data.get(), u, 0.0, *scratch);
  ASSERT_TRUE(task->setGoal(relocate->holdPosition(), Eigen::Quaterniond::Identity(), &why));
  EXPECT_EQ(task->runningCost(model.get(), data.get(), u, 0.0, *scratch), away);
  // A planner's copy waits too; back in the hand, the terms return.
  auto copy = task->clone();
  copy->copyParametersFrom(*task);
  EXPECT_FALSE(dynamic_cast<adroit_mpc::RelocateTask&>(*copy).objectInReach());
  placeObject(graspSite());
  events = task->observe(model.get(), data.get(), 0.3);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events[0].kind, "object");
  EXPECT_EQ(events[0].detail, "in reach");  // (then goal_reached: the hold is 1.5 cm above the site)
  EXPECT_TRUE(relocate->objectInReach());
}

TEST_F(RelocateOnBall, DerivativesMatchFiniteDifferencesInEveryPhase) {
  // Off the keyframe so the posture terms are active.
  for (int j = 0; j < 4; ++j) data->qpos[j] += 0.1 * (j + 1);
  mj_forward(model.get(), data.get());
  placeObject(graspSite() + Eigen::Vector3d(0.01, -0.01, 0.02));
  addVelocities(model.get(), data.get(), 0.3);
  const Eigen::VectorXd u = someControl(model.get());
  checkDerivatives(*task, model.get(), data.get(), u, 0.0, "relocate hold");
  std::string why;
  ASSERT_TRUE(task->setGoal({0.05, -0.2, 0.35}, Eigen::Quaterniond::Identity(), &why));
  task->setWeight("w_goal_orientation", 0.5);  // exercise the orientation term too
  checkDerivatives(*task, model.get(), data.get(), u, 0.0, "relocate goal");
  ASSERT_TRUE(task->release(&why));
  checkDerivatives(*task, model.get(), data.get(), u, 0.0, "relocate release");
}

TEST_F(RelocateOnBall, CopyParametersCopiesGoalPhaseAndWeights) {
  auto planner_copy = task->clone();
  std::string why;
  ASSERT_TRUE(task->setGoal({0.1, -0.2, 0.3}, Eigen::Quaterniond::Identity(), &why));
  task->setWeight("w_grasp", 3.5);
  ASSERT_TRUE(task->release(&why));
  planner_copy->copyParametersFrom(*task);
  auto* copy = dynamic_cast<adroit_mpc::RelocateTask*>(planner_copy.get());
  EXPECT_EQ(copy->phase(), adroit_mpc::RelocateTask::Phase::kRelease);
  EXPECT_EQ(copy->goalPosition(), Eigen::Vector3d(0.1, -0.2, 0.3));
  EXPECT_EQ(copy->weight("w_grasp"), 3.5);
  auto other = adroit_mpc::makeTask("catch", {});
  EXPECT_THROW(planner_copy->copyParametersFrom(*other), std::invalid_argument);
}

TEST(RelocateParams, GoalInTheParametersSkipsHold) {
  TaskParams p;
  p.vectors["goal_position"] = {0.1, -0.2, 0.3};
  adroit_mpc::RelocateTask task(p);
  EXPECT_EQ(task.phase(), adroit_mpc::RelocateTask::Phase::kGoal);
  p.vectors["goal_position"] = {0.1, 0.3, 0.2};
  EXPECT_THROW(adroit_mpc::RelocateTask{p}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------- type

TEST(TypeOnKeypad, DerivativesMatchFiniteDifferences) {
  auto model = planningScene("keypad");
  auto data = adroit::makeData(model.get());
  auto task = adroit_mpc::makeTask("type", {});
  task->bind(model.get(), kSynergies);
  std::string why;
  ASSERT_TRUE(task->setSequence("52", &why)) << why;
  setKeyframe(model.get(), data.get(), "rest");
  for (int i = 0; i < 24; ++i) data->qpos[i] += 0.05 * std::sin(i);  // hand off its rest pose
  // Some keys partly down (5: the current key, 2: the next, 9: another).
  for (const char* key : {"KEY_5", "KEY_2", "KEY_9"})
    data->qpos[model->jnt_qposadr[mj_name2id(model.get(), mjOBJ_JOINT, key)]] = -0.002;
  addVelocities(model.get(), data.get(), 0.2);
  const Eigen::VectorXd u = someControl(model.get());
  // t = 0.2: inside the S_up pulse, both current and next terms weigh.
  checkDerivatives(*task, model.get(), data.get(), u, 0.2, "type");
  checkDerivatives(*task, model.get(), data.get(), u, 0.6, "type late");
}

// ---------------------------------------------------------------------------------- factory

std::string errorOf(const std::string& name, const TaskParams& p) {
  try {
    adroit_mpc::makeTask(name, p);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(TaskFactory, MakesEveryTask) {
  for (const auto& name : adroit_mpc::taskNames()) {
    auto task = adroit_mpc::makeTask(name, {});
    EXPECT_EQ(task->name(), name);
    EXPECT_EQ(task->clone()->name(), name);
    for (const auto& w : task->weightNames()) {
      EXPECT_EQ(w.rfind("w_", 0), 0u) << w;
      EXPECT_EQ(task->weight(w), adroit_mpc::defaultTaskParams(name).numbers.at(w));
    }
  }
  const auto weights = adroit_mpc::makeTask("catch", {})->weightNames();
  for (const char* w : {"w_object_velocity", "w_goal_position", "w_goal_orientation", "w_grasp", "w_control",
                        "w_synergy"})
    EXPECT_NE(std::find(weights.begin(), weights.end(), w), weights.end()) << w;
}

TEST(TaskFactory, ErrorsNameTheProblem) {
  EXPECT_EQ(errorOf("juggle", {}), "unknown task 'juggle' (known: catch, relocate, type)");
  TaskParams p;
  p.numbers["w_juggle"] = 1;
  EXPECT_NE(errorOf("catch", p).find("unknown parameter 'w_juggle'"), std::string::npos) << errorOf("catch", p);
  p = {};
  p.numbers["goal_position"] = 1;
  EXPECT_NE(errorOf("catch", p).find("'goal_position' must be a list of numbers"), std::string::npos);
  p = {};
  p.numbers["w_grasp"] = -1;
  EXPECT_NE(errorOf("catch", p).find("'w_grasp'"), std::string::npos);
  p = {};
  p.vectors["goal_position"] = {0.0, -0.2};
  EXPECT_NE(errorOf("catch", p).find("'goal_position' needs 3 numbers"), std::string::npos);
  p = {};
  p.vectors["goal_quat"] = {0, 0, 0, 0};
  EXPECT_NE(errorOf("catch", p).find("'goal_quat'"), std::string::npos);
  p = {};
  p.strings["finger_assignment"] = "1:pinky";
  EXPECT_NE(errorOf("type", p).find("'1:pinky'"), std::string::npos);
  p = {};
  p.strings["sequence"] = "12a";
  EXPECT_NE(errorOf("type", p).find("'a'"), std::string::npos);
  EXPECT_EQ(errorOf("type", p).find('\n'), std::string::npos);

  auto task = adroit_mpc::makeTask("relocate", {});
  EXPECT_THROW(task->setWeight("w_nothing", 1), std::invalid_argument);
  EXPECT_THROW(task->setWeight("w_grasp", -0.1), std::invalid_argument);
  EXPECT_THROW(task->setWeight("w_grasp", NAN), std::invalid_argument);
  EXPECT_THROW(task->weight("w_nothing"), std::invalid_argument);
  task->setWeight("w_grasp", 2.5);
  EXPECT_EQ(task->weight("w_grasp"), 2.5);
  EXPECT_THROW(adroit_mpc::defaultTaskParams("juggle"), std::invalid_argument);
}

// Flat YAML (key: number | [numbers] | string) as the node loads it onto the parameter server.
TaskParams readFlatYaml(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw std::runtime_error("cannot read " + path);
  TaskParams p;
  std::string line;
  while (std::getline(file, line)) {
    bool quoted = false;
    for (size_t i = 0; i < line.size(); ++i) {  // strip comments outside quotes
      if (line[i] == '"') quoted = !quoted;
      if (line[i] == '#' && !quoted) {
        line.resize(i);
        break;
      }
    }
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    auto trim = [](std::string s) {
      s.erase(0, s.find_first_not_of(" \t"));
      s.erase(s.find_last_not_of(" \t") + 1);
      return s;
    };
    const std::string key = trim(line.substr(0, colon)), value = trim(line.substr(colon + 1));
    if (!value.empty() && value.front() == '[') {
      std::vector<double> v;
      std::stringstream items(value.substr(1, value.find(']') - 1));
      std::string item;
      while (std::getline(items, item, ','))
        if (!trim(item).empty()) v.push_back(std::stod(item));
      p.vectors[key] = v;
    } else if (!value.empty() && value.front() == '"') {
      p.strings[key] = value.substr(1, value.size() - 2);
    } else {
      char* end = nullptr;
      const double number = std::strtod(value.c_str(), &end);
      if (!value.empty() && *end == '\0')
        p.numbers[key] = number;
      else
        p.strings[key] = value;
    }
  }
  return p;
}

TEST(TaskFactory, YamlFilesHoldTheDefaults) {
  const std::string file = __FILE__;
  const std::string dir = file.substr(0, file.rfind("/test/")) + "/config/tasks/";
  for (const auto& name : adroit_mpc::taskNames()) {
    const TaskParams yaml = readFlatYaml(dir + name + ".yaml");
    const TaskParams defaults = adroit_mpc::defaultTaskParams(name);
    EXPECT_EQ(yaml.numbers, defaults.numbers) << name;
    EXPECT_EQ(yaml.vectors, defaults.vectors) << name;
    EXPECT_EQ(yaml.strings, defaults.strings) << name;
    EXPECT_NO_THROW(adroit_mpc::makeTask(name, yaml)) << name;
  }
}

}  // namespace
