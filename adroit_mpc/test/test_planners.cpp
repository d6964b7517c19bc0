// The planners in closed loop on small inline models (real MuJoCo): plan, apply the
// policy's action to a separate simulation for a control period, repeat. Plus the pieces of
// the sampling planners: the spline's shift, CEM's elite statistics, seeds, settings.
#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/cem_planner.h>
#include <adroit_mpc/ilqg_planner.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/sampling_planner.h>
#include <gtest/gtest.h>

#include "goal_task.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

using namespace adroit_mpc;

namespace {

using test::GoalTask;
using test::kPendulum;
using test::kPointMass;

struct ClosedLoopResult {
  double final_error = 0;
  bool controls_in_range = true;
  int diverged = 0;
  double action_steps = 0;  // sum of squared changes of the applied controls between simulation steps
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
      const std::vector<double> before(sim->ctrl, sim->ctrl + m->nu);
      policy.action(sim->time, sim->qpos, sim->qvel, sim->act, sim->ctrl);
      for (int i = 0; i < m->nu && sim->time > 0; ++i) result.action_steps += std::pow(sim->ctrl[i] - before[i], 2);
      for (int i = 0; i < m->nu; ++i)
        if (sim->ctrl[i] < m->actuator_ctrlrange[2 * i] || sim->ctrl[i] > m->actuator_ctrlrange[2 * i + 1])
          result.controls_in_range = false;
      mj_step(m, sim.get());
    }
  }
  result.final_error = task.error(m, sim.get());
  return result;
}

constexpr double kStepWeight = 3;

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

// The planners weigh the tension step cost (PlannerSettings::tension_step_weight): from the
// same state, the plan's control steps from knot to knot shrink with it, and the plan still
// heads for the goal.
TEST(Planners, StepCostShrinksThePlansControlSteps) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  PlannerState start;
  start.qpos = {0, 0};
  start.qvel = {0, 0};
  for (const std::string name : {"ilqg", "cem"}) {
    double steps[2] = {0, 0}, distance[2] = {0, 0};
    for (int with = 0; with < 2; ++with) {
      PlannerSettings s = smallSettings(0.5);
      s.tension_step_weight = with ? kStepWeight : 0.0;
      auto planner = makePlanner(name);
      planner->initialize(m.get(), task, s);
      planner->setState(start);
      for (int k = 0; k < 30; ++k) planner->optimize();
      const Trajectory& plan = planner->bestTrajectory();
      for (std::size_t t = 1; t < plan.ctrl.size(); ++t) steps[with] += (plan.ctrl[t] - plan.ctrl[t - 1]).squaredNorm();
      distance[with] = std::hypot(plan.states.back()[0] - 0.3, plan.states.back()[1] + 0.2);
    }
    std::printf("%s: the plan's squared control steps %.4f without the cost, %.4f with it; its end %.3f / %.3f m "
                "from the goal\n", name.c_str(), steps[0], steps[1], distance[0], distance[1]);
    EXPECT_LT(steps[1], 0.5 * steps[0]) << name;
    EXPECT_LT(distance[1], distance[0] + 0.02) << name;  // as far towards the goal within 2 cm
  }
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
  for (const char* kind : {"ilqg", "sampling", "cem"}) {
    GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
    auto planner = makePlanner(kind);
    planner->initialize(m.get(), task, smallSettings(0.5));
    ASSERT_FALSE(planner->optimize().diverged) << kind;
    PlanPolicy before, after;
    planner->policy(before);
    GoalTask poisoned = task;
    poisoned.poison = true;
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
  EXPECT_EQ(makePlanner("cem")->name(), "cem");
  try {
    makePlanner("mppi");
    FAIL() << "expected invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ilqg, sampling, cem"), std::string::npos) << e.what();
  }
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
  // The derivative reuse settings: one line naming the setting.
  for (const auto& [age, tolerance, name] :
       {std::tuple{-0.1, 0.01, "derivative_max_age"}, std::tuple{0.1, 0.0, "derivative_reuse_tolerance"},
        std::tuple{0.1, std::numeric_limits<double>::infinity(), "derivative_reuse_tolerance"}}) {
    s = smallSettings(0.5);
    s.derivative_max_age = age;
    s.derivative_reuse_tolerance = tolerance;
    try {
      planner.initialize(m.get(), task, s);
      ADD_FAILURE() << "expected invalid_argument for " << name;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
  for (const double weight : {-1.0, std::numeric_limits<double>::quiet_NaN()}) {
    s = smallSettings(0.5);
    s.tension_step_weight = weight;
    try {
      planner.initialize(m.get(), task, s);
      ADD_FAILURE() << "expected invalid_argument for tension_step_weight " << weight;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("tension_step_weight"), std::string::npos) << e.what();
    }
  }
  s = smallSettings(0.5);
  planner.initialize(m.get(), task, s);
  PlannerState wrong;
  wrong.qpos = {0.0};  // nq is 2
  wrong.qvel = {0.0, 0.0};
  EXPECT_THROW(planner.setState(wrong), std::invalid_argument);
}

