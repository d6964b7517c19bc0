// PlanPolicy::action: interpolation between knots, tangent-space feedback on a free body's
// quaternion, clamping to ctrlrange, and errors before a plan exists.
#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/planner.h>
#include <gtest/gtest.h>

#include <cmath>

using adroit_mpc::PlanPolicy;

namespace {

// A free body (nq 7, nv 6) and a slider carrying three motors (nu 3).
const char* kFreeBody = R"(
<mujoco><compiler autolimits="true"/>
  <worldbody>
    <body name="object"><freejoint name="object_root"/><geom size="0.05" mass="1"/></body>
    <body name="cart" pos="1 0 0"><joint name="s" type="slide" axis="1 0 0"/><geom size="0.05" mass="1"/></body>
  </worldbody>
  <actuator>
    <motor joint="s" ctrlrange="-10 10"/>
    <motor joint="s" ctrlrange="-10 10"/>
    <motor joint="s" ctrlrange="-1 1"/>
  </actuator>
</mujoco>)";

void fillPolicy(const mjModel* m, PlanPolicy& p, int knots) {
  p.policy = adroit::TvlgPolicy(m->nq + m->nv + m->na, 2 * m->nv + m->na, m->nu, knots);
  p.policy.t0 = 1.0;
  p.policy.dt = 0.1;
  for (int k = 0; k < knots; ++k) {
    p.policy.x[k].setZero();
    for (int i = 0; i < m->nq; ++i) p.policy.x[k][i] = m->qpos0[i];
  }
  p.bind(m);
}

}  // namespace

TEST(PlanPolicy, MidpointBetweenKnotsIsTheAverage) {
  auto m = adroit::loadModelString(kFreeBody).model;
  PlanPolicy p;
  fillPolicy(m.get(), p, 3);
  p.policy.u[0] << 0.0, 2.0, -0.5;
  p.policy.u[1] << 4.0, -2.0, 0.5;
  p.policy.u[2] << 8.0, 0.0, 0.0;
  // The knots' states differ in the cart position; the measured state sits on the
  // interpolated nominal so the (non-zero) feedback contributes nothing.
  p.policy.x[0][7] = 0.0;
  p.policy.x[1][7] = 0.2;
  p.policy.x[2][7] = 0.2;
  for (auto& K : p.policy.K) K.setConstant(3.0);
  std::vector<double> qpos(m->qpos0, m->qpos0 + m->nq), qvel(m->nv, 0.0);
  qpos[7] = 0.1;  // the midpoint of knots 0 and 1
  double ctrl[3];
  p.action(1.05, qpos.data(), qvel.data(), nullptr, ctrl);
  EXPECT_NEAR(ctrl[0], 2.0, 1e-12);
  EXPECT_NEAR(ctrl[1], 0.0, 1e-12);
  EXPECT_NEAR(ctrl[2], 0.0, 1e-12);
  // A quarter of the way from knot 1 to knot 2.
  qpos[7] = 0.2;
  p.action(1.125, qpos.data(), qvel.data(), nullptr, ctrl);
  EXPECT_NEAR(ctrl[0], 5.0, 1e-12);
  EXPECT_NEAR(ctrl[1], -1.5, 1e-12);
  EXPECT_NEAR(ctrl[2], 0.375, 1e-12);
}

TEST(PlanPolicy, FeedbackSeesTheFreeBodysRotationInTheTangentSpace) {
  auto m = adroit::loadModelString(kFreeBody).model;
  PlanPolicy p;
  fillPolicy(m.get(), p, 2);
  // u_i = 2 * (rotation vector component i) of the measured orientation relative to the nominal.
  for (auto& K : p.policy.K) {
    K.setZero();
    for (int i = 0; i < 3; ++i) K(i, 3 + i) = 2.0;
  }
  const double angle = 0.5;
  const double axis[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3};
  std::vector<double> qpos(m->qpos0, m->qpos0 + m->nq), qvel(m->nv, 0.0);
  mju_axisAngle2Quat(qpos.data() + 3, axis, angle);
  qpos[0] = 0.7;  // a translation the rotational gains must ignore
  double ctrl[3];
  p.action(1.0, qpos.data(), qvel.data(), nullptr, ctrl);
  EXPECT_NEAR(ctrl[0], 2 * angle * axis[0], 1e-9);
  EXPECT_NEAR(ctrl[1], 2 * angle * axis[1], 1e-9);
  EXPECT_NEAR(ctrl[2], 2 * angle * axis[2], 1e-9);  // 0.667, inside [-1, 1]
}

