// The LQ machinery on a real nonlinear problem: swing-up of a MuJoCo pendulum whose motor
// is too weak to lift it directly (torque limit 0.7 N m against a gravity torque up to
// 2.45 N m), so the optimal controls pump energy and sit on the limits. A short iLQR loop here
// (mjd_transitionFD derivatives, quadratic cost, BackwardPass with control bounds,
// backtrackingLineSearch, RegularizationSchedule) must converge to the upright state with
// a monotonically decreasing cost and never command outside the limits.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "adroit_core/line_search.h"
#include "adroit_core/lq_backward_pass.h"
#include "adroit_core/mujoco_model.h"

namespace {

using namespace adroit;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A 0.5 m, 1 kg rod on a hinge about y; q = 0 hangs down, q = pi is upright.
const char* kPendulum = R"(
<mujoco>
  <option timestep="0.01" gravity="0 0 -9.81"/>
  <worldbody>
    <body name="rod">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.02"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02" mass="1"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="hinge" gear="1" ctrllimited="true" ctrlrange="-0.7 0.7"/>
  </actuator>
</mujoco>)";

constexpr double kPi = 3.14159265358979323846;
constexpr int kHorizon = 300;          // 3 s
constexpr double kControlWeight = 0.02;
constexpr double kTerminalAngle = 200.0, kTerminalVelocity = 20.0;

double runningCost(const VectorXd& /*x*/, const VectorXd& u) { return 0.5 * kControlWeight * u.squaredNorm(); }
double terminalCost(const VectorXd& x) {
  return 0.5 * kTerminalAngle * (x[0] - kPi) * (x[0] - kPi) + 0.5 * kTerminalVelocity * x[1] * x[1];
}

class Swingup {
 public:
  Swingup() : model_(loadModelString(kPendulum).model), data_(makeData(model_.get())) {
    lo_ = VectorXd::Constant(1, model_->actuator_ctrlrange[0]);
    hi_ = VectorXd::Constant(1, model_->actuator_ctrlrange[1]);
  }
  const VectorXd& lo() const { return lo_; }
  const VectorXd& hi() const { return hi_; }

  // Simulates u_t = clamp(u_ref_t + alpha k_t + K_t (x_t - x_ref_t)) from x0 = rest; returns
  // the cost. With no gains, plays u_ref as is.
  double rollout(const std::vector<VectorXd>& x_ref, const std::vector<VectorXd>& u_ref, const FeedbackGains* gains,
                 double alpha, std::vector<VectorXd>& x, std::vector<VectorXd>& u) {
    mj_resetData(model_.get(), data_.get());
    double cost = 0;
    for (int t = 0; t < kHorizon; ++t) {
      x[t] << data_->qpos[0], data_->qvel[0];
      u[t] = u_ref[t];
      if (gains) {
        u[t] += alpha * gains->k[t];
        // The backward pass's box QP keeps the feedforward part inside the limits itself.
        min_feedforward_ = std::min(min_feedforward_, u[t][0]);
        max_feedforward_ = std::max(max_feedforward_, u[t][0]);
        u[t] += gains->K[t] * (x[t] - x_ref[t]);
      }
      u[t] = u[t].cwiseMax(lo_).cwiseMin(hi_);  // the feedback term may push outside
      cost += runningCost(x[t], u[t]);
      data_->ctrl[0] = u[t][0];
      mj_step(model_.get(), data_.get());
    }
    x[kHorizon] << data_->qpos[0], data_->qvel[0];
    return cost + terminalCost(x[kHorizon]);
  }

  // Dynamics by finite differences at each (x_t, u_t), cost derivatives in closed form.
  void linearise(const std::vector<VectorXd>& x, const std::vector<VectorXd>& u, LqApproximation& lq) {
    RowMatrix A(2, 2), B(2, 1);
    for (int t = 0; t < kHorizon; ++t) {
      mj_resetData(model_.get(), data_.get());
      data_->qpos[0] = x[t][0];
      data_->qvel[0] = x[t][1];
      data_->ctrl[0] = u[t][0];
      mjd_transitionFD(model_.get(), data_.get(), 1e-6, 1, A.data(), B.data(), nullptr, nullptr);
      lq.A[t] = A;
      lq.B[t] = B;
      lq.lx[t].setZero();
      lq.lxx[t].setZero();
      lq.lu[t] = kControlWeight * u[t];
      lq.luu[t] = MatrixXd::Constant(1, 1, kControlWeight);
      lq.lux[t].setZero();
    }
    const VectorXd& xT = x[kHorizon];
    lq.lx[kHorizon] << kTerminalAngle * (xT[0] - kPi), kTerminalVelocity * xT[1];
    lq.lxx[kHorizon] << kTerminalAngle, 0, 0, kTerminalVelocity;
  }

