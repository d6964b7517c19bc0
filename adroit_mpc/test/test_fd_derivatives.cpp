// Finite-difference derivatives against a system whose step is known in closed form, and
// the derivative_skip hold.
#include <adroit_core/mujoco_model.h>
#include <adroit_core/thread_pool.h>
#include <adroit_description/scenes.h>
#include <adroit_mpc/fd_derivatives.h>
#include <adroit_mpc/planning_model.h>
#include <gtest/gtest.h>

#include <string>
#include <utility>

using namespace adroit_mpc;
using adroit::description::sceneFile;

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

// Trees on a fixed base: an actuated double pendulum (a) with a slider (c) tied to it by a
// fixed tendon, a free slider (b), and a slider (d) whose ball sits 'gap' above the pendulum's
// tip (a contact once gap is within the margin).
std::string treesXml(double gap) {
  return R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01"/>
  <worldbody>
    <body name="base">
      <body name="a1" pos="0 0 1"><joint name="a1" type="hinge" axis="0 1 0" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5"/>
        <body name="a2" pos="0.3 0 0"><joint name="a2" type="hinge" axis="0 1 0" damping="0.1"/>
          <geom name="tip" type="sphere" pos="0.3 0 0" size="0.05" mass="0.3"/></body></body>
      <body name="b" pos="1 0 0.5"><joint name="b" type="slide" axis="0 0 1" stiffness="20" damping="0.5"/>
        <geom type="sphere" size="0.05" mass="0.2" contype="0" conaffinity="0"/></body>
      <body name="c" pos="-1 0 0.5"><joint name="c" type="slide" axis="1 0 0" damping="0.3"/>
        <geom type="sphere" size="0.05" mass="0.2" contype="0" conaffinity="0"/></body>
      <body name="d" pos="0.6 0 )" + std::to_string(1.1 + gap) + R"("><joint name="d" type="slide" axis="0 0 1" damping="0.2"/>
        <geom type="sphere" size="0.05" mass="0.1" margin="0.01"/></body>
    </body>
  </worldbody>
  <tendon><fixed name="ac"><joint joint="a2" coef="0.1"/><joint joint="c" coef="1"/></fixed></tendon>
  <actuator><motor joint="a1" ctrlrange="-3 3"/><motor tendon="ac" ctrlrange="-3 3"/>
    <motor joint="b" ctrlrange="-1 1"/></actuator>
</mujoco>)";
}

TEST(FdDerivatives, SeparatedTreesShareNudgedColumnsAndMatchOneColumnPerDof) {
  for (const double gap : {0.2, 0.0}) {  // d far above the tip; d resting on it
    auto m = adroit::loadModelString(treesXml(gap)).model;
    ASSERT_EQ(m->nv, 5);
    adroit::DataPtr d = adroit::makeData(m.get());
    d->qpos[0] = 0.0, d->qvel[0] = 0.4, d->qvel[2] = -0.2, d->qvel[3] = 0.1;
    for (int a = 0; a < m->nu; ++a) d->ctrl[a] = 0.3 * (a + 1) - 0.5;
    mj_forward(m.get(), d.get());
    const bool touching = gap == 0.0;
    ASSERT_EQ(d->ncon > 0, touching) << "gap " << gap;
    for (const bool centered : {false, true}) {
      // MuJoCo's own differences, one column per DOF.
      const int nx = 2 * m->nv;
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> A_ref(nx, nx), B_ref(nx, m->nu);
      adroit::DataPtr ref = adroit::copyData(m.get(), d.get());
      mjd_transitionFD(m.get(), ref.get(), 1e-6, centered, A_ref.data(), B_ref.data(), nullptr, nullptr);
      for (const auto& [group, warm] : {std::pair{false, false}, std::pair{false, true}, std::pair{true, false},
                                        std::pair{true, true}}) {
        FdDerivatives fd;
        fd.initialize(m.get(), 1, 1, FdSettings{1e-6, centered, 1, group, warm});
        Eigen::MatrixXd A(nx, nx), B(nx, m->nu);
        adroit::DataPtr work = adroit::copyData(m.get(), d.get());
        const int columns = fd.knot(work.get(), 0, A, B);
        // Trees: {a1 a2, c} by the tendon (+ d when it rests on the tip), {b}, {d}.
        EXPECT_EQ(columns, group ? (touching ? 4 : 3) : 5) << "gap " << gap;
        // Grouped: the nudges share one solver run. Warm started from the nominal's solution: the
        // same derivatives to the solver's precision (mjd_transitionFD starts from the knot's).
        const double tolerance = group ? 1e-7 : warm ? 1e-8 : 1e-12;
        EXPECT_LT((A - Eigen::MatrixXd(A_ref)).cwiseAbs().maxCoeff(), tolerance * (1 + A_ref.cwiseAbs().maxCoeff()))
            << "gap " << gap << " centered " << centered << " grouped " << group << " warm " << warm;
        EXPECT_LT((B - Eigen::MatrixXd(B_ref)).cwiseAbs().maxCoeff(), tolerance * (1 + B_ref.cwiseAbs().maxCoeff()));
        if (!group) continue;
        // Separated trees: exact zeros between b and the others (and d while it is in the air).
        const int b = 2, dd = 4;
        for (int other : {0, 1, 3, 4}) {
          for (int rows : {0, m->nv})
            for (int cols : {0, m->nv}) {
              EXPECT_EQ(A(rows + b, cols + other), 0.0);
              EXPECT_EQ(A(rows + other, cols + b), 0.0);
            }
        }
        if (!touching) EXPECT_EQ(A(m->nv + dd, 0), 0.0);
        else EXPECT_NE(A(m->nv + dd, 0), 0.0);  // the tip's angle moves the ball resting on it
      }
    }
  }
}

