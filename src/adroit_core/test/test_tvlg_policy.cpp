// TvlgPolicy: linear interpolation between knots, clamping to the control box, feedback
// scaling, and the time shift that warm-starts the next MPC solve.
#include <gtest/gtest.h>

#include <stdexcept>

#include "adroit_core/tvlg_policy.h"

namespace {

using adroit::TvlgPolicy;
using Eigen::MatrixXd;
using Eigen::VectorXd;

// Knot k holds u = (k, -k), K = (k + 1) * ones, x = (k, 2k, 3k): easy to check by hand.
TvlgPolicy makePolicy(int knots) {
  TvlgPolicy p(3, 3, 2, knots);
  p.t0 = 1.0;
  p.dt = 0.1;
  for (int k = 0; k < knots; ++k) {
    p.u[k] << k, -k;
    p.K[k] = MatrixXd::Constant(2, 3, k + 1.0);
    p.x[k] << k, 2.0 * k, 3.0 * k;
  }
  return p;
}

TEST(TvlgPolicy, MidwayBetweenKnotsIsTheAverage) {
  const TvlgPolicy p = makePolicy(5);
  const VectorXd dx = (VectorXd(3) << 0.5, -1.0, 2.0).finished();
  VectorXd u(2), x(3);
  for (int k = 0; k + 1 < 5; ++k) {
    const double t = p.t0 + (k + 0.5) * p.dt;
    p.action(t, dx, u);
    const VectorXd at_k = p.u[k] + p.K[k] * dx, at_next = p.u[k + 1] + p.K[k + 1] * dx;
    EXPECT_LT((u - 0.5 * (at_k + at_next)).norm(), 1e-12) << "k " << k;
    p.nominalState(t, x);
    EXPECT_LT((x - 0.5 * (p.x[k] + p.x[k + 1])).norm(), 1e-12);
  }
  // On a knot: exactly that knot's law; a quarter of the way: 3:1 weights.
  p.action(p.t0 + 2 * p.dt, VectorXd::Zero(3), u);
  EXPECT_LT((u - p.u[2]).norm(), 1e-12);
  p.action(p.t0 + 2.25 * p.dt, VectorXd::Zero(3), u);
  EXPECT_LT((u - (0.75 * p.u[2] + 0.25 * p.u[3])).norm(), 1e-12);
}

TEST(TvlgPolicy, TimesOutsideTheKnotsHoldTheEnds) {
  const TvlgPolicy p = makePolicy(4);
  VectorXd u(2);
  p.action(p.t0 - 5.0, VectorXd::Zero(3), u);
  EXPECT_EQ(u, p.u[0]);
  p.action(p.t0 + 50.0, VectorXd::Zero(3), u);
  EXPECT_EQ(u, p.u[3]);
  int k;
  double w;
  p.locate(p.t0 + 3 * p.dt, k, w);
  EXPECT_EQ(k, 2);
  EXPECT_EQ(w, 1.0);
}

TEST(TvlgPolicy, ClampsToTheControlBoxAndScalesTheFeedback) {
  TvlgPolicy p = makePolicy(3);
  const VectorXd dx = VectorXd::Constant(3, 0.1);  // K dx = 0.3 (k + 1) per control
  VectorXd u(2);
  p.action(p.t0 + p.dt, dx, u, 0.5);  // knot 1: u = (1, -1) + 0.5 * 0.6
  EXPECT_NEAR(u[0], 1.3, 1e-12);
  EXPECT_NEAR(u[1], -0.7, 1e-12);
  p.action(p.t0 + p.dt, dx, u, 0.0);
  EXPECT_LT((u - p.u[1]).norm(), 1e-12);
  p.u_min = VectorXd::Constant(2, -0.5);
  p.u_max = VectorXd::Constant(2, 1.1);
  p.action(p.t0 + p.dt, dx, u, 0.5);
  EXPECT_EQ(u[0], 1.1);
  EXPECT_EQ(u[1], -0.5);
}

TEST(TvlgPolicy, ShiftToDropsPastKnotsAndRepeatsTheLast) {
  TvlgPolicy p = makePolicy(5);
  p.covariance.assign(5, MatrixXd::Identity(2, 2));
  for (int k = 0; k < 5; ++k) p.covariance[k] *= k;
  p.shiftTo(p.t0 + 2.5 * p.dt);  // starts at knot 2 (at or before t)
  EXPECT_NEAR(p.t0, 1.2, 1e-12);
  const int expected[5] = {2, 3, 4, 4, 4};
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(p.u[k][0], expected[k]) << "k " << k;
    EXPECT_EQ(p.x[k][2], 3.0 * expected[k]);
    EXPECT_EQ(p.K[k](0, 0), expected[k] + 1.0);
    EXPECT_EQ(p.covariance[k](1, 1), expected[k]);
  }
  // The shifted policy gives the same command as before at any time it still covers.
  const TvlgPolicy original = makePolicy(5);
  VectorXd a(2), b(2);
  const VectorXd dx = VectorXd::Constant(3, 0.2);
  original.action(1.33, dx, a);
  p.shiftTo(1.2);  // already there: unchanged
  p.action(1.33, dx, b);
  EXPECT_LT((a - b).norm(), 1e-12);
  // Landing exactly on a computed knot time drops the knots before it, despite rounding.
  TvlgPolicy q = makePolicy(5);
  q.shiftTo(q.t0 + 3 * q.dt);
  EXPECT_EQ(q.u[0][0], 3.0);
  // Past the end: every knot is the last one.
  q.shiftTo(100.0);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(q.u[k][0], 4.0);
}

TEST(TvlgPolicy, BadInputThrows) {
  const TvlgPolicy p = makePolicy(3);
  VectorXd u(2), wrong(3);
  EXPECT_THROW(p.action(1.0, VectorXd::Zero(2), u), std::invalid_argument);
  EXPECT_THROW(p.action(1.0, VectorXd::Zero(3), wrong), std::invalid_argument);
  EXPECT_THROW(p.nominalState(1.0, u), std::invalid_argument);
  EXPECT_THROW(p.action(std::nan(""), VectorXd::Zero(3), u), std::invalid_argument);
  EXPECT_THROW(TvlgPolicy(3, 3, 0, 4), std::invalid_argument);
  EXPECT_THROW(TvlgPolicy().action(0.0, VectorXd::Zero(3), u), std::logic_error);
}

}  // namespace
