// Dynamics fitting: EM never decreases its (penalised) log-likelihood, also with fewer points
// than dimensions; the per-step fit recovers a known linear-Gaussian system from many
// samples; with N = 5 samples in a 100-dimensional state and the GMM prior it stays finite,
// positive definite and predicts held-out transitions better than the samples alone. A thread
// pool gives the same mixture and fit.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "adroit_learning/dynamics_fit.h"
#include "lq_problems.h"

using namespace adroit;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using test_problems::randn;

namespace {

// A known time-varying linear-Gaussian system driven by random controls.
struct TrueSystem {
  int nx, nu, T;
  std::vector<MatrixXd> A, B, noise_chol;
  std::vector<VectorXd> c;

  // time_invariant: the same matrices at every step (a physical system; what a GMM prior
  // pooled over time can capture).
  TrueSystem(std::mt19937& rng, int nx_, int nu_, int T_, double a_scale, double noise, bool time_invariant)
      : nx(nx_), nu(nu_), T(T_) {
    for (int t = 0; t < T; ++t) {
      if (time_invariant && t > 0) {
        A.push_back(A[0]);
        B.push_back(B[0]);
        c.push_back(c[0]);
        noise_chol.push_back(noise_chol[0]);
        continue;
      }
      A.push_back(0.9 * MatrixXd::Identity(nx, nx) + randn(rng, nx, nx, a_scale));
      B.push_back(randn(rng, nx, nu, 0.5));
      c.push_back(randn(rng, nx, 1, 0.1));
      noise_chol.push_back(noise * (MatrixXd::Identity(nx, nx) + 0.3 * randn(rng, nx, nx, 1.0 / nx))
                                       .triangularView<Eigen::Lower>()
                                       .toDenseMatrix());
    }
  }
  std::vector<Rollout> rollouts(std::mt19937& rng, int count) const {
    std::vector<Rollout> out(count);
    for (Rollout& r : out) {
      r.x.resize(nx, T + 1);
      r.u = randn(rng, nu, T, 1.0);
      r.x.col(0) = randn(rng, nx, 1, 0.5);
      for (int t = 0; t < T; ++t)
        r.x.col(t + 1) = A[t] * r.x.col(t) + B[t] * r.u.col(t) + c[t] + noise_chol[t] * randn(rng, nx, 1, 1.0);
    }
    return out;
  }
};

// Mean squared one-step prediction error of the fitted means on rollouts.
double predictionError(const LgDynamics& d, const std::vector<Rollout>& rollouts) {
  double sum = 0;
  int count = 0;
  for (const Rollout& r : rollouts)
    for (int t = 0; t < d.horizon; ++t, ++count)
      sum += (r.x.col(t + 1) - d.Fx[t] * r.x.col(t) - d.Fu[t] * r.u.col(t) - d.f[t]).squaredNorm();
  return sum / count;
}

}  // namespace

TEST(Gmm, EmNeverDecreasesTheObjective) {
  std::mt19937 rng(1);
  // Three clusters in 4-D, then 30 points in 40-D (rank-deficient scatter).
  MatrixXd a(4, 300);
  for (int i = 0; i < 300; ++i) a.col(i) = randn(rng, 4, 1, 0.3) + VectorXd::Constant(4, 2.0 * (i % 3));
  const MatrixXd b = randn(rng, 40, 30, 1.0);
  for (const MatrixXd* points : std::vector<const MatrixXd*>{&a, &b}) {
    for (int clusters : {1, 3, 5}) {
      Gmm gmm;
      std::vector<double> history;
      GmmSettings settings;
      settings.clusters = clusters;
      settings.regularization = 1e-3;
      gmm.fit(*points, settings, &history);
      ASSERT_GE(history.size(), 2u);
      for (size_t i = 1; i < history.size(); ++i) {
        ASSERT_TRUE(std::isfinite(history[i]));
        EXPECT_GE(history[i], history[i - 1] - 1e-9 * std::abs(history[i - 1]))
            << "clusters " << clusters << " iteration " << i;
      }
      double total = 0;
      for (double w : gmm.weights) total += w;
      EXPECT_NEAR(total, 1.0, 1e-12);
    }
  }
  // The three separated clusters are found: each mean near one of the centres.
  Gmm gmm;
  GmmSettings settings;
  settings.clusters = 3;
  gmm.fit(a, settings);
  for (int k = 0; k < 3; ++k) {
    const double centre = std::round(gmm.means[k].mean() / 2.0) * 2.0;
    EXPECT_LT((gmm.means[k] - VectorXd::Constant(4, centre)).norm(), 0.2) << k << ": " << gmm.means[k].transpose();
    EXPECT_NEAR(gmm.weights[k], 1.0 / 3.0, 0.01) << k;
  }
}