TEST(FdDerivatives, BadSettingsAreRejected) {
  auto m = adroit::loadModelString(kSlider).model;
  FdDerivatives fd;
  EXPECT_THROW(fd.initialize(m.get(), 5, 1, FdSettings{0.0, false, 1}), std::invalid_argument);
  EXPECT_THROW(fd.initialize(m.get(), 5, 1, FdSettings{1e-6, false, 0}), std::invalid_argument);
  EXPECT_THROW(fd.initialize(m.get(), 0, 1, FdSettings{1e-6, false, 1}), std::invalid_argument);
}

TEST(FdDerivatives, PositionNudgesTestOnlyThePairsInContactAndAgreeWithTheFullPass) {
  // The keypad's planning model with typing's contact settings collides through explicit pairs
  // only; the first finger pressed onto its key and the palm down onto the keypad give the
  // knot contacts. The same model testing every pair in every nudge (mjCOL_ALL: the explicit
  // pairs cover every colliding body pair, so the dynamic pass adds nothing) is the reference.
  PlanningModelSettings s;
  s.timestep = 0.01;
  s.contact_margin = s.contact_softness = 0.001;
  auto restricted = loadPlanningModel(sceneFile(descriptionShareDir(), "keypad", true), s);
  ASSERT_EQ(restricted->opt.collision, mjCOL_PAIR);
  adroit::ModelPtr full = adroit::copyModel(restricted.get());
  full->opt.collision = mjCOL_ALL;

  const mjModel* m = restricted.get();
  adroit::DataPtr d = adroit::makeData(m);
  mj_resetDataKeyframe(m, d.get(), mj_name2id(m, mjOBJ_KEY, "rest"));
  for (int a = 0; a < m->nu; ++a) {
    const std::string name = mj_id2name(m, mjOBJ_ACTUATOR, a);
    d->ctrl[a] = name.find("_flex") != std::string::npos &&
                         (name.find("FF") != std::string::npos || name.find("WRJ1") != std::string::npos)
                     ? 30.0
                     : m->actuator_ctrlrange[2 * a];
  }
  while (d->time < 0.3) mj_step(m, d.get());
  mj_forward(m, d.get());
  ASSERT_GE(d->ncon, 2) << "the pressed finger and palm should touch";
  ASSERT_LT(d->ncon, m->npair);

  const int nx = 2 * m->nv + m->na;
  Eigen::MatrixXd A_restricted(nx, nx), B_restricted(nx, m->nu), A_full(nx, nx), B_full(nx, m->nu);
  FdDerivatives fd_restricted, fd_full;
  fd_restricted.initialize(m, 1, 1, FdSettings{});
  fd_full.initialize(full.get(), 1, 1, FdSettings{});
  adroit::DataPtr work = adroit::copyData(m, d.get());
  fd_restricted.knot(work.get(), 0, A_restricted, B_restricted);
  mj_copyData(work.get(), m, d.get());
  fd_full.knot(work.get(), 0, A_full, B_full);
  // The contacts move the position columns (the pressed key's and the finger's) ...
  EXPECT_GT(A_full.cwiseAbs().maxCoeff(), 1.0);
  // ... and both passes see the same contacts in the same order.
  EXPECT_LT((A_restricted - A_full).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((B_restricted - B_full).cwiseAbs().maxCoeff(), 1e-9);
}
