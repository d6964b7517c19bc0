// LgController and the smoothed exploration noise: actions have the declared mean and
// covariance; the smoothed noise keeps unit variance at every step (ends included) and has
// the lag-1 autocorrelation of a Gaussian kernel of that width.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "adroit_learning/lg_controller.h"

using adroit::LgController;
using adroit::NormalNoise;
using Eigen::MatrixXd;
using Eigen::VectorXd;

TEST(LgController, InitialControllerHasTheGivenMeanAndDiagonalCovariance) {
  const VectorXd u0 = (VectorXd(2) << 0.5, -1.0).finished();
  const VectorXd var = (VectorXd(2) << 0.04, 0.25).finished();
  const LgController c = LgController::initial(3, 10, u0, var);
  ASSERT_EQ(c.horizon(), 10);
  for (int t = 0; t < 10; ++t) {
    EXPECT_TRUE(c.k[t].isApprox(u0));
    EXPECT_EQ(c.K[t].norm(), 0.0);
    EXPECT_TRUE(c.covariance(t).isApprox(MatrixXd(var.asDiagonal())));
    EXPECT_NEAR(c.choleskyFactor(t)(1, 1), 0.5, 1e-15);
  }
  EXPECT_THROW(LgController::initial(3, 10, u0, -var), std::invalid_argument);
}

TEST(LgController, ActionsHaveMeanKxPlusKAndCovarianceC) {
  LgController c(2, 2, 3);
  c.K[1] << 1, 2, -1, 0.5;
  c.k[1] << 0.3, -0.2;
  const MatrixXd C = (MatrixXd(2, 2) << 0.5, 0.3, 0.3, 0.4).finished();
  c.setCovariance(1, C);
  const VectorXd x = (VectorXd(2) << 0.7, -1.1).finished();
  const VectorXd mean = c.K[1] * x + c.k[1];

  VectorXd u(2);
  c.action(1, x, VectorXd::Zero(2), u);
  EXPECT_TRUE(u.isApprox(mean));

  NormalNoise rng(3);
  const int n = 200000;
  VectorXd sum = VectorXd::Zero(2);
  MatrixXd sq = MatrixXd::Zero(2, 2);
  VectorXd e(2);
  for (int i = 0; i < n; ++i) {
    e << rng(), rng();
    c.action(1, x, e, u);
    sum += u - mean;
    sq += (u - mean) * (u - mean).transpose();
  }
  EXPECT_LT((sum / n).norm(), 0.01);
  EXPECT_LT((sq / n - C).cwiseAbs().maxCoeff(), 0.01);
}

TEST(LgController, RejectsCovariancesThatAreNotPositiveDefinite) {
  LgController c(2, 2, 1);
  EXPECT_THROW(c.setCovariance(0, (MatrixXd(2, 2) << 1, 2, 2, 1).finished()), std::invalid_argument);
  EXPECT_THROW(c.setCovariance(0, (MatrixXd(2, 2) << 1, 0.5, 0, 1).finished()), std::invalid_argument);
  EXPECT_THROW(c.setCovariance(0, MatrixXd::Identity(3, 3)), std::invalid_argument);
  EXPECT_TRUE(c.covariance(0).isIdentity());  // unchanged by the rejected ones
}

// Per-step variance and interior lag-1 autocorrelation over many rollouts.
void noiseStatistics(double width, int horizon, VectorXd& variance, double& lag1) {
  NormalNoise rng(11);
  const int rollouts = 3000, nu = 2;
  variance = VectorXd::Zero(horizon);
  double cross = 0, sq = 0;
  const int margin = static_cast<int>(std::ceil(4 * width)) + 1;
  for (int r = 0; r < rollouts; ++r) {
    const MatrixXd e = adroit::smoothedNoise(rng, nu, horizon, width);
    EXPECT_EQ(e.rows(), nu);
    EXPECT_EQ(e.cols(), horizon);
    for (int t = 0; t < horizon; ++t) variance[t] += e.col(t).squaredNorm() / (rollouts * nu);
    for (int t = margin; t + 1 < horizon - margin; ++t) {
      cross += e.col(t).dot(e.col(t + 1));
      sq += e.col(t).squaredNorm();
    }
  }
  lag1 = cross / sq;
}

TEST(SmoothedNoise, KeepsUnitVarianceAtEveryStepAndTheKernelsAutocorrelation) {
  const int horizon = 60;
  for (double width : {0.0, 1.0, 2.0, 4.0}) {
    VectorXd variance;
    double lag1 = 0;
    noiseStatistics(width, horizon, variance, lag1);
    // 6000 samples per step: standard error of the variance ~0.018.
    for (int t = 0; t < horizon; ++t) EXPECT_NEAR(variance[t], 1.0, 0.08) << "width " << width << " t " << t;
    // Continuous Gaussian kernel of std s: autocorrelation exp(-lag^2 / (4 s^2)); 0 for white noise.
    const double expected = width > 0 ? std::exp(-1.0 / (4 * width * width)) : 0.0;
    EXPECT_NEAR(lag1, expected, 0.02) << "width " << width;
  }
}

TEST(SmoothedNoise, IsReproducibleFromTheSeed) {
  NormalNoise a(5), b(5);
  EXPECT_TRUE(adroit::smoothedNoise(a, 3, 20, 2.0).isApprox(adroit::smoothedNoise(b, 3, 20, 2.0)));
}
