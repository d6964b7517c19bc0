// Finite-difference derivatives against a system whose step is known in closed form, and
// the derivative_skip hold.
#include <adroit_core/mujoco_model.h>
#include <adroit_core/thread_pool.h>
#include <adroit_description/scenes.h>
#include <adroit_mpc/fd_derivatives.h>
#include <adroit_mpc/planning_model.h>
#include <gtest/gtest.h>

#include <limits>
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

// ---------------------------------------------------------------- B through generalised forces

namespace {

// Two links on a hinge chain pulled by a spatial tendon and a motor, a position servo with its
// affine bias, a motor driven beyond its range (clamped: a zero column), a servo whose force
// exceeds its forcerange (clamped: zero), one actuator whose gain depends on its length (not
// linear in the force: nudged per control), and a ball resting on the floor (a contact).
const char* kActuated = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01"/>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <site name="w" pos="0 0 0.8"/>
    <body pos="0 0 0.5"><joint name="s" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5" contype="0" conaffinity="0"/>
      <site name="s1" pos="0.1 0 0.03"/>
      <body pos="0.3 0 0"><joint name="e" type="hinge" axis="0 1 0" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.3" contype="0" conaffinity="0"/>
        <site name="e1" pos="0.1 0 0.03"/></body></body>
    <body pos="0.2 0 0.05"><freejoint/><geom type="sphere" size="0.05" mass="0.1"/></body>
  </worldbody>
  <tendon><spatial name="t"><site site="w"/><site site="s1"/><site site="e1"/></spatial></tendon>
  <actuator>
    <general tendon="t" gear="-1" gainprm="1" ctrlrange="0 20" forcerange="0 20"/>
    <motor joint="e" gear="2" ctrlrange="-3 3"/>
    <position joint="s" kp="5" ctrlrange="-1 1"/>
    <motor joint="s" ctrlrange="-1 1"/>
    <general joint="e" gainprm="2" ctrlrange="-1 1" forcerange="-1 1"/>
    <general joint="e" gaintype="affine" gainprm="1 0.5 0" ctrlrange="-1 1"/>
  </actuator>
</mujoco>)";

}  // namespace

TEST(FdDerivatives, ForceSpaceControlsGiveTheSameBAsOneNudgePerControl) {
  auto m = adroit::loadModelString(kActuated).model;
  adroit::DataPtr d = adroit::makeData(m.get());
  d->qpos[0] = 0.2, d->qpos[1] = -0.4, d->qvel[0] = 0.3;
  const double ctrl[] = {5.0, 0.5, 0.1, 1.5 /* beyond its range */, 0.8 /* force 1.6 > 1 */, 0.3};
  mju_copy(d->ctrl, ctrl, m->nu);
  for (int i = 0; i < 30; ++i) mj_step(m.get(), d.get());  // the ball settles into contact
  mju_copy(d->ctrl, ctrl, m->nu);
  mj_forward(m.get(), d.get());
  ASSERT_GT(d->ncon, 0);
  const int nx = 2 * m->nv;
  for (const bool warm : {false, true}) {
    FdSettings per_control{1e-6, false, 1, true, warm}, through_forces = per_control;
    through_forces.force_space_controls = true;
    FdDerivatives fd_control, fd_forces;
    fd_control.initialize(m.get(), 1, 1, per_control);
    fd_forces.initialize(m.get(), 1, 1, through_forces);
    Eigen::MatrixXd A_control(nx, nx), B_control(nx, m->nu), A_forces(nx, nx), B_forces(nx, m->nu);
    adroit::DataPtr work = adroit::copyData(m.get(), d.get());
    fd_control.knot(work.get(), 0, A_control, B_control);
    mj_copyData(work.get(), m.get(), d.get());
    fd_forces.knot(work.get(), 0, A_forces, B_forces);
    EXPECT_EQ(A_forces, A_control) << "warm " << warm;  // the state columns are untouched
    const double scale = 1 + B_control.cwiseAbs().maxCoeff();
    for (int a = 0; a < m->nu; ++a)
      EXPECT_LT((B_forces.col(a) - B_control.col(a)).cwiseAbs().maxCoeff(), 1e-6 * scale)
          << "actuator " << a << " warm " << warm;
    EXPECT_GT(B_control.col(0).cwiseAbs().maxCoeff(), 1e-4);  // the tendon moves the links
    EXPECT_GT(B_control.col(2).cwiseAbs().maxCoeff(), 1e-4);  // the servo too
    EXPECT_EQ(B_forces.col(3).cwiseAbs().maxCoeff(), 0.0);    // clamped control
    EXPECT_EQ(B_forces.col(4).cwiseAbs().maxCoeff(), 0.0);    // clamped force
  }
}