TEST(Gmm, PrunedEStepGivesTheExactObjectiveInHighDimensions) {
  // EM's E-step drops the point-cluster pairs that cannot matter before finishing them. Its
  // objective must stay the unpruned one: on three clusters 3 apart per coordinate in 100-D
  // (gaps of hundreds of nats: most pairs dropped early), and on one Gaussian cloud in 40-D
  // split into overlapping clusters (soft responsibilities: pairs a few nats apart kept).
  std::mt19937 rng(6);
  MatrixXd separated(100, 300);
  for (int i = 0; i < 300; ++i)
    separated.col(i) = randn(rng, 100, 1, 1.0) + VectorXd::Constant(100, 3.0 * (i % 3));
  const MatrixXd overlapping = randn(rng, 40, 400, 1.0);
  for (const MatrixXd* z : std::vector<const MatrixXd*>{&separated, &overlapping}) {
    for (int clusters : {2, 3}) {
      GmmSettings settings;
      settings.clusters = clusters;
      settings.regularization = 1e-3;
      Gmm gmm;
      std::vector<double> history;
      gmm.fit(*z, settings, &history);
      EXPECT_NEAR(history.back(), gmm.penalisedLogLikelihood(*z, settings.regularization),
                  1e-9 * std::abs(history.back()))
          << z->rows() << "-D, " << clusters << " clusters";
      for (size_t i = 1; i < history.size(); ++i)
        EXPECT_GE(history[i], history[i - 1] - 1e-9 * std::abs(history[i - 1])) << clusters << " iteration " << i;
    }
  }
}

TEST(Gmm, NegligibleResponsibilitiesAreZeroNotSubnormal) {
  // Two unit-variance clusters 1440^0.5 apart in 1-D: at z = 0 the far cluster's log
  // responsibility is -720, whose exp is subnormal (x86 computes with those ~100x slower).
  const double far = std::sqrt(1440.0);
  Gmm gmm;
  gmm.weights = {0.5, 0.5};
  gmm.means = {VectorXd::Zero(1), VectorXd::Constant(1, far)};
  gmm.covariances = {MatrixXd::Identity(1, 1), MatrixXd::Identity(1, 1)};
  // At z(1) the first cluster's log responsibility ratio is -100: tiny but kept.
  MatrixXd z(1, 2);
  z << 0.0, 0.5 * far + 100.0 / far;
  const MatrixXd r = gmm.responsibilities(z);
  EXPECT_EQ(r(1, 0), 0.0);
  EXPECT_EQ(r(0, 0), 1.0);
  EXPECT_NEAR(r(0, 1) / std::exp(-100.0), 1.0, 1e-9);
  for (Eigen::Index i = 0; i < r.size(); ++i) EXPECT_NE(std::fpclassify(r(i)), FP_SUBNORMAL) << i;
  // The log density is unchanged: log(0.5 N(0; 0, 1)).
  EXPECT_NEAR(gmm.logDensity(z)[0], std::log(0.5) - 0.5 * std::log(2 * M_PI), 1e-14);
}

TEST(DynamicsFit, AThreadPoolGivesTheSameGmmAndFit) {
  std::mt19937 rng(5);
  const TrueSystem sys(rng, 20, 4, 10, 0.05, 0.05, false);
  const std::vector<Rollout> past = sys.rollouts(rng, 30), now = sys.rollouts(rng, 5);
  ThreadPool pool(2);
  GmmSettings settings;
  Gmm serial, parallel;
  std::vector<double> serial_history, parallel_history;
  serial.fit(transitionPoints(past), settings, &serial_history);
  settings.pool = &pool;
  parallel.fit(transitionPoints(past), settings, &parallel_history);
  EXPECT_EQ(serial_history, parallel_history);
  EXPECT_EQ(serial.weights, parallel.weights);
  for (int k = 0; k < serial.clusters(); ++k) {
    EXPECT_EQ(serial.means[k], parallel.means[k]) << k;
    EXPECT_EQ(serial.covariances[k], parallel.covariances[k]) << k;
  }
  DynamicsFitSettings fit_settings;
  const LgDynamics a = fitDynamics(now, &serial);
  fit_settings.pool = &pool;
  const LgDynamics b = fitDynamics(now, &serial, fit_settings);
  for (int t = 0; t < sys.T; ++t) {
    EXPECT_EQ(a.Fx[t], b.Fx[t]) << t;
    EXPECT_EQ(a.Fu[t], b.Fu[t]) << t;
    EXPECT_EQ(a.f[t], b.f[t]) << t;
    EXPECT_EQ(a.Sigma[t], b.Sigma[t]) << t;
  }
}