// ---- sampling planners: spline, CEM --------------------------------------------------------

TEST(ControlSpline, ShiftResamplesTheHeldValuesAndSaysWhichPointsAreNew) {
  ControlSpline s;
  s.resize(4, 1, 8);  // spacing 0.1 s over a 0.4 s horizon of 8 knots
  for (int j = 0; j < 4; ++j) s.values[j][0] = j;
  EXPECT_EQ(s.atKnot(0)[0], 0);
  EXPECT_EQ(s.atKnot(3)[0], 1);  // knot 3 of 8 lies in the second quarter
  EXPECT_EQ(s.atKnot(7)[0], 3);
  EXPECT_EQ(s.shiftTo(0.0, 0.4), 4);  // no shift: nothing new
  // 0.15 s on: point j (at 0.15 + 0.1 j) held the old point j + 1; the last point lies past the
  // old end and holds the old last value.
  EXPECT_EQ(s.shiftTo(0.15, 0.4), 3);
  EXPECT_DOUBLE_EQ(s.t0, 0.15);
  EXPECT_EQ((std::vector<double>{s.values[0][0], s.values[1][0], s.values[2][0], s.values[3][0]}),
            (std::vector<double>{1, 2, 3, 3}));
  // Back in time (a reset simulation): the first value is held before the old start.
  EXPECT_EQ(s.shiftTo(0.0, 0.4), 4);
  EXPECT_EQ((std::vector<double>{s.values[0][0], s.values[1][0], s.values[2][0], s.values[3][0]}),
            (std::vector<double>{1, 1, 1, 2}));
  EXPECT_EQ(s.shiftTo(1e30, 0.4), 0);  // a huge jump: every point new, no overflow
  EXPECT_EQ(s.values[0][0], 2);
}

TEST(Cem, EliteStatisticsByHand) {
  // Two controls: range 2 and range 0 (a control fixed by its box). Three candidate splines of
  // two points; the elites are candidates 1 and 0.
  std::vector<ControlSpline> splines(3);
  const double values[3][2] = {{0.2, 1.0}, {0.6, 1.0}, {1.6, 0.0}};
  for (int i = 0; i < 3; ++i) {
    splines[i].resize(2, 2, 2);
    for (int j = 0; j < 2; ++j) splines[i].values[j] << values[i][j], 5.0;
  }
  const int elites[2] = {1, 0};
  const Eigen::Vector2d range(2.0, 0.0);
  ControlSpline mean, std;
  mean.resize(2, 2, 2);
  std.resize(2, 2, 2);
  eliteStatistics(splines, elites, 2, range, 0.01, 0.5, mean, std);
  EXPECT_NEAR(mean.values[0][0], 0.4, 1e-15);
  EXPECT_NEAR(mean.values[1][0], 1.0, 1e-15);
  EXPECT_EQ(mean.values[0][1], 5.0);
  // Point 0: deviations +-0.2, std 0.2 = 0.1 of the range; point 1: no spread -> std_min.
  EXPECT_NEAR(std.values[0][0], 0.1, 1e-15);
  EXPECT_EQ(std.values[1][0], 0.01);
  EXPECT_EQ(std.values[0][1], 0.01);  // zero range
  // The same elites with a cap below their spread: clamped to std_max.
  eliteStatistics(splines, elites, 2, range, 0.01, 0.05, mean, std);
  EXPECT_EQ(std.values[0][0], 0.05);
  // All three: means 0.8 and 2/3; point 0 deviates by -0.6, -0.2, 0.8: std sqrt(1.04 / 3) / 2.
  const int all[3] = {0, 1, 2};
  eliteStatistics(splines, all, 3, range, 0.01, 0.5, mean, std);
  EXPECT_NEAR(mean.values[0][0], 0.8, 1e-15);
  EXPECT_NEAR(mean.values[1][0], 2.0 / 3.0, 1e-15);
  EXPECT_NEAR(std.values[0][0], std::sqrt(1.04 / 3) / 2, 1e-15);
}