TEST(FdDerivatives, ForceSpaceControlsOnTheHandWithTheBottleInContact) {
  // The catch's planning model: 40 tendon actuators on 24 hand DOFs, the bottle resting on the
  // palm; B through the forces needs 24 nudges where one per control needs 40.
  PlanningModelSettings s;
  s.timestep = 0.02;
  auto model = loadPlanningModel(sceneFile(descriptionShareDir(), "bottle", true), s);
  const mjModel* m = model.get();
  adroit::DataPtr d = adroit::makeData(m);
  mj_resetDataKeyframe(m, d.get(), mj_name2id(m, mjOBJ_KEY, "rest"));
  for (int a = 0; a < m->nu; ++a) d->ctrl[a] = m->actuator_ctrlrange[2 * a];
  while (d->time < 0.3) mj_step(m, d.get());  // the bottle falls onto the palm
  for (int a = 0; a < m->nu; ++a)  // tensions across the range, one at its top
    d->ctrl[a] = m->actuator_ctrlrange[2 * a] + 0.25 * (a % 5) * (m->actuator_ctrlrange[2 * a + 1] - m->actuator_ctrlrange[2 * a]);
  mj_forward(m, d.get());
  ASSERT_GT(d->ncon, 0) << "the bottle should lie in the hand";
  const int nx = 2 * m->nv + m->na;
  FdSettings per_control{1e-6, false, 1, true, true}, through_forces = per_control;
  through_forces.force_space_controls = true;
  FdDerivatives fd_control, fd_forces;
  fd_control.initialize(m, 1, 1, per_control);
  fd_forces.initialize(m, 1, 1, through_forces);
  Eigen::MatrixXd A(nx, nx), B_control(nx, m->nu), B_forces(nx, m->nu);
  adroit::DataPtr work = adroit::copyData(m, d.get());
  fd_control.knot(work.get(), 0, A, B_control);
  mj_copyData(work.get(), m, d.get());
  fd_forces.knot(work.get(), 0, A, B_forces);
  EXPECT_LT((B_forces - B_control).cwiseAbs().maxCoeff(), 1e-6 * (1 + B_control.cwiseAbs().maxCoeff()));
}

// ------------------------------------------------------------- reuse across compute() calls

namespace {

struct Reuse {
  explicit Reuse(double max_age, double tolerance = 1e-3)
      : m(adroit::loadModelString(kPendulum).model), knots(simulate(m.get(), kT)), pool(2) {
    FdSettings s{1e-6, false, 3, true, true};
    s.max_age = max_age;
    s.reuse_tolerance = tolerance;
    fd.initialize(m.get(), kT, 2, s);
    fresh.initialize(m.get(), kT, 2, FdSettings{1e-6, false, 3, true, true});
    fresh_knots = knots;
  }
  // One call on `k`: the reusing derivatives and fresh ones (every knot of the pattern).
  void call(Knots& k) {
    fd.compute(pool, k.states, k.ctrl, k.times, k.A, k.B);
    fresh_knots.states = k.states;
    fresh_knots.ctrl = k.ctrl;
    fresh_knots.times = k.times;
    fresh.compute(pool, fresh_knots.states, fresh_knots.ctrl, fresh_knots.times, fresh_knots.A, fresh_knots.B);
  }
  std::vector<int> evaluatedKnots() const {
    std::vector<int> out;
    for (int i : fd.lastEvaluated()) out.push_back(fd.computedKnots()[i]);
    return out;
  }
  static constexpr int kT = 8;  // knots 0.01 s apart; computed 0, 3, 6, 7 (hold reach: 0.02 s)
  adroit::ModelPtr m;
  Knots knots, fresh_knots;
  adroit::ThreadPool pool;
  FdDerivatives fd, fresh;
};

}  // namespace

