#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "adroit_pneumatics/pressure_control.h"

using namespace adroit::pneumatics;

namespace {
class Linear : public ScalarDynamics {
 public:
  Linear(double a, double b) : a_(a), b_(b) {}
  double step(double p, double u, double* dp, double* du) const override {
    if (dp) *dp = a_;
    if (du) *du = b_;
    return a_ * p + b_ * u;
  }
  double a_, b_;
};
class Broken : public ScalarDynamics {
 public:
  double step(double, double, double* dp, double* du) const override {
    if (dp) *dp = 1;
    if (du) *du = 1;
    return std::numeric_limits<double>::quiet_NaN();
  }
};
}  // namespace

// Independent finite-horizon LQR on x = [p, w], x' = A x + B u with B = [b, 1] (w holds
// the command), cost x'Qx + u'Ru + 2 x'N u where Q = diag(ap, aw), R = au + aw, N = [0, -aw]'
// (the expansion of eq. 5.12 with squared norms); terminal cost ap p^2. Returns u_i = -K_i x.
static std::vector<Eigen::RowVector2d> lqrGains(const Eigen::Matrix2d& A, double b, const IlqgParams& prm) {
  const Eigen::Vector2d B(b, 1.0), N(0.0, -prm.alpha_w);
  const Eigen::Matrix2d Q = Eigen::Vector2d(prm.alpha_p, prm.alpha_w).asDiagonal();
  const double R = prm.alpha_u + prm.alpha_w;
  Eigen::Matrix2d P;
  P << prm.alpha_p, 0, 0, 0;
  std::vector<Eigen::RowVector2d> K(prm.horizon);
  for (int i = prm.horizon - 1; i >= 0; --i) {
    const double S = R + B.dot(P * B);
    K[i] = (B.transpose() * P * A + N.transpose()) / S;
    P = Q + A.transpose() * P * A - (A.transpose() * P * B + N) * (B.transpose() * P * A + N.transpose()) / S;
  }
  return K;
}

TEST(Ilqg, LinearQuadraticCaseEqualsLqr) {
  IlqgParams prm;
  prm.horizon = 30;
  prm.alpha_p = 1.0, prm.alpha_u = 0.05, prm.alpha_w = 0.02;
  prm.u_min = -5, prm.u_max = 5;
  const double a = 0.95, b = 0.04;
  const Linear f(a, b);
  std::vector<double> zero(prm.horizon + 1, 0.0);
  IlqgSolver solver(prm);
  const double p0 = 0.3, w0 = -0.5;
  ASSERT_TRUE(solver.solve(f, p0, w0, zero.data(), zero.data(), {}, 1));
  Eigen::Matrix2d A;
  A << a, 0, 0, 0;
  const auto K = lqrGains(A, b, prm);
  Eigen::Vector2d x(p0, w0);
  for (int i = 0; i < prm.horizon; ++i) {
    const double u = -K[i] * x;
    EXPECT_NEAR(solver.u()[i], u, 1e-9) << i;
    EXPECT_NEAR(solver.gainP()[i], -K[i](0), 1e-9) << i;
    EXPECT_NEAR(solver.gainW()[i], -K[i](1), 1e-9) << i;
    x = Eigen::Vector2d(a * x(0) + b * u, u);
  }
}

TEST(Ilqg, RespectsCommandLimits) {
  IlqgParams prm;
  prm.horizon = 20;
  prm.alpha_p = 1.0;  // the weights are in the dynamics' units, here unitless
  const Linear f(0.9, 0.1);
  std::vector<double> ref(prm.horizon + 1, 10.0), zero(prm.horizon + 1, 0.0);
  IlqgSolver solver(prm);
  ASSERT_TRUE(solver.solve(f, 0.0, 0.0, ref.data(), zero.data(), {}, 5));
  for (double u : solver.u()) {
    EXPECT_LE(u, prm.u_max);
    EXPECT_GE(u, prm.u_min);
  }
  EXPECT_DOUBLE_EQ(solver.u()[0], prm.u_max);
}

