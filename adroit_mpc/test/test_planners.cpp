// Both planners in closed loop on small inline models (real MuJoCo): plan, apply the
// policy's action to a separate simulation for a control period, repeat.
#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/ilqg_planner.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/sampling_planner.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace adroit_mpc;

namespace {

// Quadratic cost on hinge/slide coordinates: w_p |q - goal|^2 + w_v |v|^2 + w_u |u|^2,
// terminal x10. Exact Gauss-Newton derivatives (the model has only scalar joints, dq = dqpos).
class GoalTask : public Task {
 public:
  GoalTask(std::vector<double> goal, double w_p, double w_v, double w_u)
      : goal_(std::move(goal)), w_p_(w_p), w_v_(w_v), w_u_(w_u) {}
  std::string name() const override { return "goal"; }
  std::unique_ptr<Task> clone() const override { return std::make_unique<GoalTask>(*this); }
  void copyParametersFrom(const Task& other) override {
    const auto* o = dynamic_cast<const GoalTask*>(&other);
    if (!o) throw std::invalid_argument("not a GoalTask");
    goal_ = o->goal_;
    poison_ = o->poison_;
  }
  void bind(const mjModel* m, int synergy_dims) override {
    nv_ = m->nv;
    nu_ = m->nu + synergy_dims;
  }
  std::unique_ptr<TaskScratch> makeScratch(const mjModel*) const override { return std::make_unique<TaskScratch>(); }
  double runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double, TaskScratch&) const override {
    return stateCost(m, d, 1.0, nullptr) + w_u_ * u.squaredNorm();
  }
  double terminalCost(const mjModel* m, const mjData* d, double, TaskScratch&) const override {
    return stateCost(m, d, 10.0, nullptr);
  }
  double runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double, TaskScratch&,
                                CostDerivatives& out) const override {
    out.setZero();
    out.lu = 2 * w_u_ * u;
    out.luu.diagonal().setConstant(2 * w_u_);
    return stateCost(m, d, 1.0, &out) + w_u_ * u.squaredNorm();
  }
  double terminalCostDerivatives(const mjModel* m, const mjData* d, double, TaskScratch&,
                                 CostDerivatives& out) const override {
    out.setZero();
    return stateCost(m, d, 10.0, &out);
  }
  std::vector<std::string> weightNames() const override { return {}; }
  double weight(const std::string&) const override { return 0; }
  void setWeight(const std::string&, double) override {}
  double error(const mjModel*, const mjData* d) const override {
    double e = 0;
    for (std::size_t i = 0; i < goal_.size(); ++i) e += (d->qpos[i] - goal_[i]) * (d->qpos[i] - goal_[i]);
    return std::sqrt(e);
  }
  bool poison_ = false;  // every cost NaN (a diverging task)

 private:
  double stateCost(const mjModel*, const mjData* d, double scale, CostDerivatives* out) const {
    if (poison_) return std::numeric_limits<double>::quiet_NaN();
    double c = 0;
    for (std::size_t i = 0; i < goal_.size(); ++i) {
      const double e = d->qpos[i] - goal_[i];
      c += scale * w_p_ * e * e;
      if (out) {
        out->lx[i] += 2 * scale * w_p_ * e;
        out->lxx(i, i) += 2 * scale * w_p_;
      }
    }
    for (int i = 0; i < nv_; ++i) {
      c += scale * w_v_ * d->qvel[i] * d->qvel[i];
      if (out) {
        out->lx[nv_ + i] += 2 * scale * w_v_ * d->qvel[i];
        out->lxx(nv_ + i, nv_ + i) += 2 * scale * w_v_;
      }
    }
    return c;
  }
  std::vector<double> goal_;
  double w_p_, w_v_, w_u_;
  int nv_ = 0, nu_ = 0;
};

const char* kPointMass = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01" gravity="0 0 0"/>
  <worldbody>
    <body name="mass">
      <joint name="x" type="slide" axis="1 0 0" damping="0.2"/>
      <joint name="y" type="slide" axis="0 1 0" damping="0.2"/>
      <geom type="sphere" size="0.05" mass="1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="x" ctrlrange="-1 1"/>
    <motor joint="y" ctrlrange="-1 1"/>
  </actuator>
</mujoco>)";

const char* kPendulum = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01"/>
  <worldbody>
    <body name="pole">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.05"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02" mass="0" contype="0" conaffinity="0"/>
      <geom type="sphere" pos="0 0 -0.5" size="0.05" mass="1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="hinge" ctrlrange="-4 4"/>
  </actuator>
</mujoco>)";

struct ClosedLoopResult {
  double final_error = 0;
  bool controls_in_range = true;
  int diverged = 0;
};

// Plans every `period` seconds and applies the policy's action to a separate simulation.
ClosedLoopResult closedLoop(Planner& planner, const mjModel* m, GoalTask& task, const PlannerSettings& settings,
                            double seconds, double period) {
  planner.initialize(m, task, settings);
  adroit::DataPtr sim = adroit::makeData(m);
  PlanPolicy policy;
  PlannerState state;
  ClosedLoopResult result;
  const int steps_per_period = static_cast<int>(std::lround(period / m->opt.timestep));
  while (sim->time < seconds) {
    state.time = sim->time;
    state.qpos.assign(sim->qpos, sim->qpos + m->nq);
    state.qvel.assign(sim->qvel, sim->qvel + m->nv);
    state.act.assign(sim->act, sim->act + m->na);
    planner.setState(state);
    if (planner.optimize().diverged) ++result.diverged;
    planner.policy(policy);
    for (int k = 0; k < steps_per_period; ++k) {
      policy.action(sim->time, sim->qpos, sim->qvel, sim->act, sim->ctrl);
      for (int i = 0; i < m->nu; ++i)
        if (sim->ctrl[i] < m->actuator_ctrlrange[2 * i] || sim->ctrl[i] > m->actuator_ctrlrange[2 * i + 1])
          result.controls_in_range = false;
      mj_step(m, sim.get());
    }
  }
  result.final_error = task.error(m, sim.get());
  return result;
}