TEST(PlanPolicy, ActionIsClampedToCtrlrange) {
  auto m = adroit::loadModelString(kFreeBody).model;
  PlanPolicy p;
  fillPolicy(m.get(), p, 2);
  for (auto& u : p.policy.u) u << 50.0, -50.0, 3.0;
  std::vector<double> qpos(m->qpos0, m->qpos0 + m->nq), qvel(m->nv, 0.0);
  double ctrl[3];
  p.action(1.05, qpos.data(), qvel.data(), nullptr, ctrl);
  EXPECT_EQ(ctrl[0], 10.0);
  EXPECT_EQ(ctrl[1], -10.0);
  EXPECT_EQ(ctrl[2], 1.0);
}

TEST(PlanPolicy, ActionWithoutAPlanIsAnError) {
  auto m = adroit::loadModelString(kFreeBody).model;
  std::vector<double> qpos(m->qpos0, m->qpos0 + m->nq), qvel(m->nv, 0.0);
  double ctrl[3];
  PlanPolicy unbound;
  EXPECT_THROW(unbound.action(0, qpos.data(), qvel.data(), nullptr, ctrl), std::logic_error);
  PlanPolicy empty;
  empty.bind(m.get());
  EXPECT_THROW(empty.action(0, qpos.data(), qvel.data(), nullptr, ctrl), std::logic_error);
}

// PlanPolicy::reference: the deviation measured now, fed back through each later knot's gain.
TEST(PlanPolicy, ReferenceCarriesTodaysDeviationThroughEachKnotsGain) {
  auto m = adroit::loadModelString(kFreeBody).model;
  PlanPolicy p;
  fillPolicy(m.get(), p, 4);  // knots at 1.0, 1.1, 1.2, 1.3; all at the cart position 0
  for (int k = 0; k < 4; ++k) {
    p.policy.u[k] << 1.0 * k, -1.0 * k, 0.0;
    p.policy.K[k].setZero();
    p.policy.K[k](0, 6) = 2.0 * (k + 1);  // d u0 / d cart position, different per knot
  }
  std::vector<double> qpos(m->qpos0, m->qpos0 + m->nq), qvel(m->nv, 0.0);
  qpos[7] = 0.5;  // the cart is 0.5 m from the plan's position
  double out[4 * 3];
  // From t = 1.1: samples at 1.1, 1.2, 1.3 (the last knot), each u_k + K_k * 0.5.
  ASSERT_EQ(p.reference(1.1, qpos.data(), qvel.data(), nullptr, 10, out), 3);
  for (int j = 0; j < 3; ++j) {
    const int k = j + 1;
    EXPECT_NEAR(out[3 * j + 0], 1.0 * k + 2.0 * (k + 1) * 0.5, 1e-12) << "sample " << j;
    EXPECT_NEAR(out[3 * j + 1], -1.0 * k, 1e-12);
  }
  // Sample 0 is what the force-mode command would be; max_samples is respected.
  double ctrl[3];
  p.action(1.1, qpos.data(), qvel.data(), nullptr, ctrl);
  EXPECT_NEAR(out[0], ctrl[0], 1e-12);
  ASSERT_EQ(p.reference(1.0, qpos.data(), qvel.data(), nullptr, 2, out), 2);
  // Clamped like action(): u0 at knot 3 with feedback is 3 + 8 * 0.5 = 7 < 10; push it over.
  qpos[7] = 5.0;
  ASSERT_EQ(p.reference(1.3, qpos.data(), qvel.data(), nullptr, 10, out), 1);
  EXPECT_EQ(out[0], 10.0);
}
