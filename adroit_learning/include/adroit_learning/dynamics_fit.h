// Fitting time-varying linear-Gaussian dynamics from a few rollouts (thesis 8.2.1; Levine &
// Abbeel 2014): a Gaussian mixture model over (x_t, u_t, x_{t+1}) of the recent iterations'
// samples serves as a normal-inverse-Wishart prior for a per-step Gaussian fit of the current
// samples, which is then conditioned into x_{t+1} ~ N(Fx x + Fu u + f, Sigma). With N = 5
// samples in a ~100-dimensional state the per-step data alone is rank-deficient; the prior
// supplies the missing directions.
#pragma once

#include <adroit_learning/kl_update.h>

#include <Eigen/Dense>
#include <cstdint>
#include <vector>

namespace adroit {

// One rollout: x is nx x (T + 1) (column t = x_t), u is nu x T.
struct Rollout {
  Eigen::MatrixXd x, u;
};

// The (x_t, u_t, x_{t+1}) points of rollouts, one column each (dimension 2 nx + nu).
Eigen::MatrixXd transitionPoints(const std::vector<Rollout>& rollouts);

struct GmmSettings {
  int clusters = 4;
  int max_iterations = 100;
  double tolerance = 1e-7;        // stop when the objective gains less than this per point
  double regularization = 1e-6;   // lambda: covariance = (scatter + lambda I) / weight sum
  std::uint64_t seed = 1;         // start r uses seed + r
  int restarts = 3;               // EM from this many starts; the best objective is kept
  ThreadPool* pool = nullptr;     // when set: the clusters' E- and M-steps on its workers
};

// Gaussian mixture with full covariances, fitted by EM. The covariance update with the
// diagonal regulariser is the exact M-step of the penalised log-likelihood
//   sum_i log sum_k w_k N(z_i; mu_k, S_k) - 0.5 lambda sum_k tr(S_k^-1),
// so EM never decreases that objective (fit() can return the history of the kept start).
// Start: k-means++ seeds, a hard nearest-seed assignment, one M-step.
class Gmm {
 public:
  // points: one column per point. Throws std::invalid_argument for no points or clusters < 1.
  void fit(const Eigen::MatrixXd& points, const GmmSettings& settings = {},
           std::vector<double>* objective_history = nullptr);

  int clusters() const { return static_cast<int>(weights.size()); }
  // log p(z) of each column of points (log-sum-exp over the clusters).
  Eigen::VectorXd logDensity(const Eigen::MatrixXd& points) const;
  // Responsibilities (clusters x points): p(k | z), columns sum to 1.
  Eigen::MatrixXd responsibilities(const Eigen::MatrixXd& points) const;
  double penalisedLogLikelihood(const Eigen::MatrixXd& points, double regularization) const;

  std::vector<double> weights;
  std::vector<Eigen::VectorXd> means;
  std::vector<Eigen::MatrixXd> covariances;

 private:
  double fitOnce(const Eigen::MatrixXd& points, const GmmSettings& settings, std::uint64_t seed,
                 std::vector<double>& history);
  // log w_k + log N(z; mu_k, S_k) for every cluster and point (clusters x points).
  Eigen::MatrixXd logJoint(const Eigen::MatrixXd& points) const;
};

struct DynamicsFitSettings {
  double prior_strength = 1.0;    // n0 = m: pseudo-samples of the prior (mean and covariance)
  double regularization = 1e-6;   // added to the (x, u) covariance before conditioning
  ThreadPool* pool = nullptr;     // when set: the steps on its workers
};

// Per-step fit of x_{t+1} | x_t, u_t. prior == nullptr: the samples' own Gaussian (needs many
// samples). With a prior, step t's prior is the GMM's moment-matched Gaussian, weighted by the
// mean responsibilities of step t's points: mu0, Phi = n0 * Sigma0, and the posterior joint
//   mu = (m mu0 + N mean) / (m + N),
//   S  = (Phi + N cov + N m / (N + m) (mean - mu0)(mean - mu0)') / (N + n0).
// x0_mean / x0_cov are the samples' initial-state mean and (diagonal-regularised) covariance.
LgDynamics fitDynamics(const std::vector<Rollout>& rollouts, const Gmm* prior,
                       const DynamicsFitSettings& settings = {});

}  // namespace adroit