PlannerSettings smallSettings(double horizon) {
  PlannerSettings s;
  s.horizon = horizon;
  s.dt = 0.01;
  s.threads = 2;
  s.synergies = false;
  s.samples = 48;
  s.noise_scale = 0.2;
  s.spline_points = 4;
  return s;
}

}  // namespace

TEST(Planners, IlqgDrivesPointMassToGoal) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  IlqgPlanner planner;
  auto r = closedLoop(planner, m.get(), task, smallSettings(0.5), 3.0, 0.02);
  EXPECT_LT(r.final_error, 0.02);
  EXPECT_TRUE(r.controls_in_range);
  EXPECT_EQ(r.diverged, 0);
}

TEST(Planners, SamplingDrivesPointMassToGoal) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  SamplingPlanner planner;
  auto r = closedLoop(planner, m.get(), task, smallSettings(0.5), 3.0, 0.02);
  EXPECT_LT(r.final_error, 0.03);
  EXPECT_TRUE(r.controls_in_range);
}

TEST(Planners, IlqgHoldsPendulumAtGoalAngle) {
  auto m = adroit::loadModelString(kPendulum).model;
  GoalTask task({0.6}, 10.0, 0.1, 0.001);
  IlqgPlanner planner;
  auto r = closedLoop(planner, m.get(), task, smallSettings(0.5), 3.0, 0.02);
  EXPECT_LT(r.final_error, 0.03);  // holding 0.6 rad takes 2.8 N m of the 4 available
  EXPECT_TRUE(r.controls_in_range);
}

TEST(Planners, SamplingHoldsPendulumAtGoalAngle) {
  auto m = adroit::loadModelString(kPendulum).model;
  GoalTask task({0.6}, 10.0, 0.1, 0.001);
  SamplingPlanner planner;
  auto r = closedLoop(planner, m.get(), task, smallSettings(0.5), 3.0, 0.02);
  EXPECT_LT(r.final_error, 0.05);
  EXPECT_TRUE(r.controls_in_range);
}

TEST(Planners, IlqgIterationLowersTheCostFromTheSameState) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  IlqgPlanner planner;
  planner.initialize(m.get(), task, smallSettings(0.5));
  double previous = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 5; ++i) {
    OptimizeReport r = planner.optimize();  // the state stays at t = 0: pure re-optimisation
    EXPECT_LE(r.cost_after, r.cost_before + 1e-12);
    EXPECT_LE(r.cost_after, previous + 1e-9);
    previous = r.cost_after;
    EXPECT_GT(r.total, 0);
    EXPECT_GE(r.total, r.derivatives + r.backward);
  }
  EXPECT_LT(previous, planner.bestTrajectory().cost + 1e-12);
}

TEST(Planners, DivergingTaskIsReportedAndThePolicyKept) {
  auto m = adroit::loadModelString(kPointMass).model;
  for (const char* kind : {"ilqg", "sampling"}) {
    GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
    auto planner = makePlanner(kind);
    planner->initialize(m.get(), task, smallSettings(0.5));
    ASSERT_FALSE(planner->optimize().diverged) << kind;
    PlanPolicy before, after;
    planner->policy(before);
    GoalTask poisoned = task;
    poisoned.poison_ = true;
    planner->setTask(poisoned);
    EXPECT_TRUE(planner->optimize().diverged) << kind;
    planner->policy(after);
    ASSERT_EQ(before.policy.knots(), after.policy.knots());
    for (int k = 0; k < before.policy.knots(); ++k) {
      EXPECT_EQ(before.policy.u[k], after.policy.u[k]) << kind << " knot " << k;
      EXPECT_EQ(before.policy.x[k], after.policy.x[k]) << kind << " knot " << k;
    }
    EXPECT_TRUE(std::isfinite(after.cost));
    // Healthy task again: the planner recovers from the safe warm start.
    planner->setTask(task);
    EXPECT_FALSE(planner->optimize().diverged) << kind;
  }
}

TEST(Planners, BadSettingsAndNamesAreRejected) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 1, 1, 1);
  EXPECT_THROW(makePlanner("cem"), std::invalid_argument);
  PlannerSettings s = smallSettings(0.5);
  s.dt = 0.005;  // model timestep is 0.01
  IlqgPlanner planner;
  try {
    planner.initialize(m.get(), task, s);
    FAIL() << "expected invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("timestep"), std::string::npos) << e.what();
  }
  s = smallSettings(0.5);
  s.synergies = true;  // a point mass has no fingers
  EXPECT_THROW(planner.initialize(m.get(), task, s), std::invalid_argument);
  s = smallSettings(0.5);
  planner.initialize(m.get(), task, s);
  PlannerState wrong;
  wrong.qpos = {0.0};  // nq is 2
  wrong.qvel = {0.0, 0.0};
  EXPECT_THROW(planner.setState(wrong), std::invalid_argument);
}