  double min_feedforward_ = 0, max_feedforward_ = 0;  // u_ref + alpha k over every rollout

 private:
  ModelPtr model_;
  DataPtr data_;
  VectorXd lo_, hi_;
};

TEST(IlqrMujoco, PendulumSwingupConvergesWithinTheTorqueLimit) {
  Swingup problem;
  std::vector<VectorXd> x(kHorizon + 1, VectorXd::Zero(2)), u(kHorizon, VectorXd::Zero(1));
  std::vector<VectorXd> x_try = x, u_try = u;
  double cost = problem.rollout(x, u, nullptr, 0, x, u);
  const double initial_cost = cost;

  LqApproximation lq(2, 1, kHorizon);
  BackwardPass pass(2, 1, kHorizon);
  FeedbackGains gains;
  gains.resize(2, 1, kHorizon);
  RegularizationSchedule regularization;
  std::vector<double> accepted_costs = {cost};
  bool converged = false;
  for (int iteration = 0; iteration < 300 && !converged; ++iteration) {
    problem.linearise(x, u, lq);
    BackwardPassResult backward;
    while (!(backward = pass.run(lq, u, problem.lo(), problem.hi(), regularization.mu, gains)).ok) {
      regularization.increase();
      ASSERT_FALSE(regularization.exhausted()) << "iteration " << iteration;
    }
    const LineSearchResult step = backtrackingLineSearch(
        [&](double alpha) { return problem.rollout(x, u, &gains, alpha, x_try, u_try); }, cost, backward.dV);
    if (!step.accepted) {
      regularization.increase();
      ASSERT_FALSE(regularization.exhausted()) << "no progress at iteration " << iteration;
      continue;
    }
    // The last rollout is the accepted one only if it was the last tried; replay to be sure.
    const double new_cost = problem.rollout(x, u, &gains, step.alpha, x_try, u_try);
    EXPECT_EQ(new_cost, step.cost);
    EXPECT_LT(new_cost, cost) << "iteration " << iteration;  // monotone decrease
    converged = cost - new_cost < 1e-9 * cost;
    cost = new_cost;
    x.swap(x_try);
    u.swap(u_try);
    accepted_costs.push_back(cost);
    regularization.decrease();
  }
  EXPECT_TRUE(converged) << "cost " << cost << " after " << accepted_costs.size() << " accepted steps";
  // Upright and nearly at rest at the end of the horizon (from 3.14 rad away at rest).
  const VectorXd& xT = x[kHorizon];
  EXPECT_LT(std::abs(xT[0] - kPi), 0.05) << "final angle " << xT[0];
  EXPECT_LT(std::abs(xT[1]), 0.3) << "final velocity " << xT[1];
  EXPECT_LT(cost, 0.01 * initial_cost);
  // The limits were used (it cannot lift the rod otherwise) and never exceeded.
  EXPECT_GE(problem.min_feedforward_, -0.7 - 1e-12);
  EXPECT_LE(problem.max_feedforward_, 0.7 + 1e-12);
  int on_limit = 0;
  for (const auto& ut : u) on_limit += std::abs(ut[0]) > 0.7 - 1e-9;
  EXPECT_GT(on_limit, 30);
  std::printf("swing-up: %zu accepted iterations, cost %.4g -> %.4g, final angle error %.2e rad, velocity %.2e "
              "rad/s, %d of %d controls on a limit\n",
              accepted_costs.size() - 1, initial_cost, cost, xT[0] - kPi, xT[1], on_limit, kHorizon);
  for (size_t i = 1; i < accepted_costs.size(); ++i) EXPECT_LT(accepted_costs[i], accepted_costs[i - 1]);
}

}  // namespace