TEST(FdDerivativesReuse, ReusedDerivativesEqualFreshOnesWhenNothingMoved) {
  Reuse r(0.03);
  r.call(r.knots);
  EXPECT_EQ(r.evaluatedKnots(), (std::vector<int>{0, 3, 6, 7}));  // nothing kept yet
  const std::vector<Eigen::MatrixXd> first_A = r.knots.A, first_B = r.knots.B;
  for (int call = 1; call < 3; ++call) {  // the same trajectory again (a second iteration)
    r.call(r.knots);
    EXPECT_EQ(r.fd.lastEvaluatedKnots(), 0) << "call " << call;
    for (int t = 0; t < Reuse::kT; ++t) {
      EXPECT_EQ(r.knots.A[t], r.fresh_knots.A[t]) << "call " << call << " knot " << t;
      EXPECT_EQ(r.knots.B[t], r.fresh_knots.B[t]) << "call " << call << " knot " << t;
      EXPECT_EQ(r.knots.A[t], first_A[t]);
      EXPECT_EQ(r.knots.B[t], first_B[t]);
    }
  }
}

TEST(FdDerivativesReuse, EveryLinearisationIsRefreshedWithinMaxAge) {
  // The pendulum hanging still: the same state at every time, so a plan shifted in time is the
  // same plan and only the age decides. 0.01 s per call against a max age of 0.03 s: 4 knots
  // x 0.01 / 0.03 = 4/3 evaluations per call (1, 1, 2, ...), the oldest first.
  Reuse r(0.03);
  Knots still = r.knots;
  for (auto& x : still.states) x.setZero();
  for (auto& u : still.ctrl) u.setZero();
  r.call(still);
  int evaluations = 0;
  double oldest = 0;
  for (int call = 1; call <= 9; ++call) {
    for (double& t : still.times) t += 0.01;
    r.call(still);
    EXPECT_EQ(r.fd.lastEvaluatedKnots(), call % 3 == 0 ? 2 : 1) << "call " << call;
    evaluations += r.fd.lastEvaluatedKnots();
    EXPECT_LE(r.fd.lastOldestAge(), 0.03 + 1e-12) << "call " << call;
    oldest = std::max(oldest, r.fd.lastOldestAge());
    for (int t = 0; t < Reuse::kT; ++t) EXPECT_EQ(still.A[t], r.fresh_knots.A[t]) << "call " << call << " knot " << t;
  }
  EXPECT_EQ(evaluations, 12);
  EXPECT_NEAR(oldest, 0.03, 1e-12);  // linearisations do serve up to the max age
  // Against a max age of 0.1 s: 0.4 evaluations due per call. The last knot, whose time is
  // beyond the hold's reach of everything kept every third call, is evaluated then anyway and
  // counts; the due ones go to the oldest, which keeps the oldest in use at 0.07 s (refreshing
  // the newest instead lets it reach 0.09 s).
  Reuse slow(0.1);
  slow.call(still);
  evaluations = 0;
  oldest = 0;
  for (int call = 1; call <= 20; ++call) {
    for (double& t : still.times) t += 0.01;
    slow.call(still);
    evaluations += slow.fd.lastEvaluatedKnots();
    oldest = std::max(oldest, slow.fd.lastOldestAge());
  }
  EXPECT_EQ(evaluations, 9);
  EXPECT_NEAR(oldest, 0.07, 1e-12);
  // The first knot moving at every call takes an evaluation each time, more than half of what
  // is due at a max age of 0.03 s: the others still expire at 0.03 s and are evaluated then.
  Reuse jumpy(0.03);
  jumpy.call(still);
  for (int call = 1; call <= 12; ++call) {
    for (double& t : still.times) t += 0.01;
    still.states[0][0] = call % 2 ? 0.01 : -0.01;
    jumpy.call(still);
    EXPECT_LE(jumpy.fd.lastOldestAge(), 0.03 + 1e-12) << "call " << call;
    EXPECT_EQ(jumpy.fd.lastEvaluated().front(), 0) << "call " << call;  // the moved knot
  }
  // A call later than the max age keeps nothing.
  for (double& t : still.times) t += 0.05;
  r.call(still);
  EXPECT_EQ(r.fd.lastEvaluatedKnots(), 4);
}