TEST(Cem, DrivesPointMassToGoal) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  CemPlanner planner;
  auto r = closedLoop(planner, m.get(), task, smallSettings(0.5), 3.0, 0.02);
  EXPECT_LT(r.final_error, 0.03);
  EXPECT_TRUE(r.controls_in_range);
  EXPECT_EQ(r.diverged, 0);
}

TEST(SamplingPlanners, CostNeverRisesForAFixedState) {
  auto m = adroit::loadModelString(kPendulum).model;
  for (const double step_weight : {0.0, kStepWeight})
    for (const char* kind : {"sampling", "cem"}) {
      GoalTask task({0.6}, 10.0, 0.1, 0.001);
      auto planner = makePlanner(kind);
      PlannerSettings s = smallSettings(0.5);
      s.samples = 8;
      s.cem_elites = 3;
      s.tension_step_weight = step_weight;
      planner->initialize(m.get(), task, s);
      double previous = std::numeric_limits<double>::infinity(), first = 0;
      for (int i = 0; i < 15; ++i) {
        OptimizeReport r = planner->optimize();  // the state stays at t = 0
        if (i == 0) first = r.cost_before;
        EXPECT_LE(r.cost_after, r.cost_before) << kind << " iteration " << i;
        EXPECT_LE(r.cost_after, previous) << kind << " iteration " << i;
        // Candidate 0 is the previous plan. With the step cost its first knot is now priced
        // against itself (the plan in effect at t = 0), so it costs at most what it did.
        if (i > 0 && step_weight == 0) EXPECT_EQ(r.cost_before, previous) << kind << ": the previous plan is candidate 0";
        if (i > 0) EXPECT_LE(r.cost_before, previous) << kind << ", step weight " << step_weight;
        EXPECT_EQ(planner->bestTrajectory().cost, r.cost_after) << kind;
        previous = r.cost_after;
      }
      EXPECT_LT(previous, 0.5 * first) << kind << ": the iterations did lower the cost";
    }
}

TEST(Cem, OneEliteClampsTheStdAtItsMinimumAndThePlanIsTheMean) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  PlannerSettings s = smallSettings(0.5);
  s.cem_elites = 1;  // no spread among one elite
  s.cem_std_min = 0.02;
  CemPlanner planner;
  planner.initialize(m.get(), task, s);
  for (const auto& v : planner.standardDeviation().values) EXPECT_TRUE((v.array() == s.cem_std_initial).all());
  planner.optimize();
  for (const auto& v : planner.standardDeviation().values) EXPECT_TRUE((v.array() == 0.02).all()) << v.transpose();
  const Trajectory& plan = planner.bestTrajectory();
  for (std::size_t t = 0; t < plan.controls.size(); ++t)
    EXPECT_EQ(plan.controls[t], planner.mean().atKnot(static_cast<int>(t))) << "knot " << t;
}