TEST(DynamicsFit, RecoversAKnownSystemFromManySamples) {
  std::mt19937 rng(2);
  const TrueSystem sys(rng, 3, 2, 4, 0.1, 0.05, false);
  const std::vector<Rollout> data = sys.rollouts(rng, 4000);
  Gmm gmm;
  gmm.fit(transitionPoints(data));
  for (const Gmm* prior : std::vector<const Gmm*>{nullptr, &gmm}) {
    const LgDynamics d = fitDynamics(data, prior);
    for (int t = 0; t < sys.T; ++t) {
      EXPECT_LT((d.Fx[t] - sys.A[t]).cwiseAbs().maxCoeff(), 0.02) << t;
      EXPECT_LT((d.Fu[t] - sys.B[t]).cwiseAbs().maxCoeff(), 0.02) << t;
      EXPECT_LT((d.f[t] - sys.c[t]).cwiseAbs().maxCoeff(), 0.02) << t;
      const MatrixXd true_cov = sys.noise_chol[t] * sys.noise_chol[t].transpose();
      // The prior (one pseudo-sample of a GMM pooled over steps with different A_t) adds its
      // own residual covariance / (N + 1): a little more slack with it.
      const double tolerance = prior ? 0.2 : 0.1;
      EXPECT_LT((d.Sigma[t] - true_cov).cwiseAbs().maxCoeff(), tolerance * true_cov.cwiseAbs().maxCoeff()) << t;
    }
  }
}

TEST(DynamicsFit, FiveSamplesInAHundredDimensionsWithThePrior) {
  std::mt19937 rng(3);
  const int nx = 100, nu = 10, T = 8;
  const TrueSystem sys(rng, nx, nu, T, 0.005, 0.02, true);
  const std::vector<Rollout> past = sys.rollouts(rng, 100);  // recent iterations (20 x 5)
  const std::vector<Rollout> now = sys.rollouts(rng, 5);     // N = 5 of this iteration
  const std::vector<Rollout> held_out = sys.rollouts(rng, 10);
  Gmm gmm;
  GmmSettings settings;
  settings.clusters = 2;
  settings.regularization = 1e-4;
  gmm.fit(transitionPoints(past), settings);

  const LgDynamics with_prior = fitDynamics(now, &gmm);
  const LgDynamics alone = fitDynamics(now, nullptr);
  for (int t = 0; t < T; ++t) {
    ASSERT_TRUE(with_prior.Fx[t].allFinite() && with_prior.Fu[t].allFinite() && with_prior.f[t].allFinite()) << t;
    ASSERT_TRUE(with_prior.Sigma[t].allFinite()) << t;
    EXPECT_EQ(with_prior.Sigma[t].llt().info(), Eigen::Success) << t;
  }
  const double e_prior = predictionError(with_prior, held_out);
  const double e_alone = predictionError(alone, held_out);
  const double noise = 0.02 * 0.02 * nx;  // about the irreducible error
  // 5 points per step cannot determine 110 inputs; the prior brings it near the noise floor.
  EXPECT_LT(e_prior, 4 * noise) << "prior " << e_prior << " alone " << e_alone;
  EXPECT_LT(e_prior, 0.01 * e_alone) << "prior " << e_prior << " alone " << e_alone;
  // And the fitted model is usable by the update: the KL step runs on it.
  QuadraticCost cost(nx, nu, T);
  for (int t = 0; t <= T; ++t) {
    cost.cxx[t].setIdentity();
    if (t < T) cost.cuu[t] = 0.1 * MatrixXd::Identity(nu, nu);
  }
  KlUpdate update(nx, nu, T);
  const LgController prev = LgController::initial(nx, T, VectorXd::Zero(nu), VectorXd::Constant(nu, 0.5));
  const KlUpdateResult r = update.update(with_prior, cost, prev, 1.0);
  EXPECT_TRUE(r.converged);
  EXPECT_TRUE(std::isfinite(r.predicted_cost));
  std::cout << "one-step error: with prior " << e_prior << ", samples alone " << e_alone << ", noise ~" << noise
            << "\n";
}
