// Finite-difference derivatives against a system whose step is known in closed form, and
// the derivative_skip hold.
#include <adroit_core/mujoco_model.h>
#include <adroit_core/thread_pool.h>
#include <adroit_mpc/fd_derivatives.h>
#include <gtest/gtest.h>

using namespace adroit_mpc;

namespace {

// A damped slider, no contacts, no armature: MuJoCo's semi-implicit Euler integrates the
// joint damping implicitly, so with h = timestep, m = mass, b = damping:
//   v' = v + h (u - b v) / (m + h b),   q' = q + h v'.
const double kH = 0.01, kMass = 2.0, kDamping = 0.4;
const char* kSlider = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01" gravity="0 0 0"/>
  <worldbody>
    <body><joint name="q" type="slide" axis="1 0 0" damping="0.4"/>
      <geom type="sphere" size="0.05" mass="2" contype="0" conaffinity="0"/></body>
  </worldbody>
  <actuator><motor joint="q" ctrlrange="-5 5"/></actuator>
</mujoco>)";

const char* kPendulum = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01"/>
  <worldbody>
    <body><joint name="hinge" type="hinge" axis="0 1 0" damping="0.05"/>
      <geom type="sphere" pos="0 0 -0.5" size="0.05" mass="1" contype="0" conaffinity="0"/></body>
  </worldbody>
  <actuator><motor joint="hinge" ctrlrange="-4 4"/></actuator>
</mujoco>)";

struct Knots {
  std::vector<Eigen::VectorXd> states, ctrl;
  std::vector<double> times;
  std::vector<Eigen::MatrixXd> A, B;
};

// A trajectory of the model under a varying control, T knots.
Knots simulate(const mjModel* m, int T) {
  Knots k;
  adroit::DataPtr d = adroit::makeData(m);
  d->qpos[0] = 0.3;
  for (int t = 0; t <= T; ++t) {
    Eigen::VectorXd x(m->nq + m->nv);
    x << Eigen::Map<Eigen::VectorXd>(d->qpos, m->nq), Eigen::Map<Eigen::VectorXd>(d->qvel, m->nv);
    k.states.push_back(x);
    k.times.push_back(d->time);
    if (t == T) break;
    Eigen::VectorXd u(m->nu);
    u.setConstant(std::sin(0.7 * t));
    k.ctrl.push_back(u);
    mju_copy(d->ctrl, u.data(), m->nu);
    mj_step(m, d.get());
  }
  k.A.assign(T, Eigen::MatrixXd::Zero(2 * m->nv, 2 * m->nv));
  k.B.assign(T, Eigen::MatrixXd::Zero(2 * m->nv, m->nu));
  return k;
}

}  // namespace

TEST(FdDerivatives, MatchTheHandDerivedDampedSliderStep) {
  auto m = adroit::loadModelString(kSlider).model;
  Knots k = simulate(m.get(), 5);
  adroit::ThreadPool pool(2);
  FdDerivatives fd;
  fd.initialize(m.get(), 5, 2, FdSettings{1e-6, false, 1});
  fd.compute(pool, k.states, k.ctrl, k.times, k.A, k.B);
  const double effective = kMass + kH * kDamping;
  const double dv_dv = 1 - kH * kDamping / effective;
  const double dv_du = kH / effective;
  for (int t = 0; t < 5; ++t) {
    EXPECT_NEAR(k.A[t](0, 0), 1.0, 1e-7);          // dq'/dq
    EXPECT_NEAR(k.A[t](0, 1), kH * dv_dv, 1e-7);   // dq'/dv
    EXPECT_NEAR(k.A[t](1, 0), 0.0, 1e-7);          // dv'/dq
    EXPECT_NEAR(k.A[t](1, 1), dv_dv, 1e-7);        // dv'/dv
    EXPECT_NEAR(k.B[t](0, 0), kH * dv_du, 1e-7);   // dq'/du
    EXPECT_NEAR(k.B[t](1, 0), dv_du, 1e-7);        // dv'/du
  }
}

TEST(FdDerivatives, SkipHoldsEachComputedKnotAndAlwaysComputesTheLast) {
  auto m = adroit::loadModelString(kPendulum).model;
  const int T = 8;
  Knots every = simulate(m.get(), T), skipped = simulate(m.get(), T);
  adroit::ThreadPool pool(2);
  FdDerivatives fd_every, fd_skip;
  fd_every.initialize(m.get(), T, 2, FdSettings{1e-6, true, 1});
  fd_skip.initialize(m.get(), T, 2, FdSettings{1e-6, true, 3});
  EXPECT_EQ(fd_skip.computedKnots(), (std::vector<int>{0, 3, 6, 7}));
  fd_every.compute(pool, every.states, every.ctrl, every.times, every.A, every.B);
  fd_skip.compute(pool, skipped.states, skipped.ctrl, skipped.times, skipped.A, skipped.B);
  for (int t : {0, 3, 6, 7}) {
    EXPECT_TRUE(skipped.A[t].isApprox(every.A[t], 1e-12)) << "computed knot " << t;
    EXPECT_TRUE(skipped.B[t].isApprox(every.B[t], 1e-12)) << "computed knot " << t;
  }
  for (int t : {1, 2}) EXPECT_EQ(skipped.A[t], every.A[0]) << "held knot " << t;
  for (int t : {4, 5}) EXPECT_EQ(skipped.A[t], every.A[3]) << "held knot " << t;
  // The pendulum's linearisation changes along the swing, so holding is an approximation.
  EXPECT_GT((every.A[3] - every.A[0]).norm(), 1e-6);
  // dv'/dq = h * (-g / l) cos(q) for a point mass pendulum (damping aside): sign check.
  EXPECT_LT(every.A[0](1, 0), 0.0);
}

TEST(FdDerivatives, BadSettingsAreRejected) {
  auto m = adroit::loadModelString(kSlider).model;
  FdDerivatives fd;
  EXPECT_THROW(fd.initialize(m.get(), 5, 1, FdSettings{0.0, false, 1}), std::invalid_argument);
  EXPECT_THROW(fd.initialize(m.get(), 5, 1, FdSettings{1e-6, false, 0}), std::invalid_argument);
  EXPECT_THROW(fd.initialize(m.get(), 0, 1, FdSettings{1e-6, false, 1}), std::invalid_argument);
}