TEST(Ilqg, NonFiniteResultIsRejected) {
  IlqgParams prm;
  prm.horizon = 10;
  std::vector<double> ref(prm.horizon + 1, 0.3), zero(prm.horizon + 1, 0.0);
  IlqgSolver solver(prm);
  EXPECT_FALSE(solver.solve(Broken(), 0.2, 0.0, ref.data(), zero.data(), {}, 2));
}

namespace {
ParametricModel model() {
  ParametricParams p;
  p.c2 = 0.05, p.c3 = 2.0, p.c4 = 0.5, p.c7 = 60, p.c9 = 10, p.cg = 0.2;
  return ParametricModel(p);
}
double simulate(PressureController& c, double target, double seconds, double* final_error) {
  const ParametricModel m = model();
  ParametricInputs in;
  in.volume = 1e-6;
  double p = 150e3, w = 0.0;
  std::vector<double> ref(101, target);
  double worst_late = 0;
  for (int k = 0; k < static_cast<int>(seconds / 0.005); ++k) {
    const double u = c.update(k * 0.005, p, w, in, ref.data(), 101, 0.005, nullptr, true);
    EXPECT_TRUE(std::isfinite(u));
    p = m.step(p, u, 0.005, in);
    w = u;
    if (k * 0.005 > seconds - 0.1) worst_late = std::max(worst_late, std::abs(p - target));
  }
  *final_error = worst_late;
  return p;
}
}  // namespace

TEST(IlqgController, TracksAConstantReference) {
  IlqgPressureController c(model(), IlqgParams{});
  double err;
  simulate(c, 400e3, 0.6, &err);
  EXPECT_LT(err, 2e3);
}

TEST(PidfController, IntegralRemovesSteadyError) {
  PidfParams prm;
  prm.feedforward = false;
  prm.kp = 2e-6, prm.ki = 2e-5, prm.kd = 0.0;  // 2 V/MPa, 20 V/(MPa s)
  PidfController c(model(), prm);
  double err;
  simulate(c, 350e3, 2.0, &err);
  EXPECT_LT(err, 2e3);
}

// The feedforward takes the previewed reference feedforward_advance ahead (samples 5 ms
// apart, the jump 10 ms ahead): the new level's steady-state command at 10 ms, the
// interpolated reference's at 7.5 ms, the current level's without an advance.
TEST(PidfController, FeedforwardTakesTheReferenceAheadByTheAdvance) {
  PidfParams prm;
  prm.kp = prm.ki = prm.kd = 0.0;  // feedforward only
  const ParametricModel m = model();
  ParametricInputs in;
  in.volume = 1e-6;
  const std::vector<double> ref = {200e3, 200e3, 400e3, 400e3};
  const auto command = [&](double advance) {
    prm.feedforward_advance = advance;
    PidfController c(m, prm);
    return c.update(0.0, 200e3, 0.0, in, ref.data(), 4, 0.005, nullptr, true);
  };
  const auto steady = [&](double p) { return m.inverseSteadyState(p, in, prm.u_min, prm.u_max); };
  EXPECT_NEAR(command(0.0), steady(200e3), 1e-9);
  EXPECT_NEAR(command(0.0075), steady(300e3), 1e-9);
  EXPECT_NEAR(command(0.010), steady(400e3), 1e-9);
  EXPECT_GT(steady(400e3), steady(200e3) + 0.1);  // the cases differ
  prm.feedforward_advance = -0.001;
  EXPECT_THROW(PidfController(m, prm), std::invalid_argument);
}

TEST(IlqgController, PolicyExpiresWithoutNewSolve) {
  IlqgPressureController c(model(), IlqgParams{}, 1000);
  ParametricInputs in;
  std::vector<double> ref(101, 300e3);
  EXPECT_TRUE(std::isfinite(c.update(0.0, 200e3, 0.0, in, ref.data(), 101, 0.005, nullptr, true)));
  EXPECT_TRUE(std::isfinite(c.evaluate(0.49, 200e3, 0.0)));
  EXPECT_TRUE(std::isnan(c.evaluate(0.51, 200e3, 0.0)));  // past the 0.5 s horizon
}