TEST(Cem, StdFollowsTheElitesWithinItsBounds) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  PlannerSettings s = smallSettings(0.5);
  s.cem_elites = 12;  // the best quarter of 48
  s.cem_std_initial = 0.3;
  s.cem_std_min = 0.001;
  CemPlanner planner;
  planner.initialize(m.get(), task, s);
  // From the same state the elites concentrate: the average std (seeds 1-6: 0.15-0.19 after
  // one iteration, 0.007-0.036 after six) falls well below the initial 0.3.
  double average = 0;
  for (int i = 0; i < 6; ++i) {
    planner.optimize();
    double sum = 0;
    int n = 0;
    for (const auto& v : planner.standardDeviation().values) {
      EXPECT_GE(v.minCoeff(), 0.001);
      EXPECT_LE(v.maxCoeff(), 0.3);
      sum += v.sum();
      n += static_cast<int>(v.size());
    }
    average = sum / n;
    if (i == 0) {
      EXPECT_LT(average, 0.7 * 0.3);
    }
  }
  EXPECT_LT(average, 0.25 * 0.3);
  // Bounds that meet: the std cannot move.
  s.cem_std_min = s.cem_std_initial;
  planner.initialize(m.get(), task, s);
  for (int i = 0; i < 3; ++i) planner.optimize();
  for (const auto& v : planner.standardDeviation().values) EXPECT_TRUE((v.array() == 0.3).all());
}

namespace {

// The plan of `seed` after a short closed loop, with `threads` workers.
Trajectory cemPlan(std::uint64_t seed, int threads) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 10.0, 0.1, 0.01);
  PlannerSettings s = smallSettings(0.5);
  s.seed = seed;
  s.threads = threads;
  CemPlanner planner;
  closedLoop(planner, m.get(), task, s, 0.2, 0.02);
  return planner.bestTrajectory();
}

}  // namespace

TEST(Cem, SameSeedSamePlanWhateverTheWorkers) {
  const Trajectory a = cemPlan(7, 1), b = cemPlan(7, 2), c = cemPlan(8, 2);
  ASSERT_EQ(a.controls.size(), b.controls.size());
  EXPECT_EQ(a.cost, b.cost);
  bool seed_matters = false;
  for (std::size_t t = 0; t < a.controls.size(); ++t) {
    EXPECT_EQ(a.controls[t], b.controls[t]) << "knot " << t;
    EXPECT_EQ(a.states[t], b.states[t]) << "knot " << t;
    seed_matters = seed_matters || a.controls[t] != c.controls[t];
  }
  EXPECT_TRUE(seed_matters) << "another seed gave the same plan";
}

TEST(Cem, BadSettingsAreRefusedNamingTheSetting) {
  auto m = adroit::loadModelString(kPointMass).model;
  GoalTask task({0.3, -0.2}, 1, 1, 1);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  struct Case {
    const char* setting;
    void (*bend)(PlannerSettings&, double, double);
  };
  const Case cases[] = {
      {"cem_elites", [](PlannerSettings& s, double, double) { s.cem_elites = 0; }},
      {"cem_elites", [](PlannerSettings& s, double, double) { s.cem_elites = s.samples + 1; }},
      {"cem_std_initial", [](PlannerSettings& s, double, double) { s.cem_std_initial = 0; }},
      {"cem_std_initial", [](PlannerSettings& s, double n, double) { s.cem_std_initial = n; }},
      {"cem_std_initial", [](PlannerSettings& s, double, double i) { s.cem_std_initial = i; }},
      {"cem_std_min", [](PlannerSettings& s, double, double) { s.cem_std_min = -0.01; }},
      {"cem_std_min", [](PlannerSettings& s, double n, double) { s.cem_std_min = n; }},
      {"cem_std_min", [](PlannerSettings& s, double, double) { s.cem_std_min = 2 * s.cem_std_initial; }},
  };
  for (const Case& c : cases) {
    PlannerSettings s = smallSettings(0.5);
    c.bend(s, nan, inf);
    CemPlanner planner;
    try {
      planner.initialize(m.get(), task, s);
      ADD_FAILURE() << "accepted a bad " << c.setting;
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(c.setting), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
  }
  PlannerSettings s = smallSettings(0.5);
  s.cem_elites = s.samples;
  s.cem_std_min = s.cem_std_initial;
  CemPlanner planner;
  EXPECT_NO_THROW(planner.initialize(m.get(), task, s)) << "the bounds themselves are allowed";
}
