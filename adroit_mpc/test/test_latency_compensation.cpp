// Latency compensation: the prediction under the running policy against the closed form of
// MuJoCo's semi-implicit Euler, feedback scaling passed through, whole knots only, and the
// state left alone when there is nothing to predict; the latency estimate's median window.
#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/latency_compensation.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using adroit_mpc::LatencyEstimate;
using adroit_mpc::PlannerState;
using adroit_mpc::PlanPolicy;
using adroit_mpc::StatePredictor;

namespace {

// A 2 kg cart on a frictionless rail with one force actuator, 10 ms steps, no gravity.
const char* kCart = R"(
<mujoco><option timestep="0.01" gravity="0 0 0" integrator="Euler"/>
  <worldbody>
    <body name="cart"><joint name="x" type="slide" axis="1 0 0" damping="0"/><geom size="0.05" mass="2"/></body>
  </worldbody>
  <actuator><motor joint="x" ctrllimited="false"/></actuator>
</mujoco>)";

constexpr double kMass = 2.0, kDt = 0.01;

// A policy from t0 over 20 knots: u = force + gain (x - 0) on the cart's position.
PlanPolicy cartPolicy(const mjModel* m, double t0, double force, double gain) {
  PlanPolicy p;
  p.policy = adroit::TvlgPolicy(m->nq + m->nv + m->na, 2 * m->nv + m->na, m->nu, 20);
  p.policy.t0 = t0;
  p.policy.dt = kDt;
  for (int k = 0; k < 20; ++k) {
    p.policy.x[k].setZero();
    p.policy.u[k].setConstant(force);
    p.policy.K[k].setZero();
    p.policy.K[k](0, 0) = gain;
  }
  p.bind(m);
  return p;
}

PlannerState cartState(double time, double x, double v) {
  PlannerState s;
  s.time = time;
  s.qpos = {x};
  s.qvel = {v};
  return s;
}

}  // namespace

TEST(StatePredictor, ConstantForceFollowsSemiImplicitEuler) {
  auto m = adroit::loadModelString(kCart).model;
  StatePredictor predictor;
  predictor.initialize(m.get());
  const double force = 3.0;
  const PlanPolicy policy = cartPolicy(m.get(), 1.0, force, 0.0);
  PlannerState s = cartState(1.0, 0.2, 0.5);
  // 0.046 s rounds to five knots.
  EXPECT_NEAR(predictor.predict(policy, 1.0, 0.046, s), 5 * kDt, 1e-12);
  EXPECT_NEAR(s.time, 1.0 + 5 * kDt, 1e-12);
  // v_k = v_0 + k a dt; x_n = x_0 + sum_{k=1..n} v_k dt = x_0 + n v_0 dt + a dt^2 n (n + 1) / 2.
  const double a = force / kMass;
  const int n = 5;
  EXPECT_NEAR(s.qvel[0], 0.5 + n * a * kDt, 1e-12);
  EXPECT_NEAR(s.qpos[0], 0.2 + n * 0.5 * kDt + a * kDt * kDt * n * (n + 1) / 2.0, 1e-12);
}

TEST(StatePredictor, StopsAtThePolicysLastKnot) {
  auto m = adroit::loadModelString(kCart).model;
  StatePredictor predictor;
  predictor.initialize(m.get());
  // Knots at 1.00 ... 1.19: from 1.05, half a second ahead is cut to the 14 knots up to 1.19.
  PlannerState s = cartState(1.05, 0.0, 0.0);
  EXPECT_NEAR(predictor.predict(cartPolicy(m.get(), 1.0, 1.0, 0.0), 1.0, 0.5, s), 14 * kDt, 1e-12);
  EXPECT_NEAR(s.time, 1.19, 1e-12);
  // Past its end there is nothing to predict with.
  PlannerState late = cartState(1.3, 0.0, 0.0);
  EXPECT_EQ(predictor.predict(cartPolicy(m.get(), 1.0, 1.0, 0.0), 1.0, 0.05, late), 0.0);
  EXPECT_EQ(late.time, 1.3);
}

TEST(StatePredictor, FeedbackActsScaledAsOnTheRobot) {
  auto m = adroit::loadModelString(kCart).model;
  StatePredictor predictor;
  predictor.initialize(m.get());
  // u = -40 x: the cart at x = 0.1 is pushed back, unless the feedback is scaled to zero.
  const PlanPolicy policy = cartPolicy(m.get(), 0.0, 0.0, -40.0);
  PlannerState open = cartState(0.0, 0.1, 0.0), closed = cartState(0.0, 0.1, 0.0);
  predictor.predict(policy, 0.0, 0.03, open);
  predictor.predict(policy, 1.0, 0.03, closed);
  EXPECT_DOUBLE_EQ(open.qpos[0], 0.1);
  EXPECT_DOUBLE_EQ(open.qvel[0], 0.0);
  // First step by hand: v1 = -40 * 0.1 / 2 * dt = -0.02, x1 = 0.1 - 0.0002.
  EXPECT_LT(closed.qvel[0], -0.02 + 1e-12);
  EXPECT_LT(closed.qpos[0], 0.1 - 0.0002 + 1e-12);
}

TEST(StatePredictor, LeavesTheStateAloneWhenThereIsNothingToPredict) {
  auto m = adroit::loadModelString(kCart).model;
  StatePredictor predictor;
  predictor.initialize(m.get());
  PlannerState s = cartState(2.0, 0.3, -0.1);
  // Less than half a knot.
  EXPECT_EQ(predictor.predict(cartPolicy(m.get(), 2.0, 1.0, 0.0), 1.0, 0.0049, s), 0.0);
  // No plan yet.
  EXPECT_EQ(predictor.predict(PlanPolicy{}, 1.0, 0.05, s), 0.0);
  // A policy that drives the prediction out of the finite numbers.
  EXPECT_EQ(predictor.predict(cartPolicy(m.get(), 2.0, std::numeric_limits<double>::quiet_NaN(), 0.0), 1.0, 0.05, s),
            0.0);
  EXPECT_EQ(s.time, 2.0);
  EXPECT_EQ(s.qpos[0], 0.3);
  EXPECT_EQ(s.qvel[0], -0.1);
}

TEST(LatencyEstimate, MedianOfTheRecentWindow) {
  LatencyEstimate e;
  EXPECT_EQ(e.expected(), 0.0);
  e.record(0.04);
  EXPECT_DOUBLE_EQ(e.expected(), 0.04);
  // One slow solve among quick ones does not move the median.
  for (double v : {0.03, 0.05, 0.3}) e.record(v);
  e.record(0.04);
  EXPECT_DOUBLE_EQ(e.expected(), 0.04);
  // Bad values are ignored.
  e.record(std::numeric_limits<double>::quiet_NaN());
  e.record(-1.0);
  EXPECT_DOUBLE_EQ(e.expected(), 0.04);
  // A machine that got slower: after a full window only the new times count.
  for (int i = 0; i < 9; ++i) e.record(0.08);
  EXPECT_DOUBLE_EQ(e.expected(), 0.08);
}