// A pool whose tick budget is spent (may_solve false) gets the plan it has, evaluated now;
// the solve it missed stays due and runs at the next call that may solve, schedule or not.
TEST(IlqgController, ASolveThatMayNotRunIsDeferredAndThePlanEvaluated) {
  IlqgPressureController c(model(), IlqgParams{}, 3);
  ParametricInputs in;
  std::vector<double> ref(101, 300e3);
  ControlStats stats;
  // Without a plan it solves even when it may not (else it would have nothing to command).
  EXPECT_TRUE(std::isfinite(c.update(0.0, 200e3, 0.0, in, ref.data(), 101, 0.005, &stats, false)));
  EXPECT_TRUE(stats.solved);
  c.update(0.005, 210e3, 0.5, in, ref.data(), 101, 0.005, &stats, true);  // tick 1 of 3: not scheduled
  EXPECT_FALSE(stats.solved);
  c.update(0.010, 220e3, 0.5, in, ref.data(), 101, 0.005, &stats, true);  // tick 2 of 3
  EXPECT_FALSE(stats.solved);
  // Tick 3: scheduled, but may not solve: the plan of t = 0 acts, as evaluate() gives it.
  const double t0_plan = c.policy().t0;
  const double held = c.update(0.015, 230e3, 0.5, in, ref.data(), 101, 0.005, &stats, false);
  EXPECT_FALSE(stats.solved);
  EXPECT_EQ(c.policy().t0, t0_plan);
  EXPECT_DOUBLE_EQ(held, c.evaluate(0.015, c.pressureEstimate(), 0.5));
  // The deferred solve is still due at the next call that may solve.
  c.update(0.020, 240e3, held, in, ref.data(), 101, 0.005, &stats, true);
  EXPECT_TRUE(stats.solved);
  EXPECT_EQ(c.policy().t0, 0.020);
}

TEST(Resample, InterpolatesAndHolds) {
  const double in[] = {0.0, 10.0, 20.0};
  double out[5];
  resampleReference(in, 3, 0.01, 0.0, 0.005, 5, out);
  EXPECT_DOUBLE_EQ(out[1], 5.0);
  EXPECT_DOUBLE_EQ(out[4], 20.0);
}

namespace {
// p' = a p + c w + b u: the previous command still acts (dead time).
class LinearWithMemory : public ScalarDynamics {
 public:
  LinearWithMemory(double a, double b, double c) : a_(a), b_(b), c_(c) {}
  double step(double p, double u, double* dp, double* du) const override { return stepWithMemory(p, 0.0, u, dp, nullptr, du); }
  double stepWithMemory(double p, double w, double u, double* dp, double* dw, double* du) const override {
    if (dp) *dp = a_;
    if (dw) *dw = c_;
    if (du) *du = b_;
    return a_ * p + c_ * w + b_ * u;
  }
  double a_, b_, c_;
};
}  // namespace

TEST(Ilqg, DeadTimeCaseEqualsLqr) {
  IlqgParams prm;
  prm.horizon = 25;
  prm.alpha_p = 1.0, prm.alpha_u = 0.03, prm.alpha_w = 0.02;
  prm.u_min = -5, prm.u_max = 5;
  const double a = 0.9, b = 0.03, c = 0.02;
  const LinearWithMemory f(a, b, c);
  std::vector<double> zero(prm.horizon + 1, 0.0);
  IlqgSolver solver(prm);
  const double p0 = 0.25, w0 = 0.7;
  ASSERT_TRUE(solver.solve(f, p0, w0, zero.data(), zero.data(), {}, 1));
  Eigen::Matrix2d A;  // the previous command w also moves the pressure (dead time)
  A << a, c, 0, 0;
  const auto K = lqrGains(A, b, prm);
  Eigen::Vector2d x(p0, w0);
  for (int i = 0; i < prm.horizon; ++i) {
    const double u = -K[i] * x;
    EXPECT_NEAR(solver.u()[i], u, 1e-9) << i;
    EXPECT_NEAR(solver.gainW()[i], -K[i](1), 1e-9) << i;
    x = Eigen::Vector2d(a * x(0) + c * x(1) + b * u, u);
  }
}