TEST(FdDerivativesReuse, AKnotWhoseStateMovedIsRefreshed) {
  Reuse r(0.1);
  r.call(r.knots);
  Knots moved = r.knots;
  moved.states[6][0] += 0.05;  // the pendulum's angle at knot 6, beyond the 1e-3 tolerance
  r.call(moved);
  EXPECT_EQ(r.evaluatedKnots(), (std::vector<int>{6}));
  EXPECT_EQ(moved.A[6], r.fresh_knots.A[6]);  // evaluated at the moved state
  EXPECT_GT((moved.A[6] - r.knots.A[6]).norm(), 1e-6);
  for (int t : {0, 1, 2, 3, 4, 5, 7}) EXPECT_EQ(moved.A[t], r.knots.A[t]) << "knot " << t;  // kept (and held)
  // A velocity change counts as dt |dv|: 0.05 rad/s x 0.01 s = 5e-4, within the tolerance.
  Knots slower = moved;
  slower.states[3][1] += 0.05;
  r.call(slower);
  EXPECT_EQ(r.fd.lastEvaluatedKnots(), 0);
  slower.states[3][1] += 0.1;  // 1.5e-3: beyond
  r.call(slower);
  EXPECT_EQ(r.evaluatedKnots(), (std::vector<int>{3}));
}

TEST(FdDerivativesReuse, ALaterCallTakesTheLinearisationNearestInTimeWithinTheHold) {
  Reuse r(0.1, 1e9);  // any state: only the times decide
  r.call(r.knots);
  const std::vector<Eigen::MatrixXd> first = r.knots.A;
  // The same motion one knot later: knot t now sits where knot t + 1 was.
  Knots later = simulate(r.m.get(), Reuse::kT + 1);
  later.states.erase(later.states.begin());
  later.ctrl.erase(later.ctrl.begin());
  later.times.erase(later.times.begin());
  later.A.pop_back();
  later.B.pop_back();
  r.call(later);
  // Knot 0 (old time 1) would take the old knot 0's, 3 (old 4) takes the old 3's, 6 (old 7) and
  // 7 (old 8) the old knot 7's (the nearest). 4 x 0.01 / 0.1 = 0.4 evaluations due: none yet.
  EXPECT_EQ(r.fd.lastEvaluatedKnots(), 0);
  EXPECT_EQ(later.A[0], first[0]);
  EXPECT_EQ(later.A[3], first[3]);
  EXPECT_EQ(later.A[6], first[7]);
  EXPECT_EQ(later.A[7], first[7]);
  // Far in time (a new trial restarting the clock): nothing kept is near, all are evaluated.
  Knots restarted = r.knots;
  for (double& t : restarted.times) t -= 10;
  r.call(restarted);
  EXPECT_EQ(r.fd.lastEvaluatedKnots(), 4);
}

TEST(FdDerivativesReuse, ForgetAndNoReuseEvaluateEveryKnot) {
  Reuse r(0.1);
  r.call(r.knots);
  r.fd.forget();
  r.call(r.knots);
  EXPECT_EQ(r.fd.lastEvaluatedKnots(), 4);
  Reuse none(0.0);  // max_age 0: the path before reuse
  for (int call = 0; call < 3; ++call) {
    none.call(none.knots);
    EXPECT_EQ(none.fd.lastEvaluatedKnots(), 4);
  }
}

TEST(FdDerivativesReuse, BadReuseSettingsAreRejected) {
  auto m = adroit::loadModelString(kSlider).model;
  FdDerivatives fd;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const auto& [age, tolerance] : {std::pair{-0.1, 0.01}, std::pair{nan, 0.01}, std::pair{0.1, 0.0},
                                       std::pair{0.1, -1.0}, std::pair{0.1, nan}}) {
    FdSettings s;
    s.max_age = age;
    s.reuse_tolerance = tolerance;
    EXPECT_THROW(fd.initialize(m.get(), 5, 1, s), std::invalid_argument) << age << " " << tolerance;
  }
}
