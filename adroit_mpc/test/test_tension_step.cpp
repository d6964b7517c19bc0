// The tension step cost of ControlSpace (PlannerSettings::tension_step_weight) on the hand's
// planning model with its synergies: the cost from its definition, the first knot against the
// previous plan's controls, and the derivatives iLQG takes against finite differences.
#include <adroit_core/mujoco_model.h>
#include <adroit_description/scenes.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/planning_model.h>
#include <gtest/gtest.h>

#include <random>

using namespace adroit_mpc;

namespace {

constexpr double kWeight = 2.0;
constexpr int kKnots = 4;

adroit::ModelPtr handModel() {
  return adroit::loadModelFile(adroit::description::sceneFile(descriptionShareDir(), "hand", true)).model;
}

// Knot controls inside the box, synergies small enough that no actuator clamps.
KnotTrajectory randomPlan(const mjModel* m, const ControlSpace& space, std::mt19937& rng) {
  std::uniform_real_distribution<double> fraction(0.3, 0.7), synergy(-0.1, 0.1);
  KnotTrajectory plan;
  plan.resize(m, kKnots, space.size());
  for (int t = 0; t <= kKnots; ++t) plan.times[t] = 1.0 + 0.01 * t;
  for (int t = 0; t < kKnots; ++t) {
    for (int i = 0; i < space.actuators(); ++i)
      plan.controls[t][i] = space.lower()[i] + fraction(rng) * (space.upper()[i] - space.lower()[i]);
    for (int k = space.actuators(); k < space.size(); ++k) plan.controls[t][k] = synergy(rng);
    space.toCtrl(plan.controls[t], plan.ctrl[t].data());
  }
  return plan;
}

double totalStepCost(const ControlSpace& space, const KnotTrajectory& plan) {
  double sum = 0;
  for (int t = 0; t < kKnots; ++t) sum += space.stepCost(plan, t);
  return sum;
}

}  // namespace

TEST(TensionStep, CostFromItsDefinitionWithTheFirstKnotAgainstThePreviousPlan) {
  auto m = handModel();
  ControlSpace space;
  space.initialize(m.get(), true, kWeight);
  std::mt19937 rng(3);
  const KnotTrajectory plan = randomPlan(m.get(), space, rng);
  const KnotTrajectory previous = randomPlan(m.get(), space, rng);
  const auto expected = [&](const Eigen::VectorXd& from, const Eigen::VectorXd& to) {
    double sum = 0;
    for (int i = 0; i < m->nu; ++i) {
      const double range = m->actuator_ctrlrange[2 * i + 1] - m->actuator_ctrlrange[2 * i];
      sum += std::pow((to[i] - from[i]) / range, 2);
    }
    return 0.5 * kWeight * sum;
  };
  space.forgetApplied();
  EXPECT_EQ(space.stepCost(plan, 0), 0.0);  // nothing runs: the first knot is free
  EXPECT_NEAR(space.stepCost(plan, 2), expected(plan.ctrl[1], plan.ctrl[2]), 1e-12);
  // Halfway between the previous plan's knots 1 and 2: their mean is in effect.
  space.holdApplied(previous, 0.5 * (previous.times[1] + previous.times[2]));
  const Eigen::VectorXd mean = 0.5 * (previous.ctrl[1] + previous.ctrl[2]);
  EXPECT_NEAR(space.stepCost(plan, 0), expected(mean, plan.ctrl[0]), 1e-12);
  // Past its last knot the last one holds.
  space.holdApplied(previous, previous.times.back() + 1.0);
  EXPECT_NEAR(space.stepCost(plan, 0), expected(previous.ctrl[kKnots - 1], plan.ctrl[0]), 1e-12);
  ControlSpace none;
  none.initialize(m.get(), true, 0.0);
  EXPECT_EQ(totalStepCost(none, plan), 0.0);
  EXPECT_THROW(none.initialize(m.get(), true, -1.0), std::invalid_argument);
}

TEST(TensionStep, DerivativesMatchFiniteDifferencesThroughTheSynergies) {
  auto m = handModel();
  ControlSpace space;
  space.initialize(m.get(), true, kWeight);
  ASSERT_TRUE(space.hasSynergies());
  std::mt19937 rng(5);
  KnotTrajectory plan = randomPlan(m.get(), space, rng);
  const KnotTrajectory previous = randomPlan(m.get(), space, rng);
  const int n = space.size();
  for (const bool applied : {false, true}) {
    if (applied) space.holdApplied(previous, plan.times[0]);
    else space.forgetApplied();
    for (int t = 0; t < kKnots; ++t) {
      Eigen::VectorXd lu = Eigen::VectorXd::Zero(n);
      Eigen::MatrixXd luu = Eigen::MatrixXd::Zero(n, n);
      space.addStepDerivatives(plan, t, lu, luu);
      // Central differences of the plan's whole step cost in knot t's planner controls (the
      // cost is quadratic in them while no actuator clamps: the differences are exact).
      const double h = 1e-4;
      Eigen::VectorXd gradient(n);
      Eigen::MatrixXd hessian(n, n);
      const auto costAt = [&](const Eigen::VectorXd& u) {
        KnotTrajectory moved = plan;
        moved.controls[t] = u;
        space.toCtrl(u, moved.ctrl[t].data());
        return totalStepCost(space, moved);
      };
      const Eigen::VectorXd u0 = plan.controls[t];
      for (int i = 0; i < n; ++i) {
        Eigen::VectorXd e = Eigen::VectorXd::Zero(n);
        e[i] = h;
        gradient[i] = (costAt(u0 + e) - costAt(u0 - e)) / (2 * h);
        for (int j = 0; j < n; ++j) {
          Eigen::VectorXd f = Eigen::VectorXd::Zero(n);
          f[j] = h;
          hessian(i, j) = (costAt(u0 + e + f) - costAt(u0 + e - f) - costAt(u0 - e + f) + costAt(u0 - e - f)) / (4 * h * h);
        }
      }
      EXPECT_LT((lu - gradient).lpNorm<Eigen::Infinity>(), 1e-6 * (1 + gradient.lpNorm<Eigen::Infinity>()))
          << "knot " << t << (applied ? " (applied)" : "");
      EXPECT_LT((luu - hessian).lpNorm<Eigen::Infinity>(), 1e-4 * (1 + hessian.lpNorm<Eigen::Infinity>()))
          << "knot " << t << (applied ? " (applied)" : "");
      EXPECT_GT(lu.norm(), 0) << "knot " << t;
    }
  }
}