TEST(IlqgController, OffsetFreeAgainstAConstantDisturbance) {
  // The plant is the controller's model plus a constant pressure-rate bias (a leak the model
  // does not know, -2 MPa/s): without the disturbance estimate a steady offset remains,
  // with it the error goes to (near) zero.
  const ParametricModel m = model();
  ParametricInputs in;
  in.volume = 1e-6;
  auto run = [&](double gain) {
    IlqgParams prm;
    prm.disturbance_gain = gain;
    prm.measurement_gain = 1.0;
    IlqgPressureController c(m, prm);
    std::vector<double> ref(101, 350e3);
    double p = 200e3, w = 0.0;
    for (int k = 0; k < 300; ++k) {
      const double u = c.update(k * 0.005, p, w, in, ref.data(), 101, 0.005, nullptr, true);
      p = m.step(p, u, 0.005, in) - 2e6 * 0.005;
      w = u;
    }
    return std::abs(p - 350e3);
  };
  const double without = run(0.0), with = run(0.3);
  EXPECT_GT(without, 5e3);
  EXPECT_LT(with, 0.5e3);
}

TEST(IlqgController, RejectsBadEstimatorParameters) {
  IlqgParams prm;
  prm.disturbance_gain = 1.5;
  EXPECT_THROW(IlqgPressureController(model(), prm), std::invalid_argument);
  prm = IlqgParams{};
  prm.measurement_gain = 0.0;
  EXPECT_THROW(IlqgPressureController(model(), prm), std::invalid_argument);
}

TEST(IlqgController, ReferenceJumpStartsAtTheLimit) {
  // Hold 200 kPa, then the whole future reference jumps to 450 kPa. With the "limit, then
  // hold" guess the first command after the jump opens the valve to its limit, and the
  // pressure error over the following 100 ms is no larger than without the guess.
  const ParametricModel m = model();
  ParametricInputs in;
  in.volume = 1e-6;
  auto run = [&](double threshold, double* first_after_jump) {
    IlqgParams prm;
    prm.jump_threshold = threshold;
    IlqgPressureController c(m, prm);
    double p = 200e3, w = 0.0, sq = 0;
    for (int k = 0; k < 100; ++k) {
      const double target = k < 60 ? 200e3 : 450e3;
      std::vector<double> ref(101, target);
      const double u = c.update(k * 0.005, p, w, in, ref.data(), 101, 0.005, nullptr, true);
      if (k == 60) *first_after_jump = u;
      p = m.step(p, u, 0.005, in);
      w = u;
      if (k >= 60 && k < 80) sq += (p - target) * (p - target);
    }
    return std::sqrt(sq / 20);
  };
  double first_with = 0, first_without = 0;
  const double with = run(20e3, &first_with), without = run(0.0, &first_without);  // Pa
  EXPECT_DOUBLE_EQ(first_with, IlqgParams{}.u_max);
  EXPECT_LE(with, without * 1.001) << "with " << with << " without " << without;
}

TEST(IlqgController, LargeInnovationIsTakenInFull) {
  // Sensor noise (a small innovation) is filtered with measurement_gain; an innovation far
  // beyond measurement_band is model error and the estimate follows it to within the band.
  const ParametricModel m = model();
  ParametricInputs in;
  in.volume = 1e-6;
  IlqgParams prm;
  prm.measurement_gain = 0.25, prm.measurement_band = 4000, prm.disturbance_gain = 0.0;
  IlqgPressureController c(m, prm);
  std::vector<double> ref(101, 300e3);
  double p = 300e3, w = 0.0;
  for (int k = 0; k < 40; ++k) {  // settle on the model itself: innovations are zero
    w = c.update(k * 0.005, p, w, in, ref.data(), 101, 0.005, nullptr, true);
    p = m.stepDelayed(p, w, w, 0.005, in);
  }
  const double pred = m.stepDelayed(c.pressureEstimate(), w, w, 0.005, in);
  c.update(40 * 0.005, pred + 2000.0, w, in, ref.data(), 101, 0.005, nullptr, true);  // noise-sized
  EXPECT_NEAR(c.pressureEstimate(), pred + 0.25 * 2000.0, 50.0);
  const double pred2 = m.stepDelayed(c.pressureEstimate(), w, w, 0.005, in);
  c.update(41 * 0.005, pred2 + 60e3, w, in, ref.data(), 101, 0.005, nullptr, true);  // model error
  EXPECT_NEAR(c.pressureEstimate(), pred2 + 60e3 - 0.75 * 4000.0, 50.0);
}
