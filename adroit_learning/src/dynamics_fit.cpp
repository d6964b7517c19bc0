#include "adroit_learning/dynamics_fit.h"

#include <adroit_core/normal_noise.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace adroit {

namespace {

constexpr double kLog2Pi = 1.8378770664093453;

// Sample mean and maximum-likelihood covariance of the columns.
void moments(const Eigen::MatrixXd& points, Eigen::VectorXd& mean, Eigen::MatrixXd& cov) {
  const double n = static_cast<double>(points.cols());
  mean = points.rowwise().mean();
  const Eigen::MatrixXd centred = points.colwise() - mean;
  cov.noalias() = centred * centred.transpose() / n;
}

}  // namespace

Eigen::MatrixXd transitionPoints(const std::vector<Rollout>& rollouts) {
  if (rollouts.empty()) throw std::invalid_argument("transitionPoints: no rollouts");
  const Eigen::Index nx = rollouts[0].x.rows(), nu = rollouts[0].u.rows();
  Eigen::Index count = 0;
  for (const Rollout& r : rollouts) {
    if (r.x.rows() != nx || r.u.rows() != nu || r.x.cols() != r.u.cols() + 1)
      throw std::invalid_argument("transitionPoints: rollouts must all be nx x (T+1) and nu x T");
    count += r.u.cols();
  }
  Eigen::MatrixXd z(2 * nx + nu, count);
  Eigen::Index c = 0;
  for (const Rollout& r : rollouts)
    for (Eigen::Index t = 0; t < r.u.cols(); ++t, ++c) z.col(c) << r.x.col(t), r.u.col(t), r.x.col(t + 1);
  return z;
}

namespace {

// Cholesky factors of a mixture's covariances and their log-determinants, computed once and
// shared by every evaluation that needs them (EM's E-step and objective, the per-step prior
// of fitDynamics). `pool`: the clusters on its workers.
struct GmmFactors {
  std::vector<Eigen::LLT<Eigen::MatrixXd>> llt;
  std::vector<double> log_det;

  void compute(const std::vector<Eigen::MatrixXd>& covariances, ThreadPool* pool) {
    llt.resize(covariances.size());
    log_det.resize(covariances.size());
    forEachIndex(pool, covariances.size(), [&](std::size_t k, std::size_t) {
      llt[k].compute(covariances[k]);
      if (llt[k].info() != Eigen::Success) throw std::runtime_error("Gmm: a covariance is not positive definite");
      log_det[k] = 2.0 * llt[k].matrixLLT().diagonal().array().log().sum();
    });
  }
  // sum_k tr(S_k^-1) = sum_k |L_k^-1|_F^2 (summed in cluster order: the same with any pool).
  double traceOfInverses(ThreadPool* pool) const {
    std::vector<double> traces(llt.size());
    forEachIndex(pool, llt.size(), [&](std::size_t k, std::size_t) {
      Eigen::MatrixXd inv = Eigen::MatrixXd::Identity(llt[k].rows(), llt[k].cols());
      llt[k].matrixL().solveInPlace(inv);
      traces[k] = inv.squaredNorm();
    });
    double total = 0;
    for (double t : traces) total += t;
    return total;
  }
};

// Responsibilities below exp(-230) ~ 1e-100 count as exactly 0: they change no sum at double
// precision, but in high dimensions (log-likelihood gaps of thousands between clusters) the
// products they enter underflow into subnormal numbers, which x86 processes ~100x slower (the
// M-step's rank update and fitDynamics' moment matching took 10-20x longer).
constexpr double kLogNegligible = -230.0;

// log w_k + log N(z; mu_k, S_k) (clusters x points) into `out`; y: one d x n scratch matrix
// per worker of `pool` (clusters on its workers).
//
// With `owner` (a cluster per point, e.g. the last E-step's most responsible one), entries
// that are negligible next to the owner's -- log-joint below the owner's + kLogNegligible, so
// responsibility 0 -- come out as -inf without being finished: the whitened vector
// L_k^-1 (z - mu_k) is computed by blocks of rows (forward substitution), its squared norm so
// far only grows, and a point leaves cluster k's solve as soon as that partial norm rules it
// out. With the nearly hard responsibilities of high dimensions most points leave after the
// first block, and the E-step costs about one full solve per point instead of one per cluster.
void logJointFactored(const Gmm& gmm, const GmmFactors& factors, const Eigen::MatrixXd& points, Eigen::MatrixXd& out,
                      std::vector<Eigen::MatrixXd>& y, ThreadPool* pool, const Eigen::VectorXi* owner = nullptr) {
  const Eigen::Index d = points.rows(), n = points.cols();
  const int K = gmm.clusters();
  out.resize(K, n);
  const auto constant = [&](std::size_t k) {  // log w_k - 0.5 (log det S_k + d log 2 pi)
    const double log_w = gmm.weights[k] > 0 ? std::log(gmm.weights[k]) : -std::numeric_limits<double>::infinity();
    return log_w - 0.5 * (factors.log_det[k] + static_cast<double>(d) * kLog2Pi);
  };
  if (!owner) {
    forEachIndex(pool, K, [&](std::size_t k, std::size_t worker) {
      Eigen::MatrixXd& yk = y[worker];
      yk = points.colwise() - gmm.means[k];
      factors.llt[k].matrixL().solveInPlace(yk);
      out.row(k) = (constant(k) - 0.5 * yk.colwise().squaredNorm().array()).matrix();
    });
    return;
  }
  // The owners' entries in full first: they set each point's threshold.
  forEachIndex(pool, K, [&](std::size_t k, std::size_t worker) {
    Eigen::MatrixXd& yk = y[worker];
    Eigen::Index m = 0;
    for (Eigen::Index i = 0; i < n; ++i)
      if ((*owner)[i] == static_cast<int>(k)) yk.col(m++) = points.col(i) - gmm.means[k];
    if (m == 0) return;
    auto block = yk.leftCols(m);
    factors.llt[k].matrixL().solveInPlace(block);
    const double c = constant(k);
    m = 0;
    for (Eigen::Index i = 0; i < n; ++i)
      if ((*owner)[i] == static_cast<int>(k)) out(k, i) = c - 0.5 * yk.col(m++).squaredNorm();
  });
  constexpr Eigen::Index kRows = 32;  // rows per block of the forward substitution
  forEachIndex(pool, K, [&](std::size_t k, std::size_t worker) {
    Eigen::MatrixXd& yk = y[worker];
    const Eigen::MatrixXd& L = factors.llt[k].matrixLLT();  // lower triangle = L
    const double c = constant(k);
    std::vector<Eigen::Index> active;  // points still in this cluster's solve, in yk's column order
    for (Eigen::Index i = 0; i < n; ++i)
      if ((*owner)[i] != static_cast<int>(k)) {
        yk.col(static_cast<Eigen::Index>(active.size())) = points.col(i) - gmm.means[k];
        active.push_back(i);
      }
    Eigen::VectorXd partial = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(active.size()));
    for (Eigen::Index r0 = 0; r0 < d && !active.empty(); r0 += kRows) {
      const Eigen::Index h = std::min(kRows, d - r0), m = static_cast<Eigen::Index>(active.size());
      auto rows = yk.block(r0, 0, h, m);
      if (r0 > 0) rows.noalias() -= L.block(r0, 0, h, r0) * yk.topLeftCorner(r0, m);
      L.block(r0, r0, h, h).triangularView<Eigen::Lower>().solveInPlace(rows);
      partial.head(m) += rows.colwise().squaredNorm().transpose();
      // Keep the points whose log-joint can still reach their owner's + kLogNegligible.
      Eigen::Index kept = 0;
      for (Eigen::Index j = 0; j < m; ++j) {
        const Eigen::Index i = active[j];
        if (c - 0.5 * partial[j] < out((*owner)[i], i) + kLogNegligible) {
          out(k, i) = -std::numeric_limits<double>::infinity();
          continue;
        }
        if (kept != j) {
          yk.col(kept) = yk.col(j);
          partial[kept] = partial[j];
          active[kept] = i;
        }
        ++kept;
      }
      active.resize(kept);
    }
    for (std::size_t j = 0; j < active.size(); ++j) out(k, active[j]) = c - 0.5 * partial[j];
  });
}

// Column-wise log-sum-exp of the log-joint lj (the log density of each point), with lj turned
// into the responsibilities in place.
Eigen::VectorXd normaliseColumns(Eigen::MatrixXd& lj) {
  Eigen::VectorXd log_density(lj.cols());
  for (Eigen::Index i = 0; i < lj.cols(); ++i) {
    const double m = lj.col(i).maxCoeff();
    lj.col(i) = (lj.col(i).array() - m > kLogNegligible).select((lj.col(i).array() - m).exp(), 0.0).matrix();
    const double sum = lj.col(i).sum();
    log_density[i] = m + std::log(sum);
    lj.col(i) /= sum;
  }
  return log_density;
}

}  // namespace

Eigen::MatrixXd Gmm::logJoint(const Eigen::MatrixXd& points) const {
  GmmFactors factors;
  factors.compute(covariances, nullptr);
  Eigen::MatrixXd out;
  std::vector<Eigen::MatrixXd> y(1);
  logJointFactored(*this, factors, points, out, y, nullptr);
  return out;
}

Eigen::VectorXd Gmm::logDensity(const Eigen::MatrixXd& points) const {
  Eigen::MatrixXd lj = logJoint(points);
  return normaliseColumns(lj);
}

Eigen::MatrixXd Gmm::responsibilities(const Eigen::MatrixXd& points) const {
  Eigen::MatrixXd lj = logJoint(points);
  normaliseColumns(lj);
  return lj;
}

double Gmm::penalisedLogLikelihood(const Eigen::MatrixXd& points, double regularization) const {
  double penalty = 0;
  for (const Eigen::MatrixXd& S : covariances)
    penalty += S.llt().solve(Eigen::MatrixXd::Identity(S.rows(), S.cols())).trace();
  return logDensity(points).sum() - 0.5 * regularization * penalty;
}

void Gmm::fit(const Eigen::MatrixXd& points, const GmmSettings& s, std::vector<double>* history) {
  if (points.cols() == 0 || points.rows() == 0) throw std::invalid_argument("Gmm::fit: no points");
  if (s.clusters < 1 || s.restarts < 1) throw std::invalid_argument("Gmm::fit: clusters and restarts must be >= 1");
  if (!(s.regularization > 0)) throw std::invalid_argument("Gmm::fit: regularization must be positive");
  if (!points.allFinite()) throw std::invalid_argument("Gmm::fit: points must be finite");
  // EM finds a local optimum of its start: keep the best of several starts.
  Gmm best;
  std::vector<double> best_history, run_history;
  double best_objective = -std::numeric_limits<double>::infinity();
  for (int r = 0; r < s.restarts; ++r) {
    const double objective = fitOnce(points, s, s.seed + static_cast<std::uint64_t>(r), run_history);
    if (r == 0 || objective > best_objective) {
      best_objective = objective;
      best = *this;
      best_history.swap(run_history);
    }
  }
  *this = std::move(best);
  if (history) *history = std::move(best_history);
}

double Gmm::fitOnce(const Eigen::MatrixXd& points, const GmmSettings& s, std::uint64_t seed,
                    std::vector<double>& history) {
  const Eigen::Index n = points.cols(), d = points.rows();
  const int K = s.clusters;
  // One d x n scratch matrix per worker: the E-step's whitened points, the M-step's scaled ones.
  std::vector<Eigen::MatrixXd> scratch(workerCount(s.pool), Eigen::MatrixXd(d, n));

  // M-step for responsibilities r (clusters x points), the clusters on the pool's workers.
  const auto maximise = [&](const Eigen::MatrixXd& r) {
    forEachIndex(s.pool, K, [&](std::size_t k, std::size_t worker) {
      Eigen::MatrixXd& scaled = scratch[worker];
      const double nk = std::max(r.row(k).sum(), 1e-12);
      weights[k] = r.row(k).sum() / static_cast<double>(n);
      means[k] = points * r.row(k).transpose() / nk;
      // Weighted scatter sum_i r_ki (z_i - mu_k)(z_i - mu_k)' as one symmetric rank update
      // of the columns scaled by sqrt(r_ki) (half the work of the general product), over the
      // points with r_ki > 0 only: in high dimensions responsibilities are nearly hard, so
      // that is about 1/K of them.
      Eigen::Index members = 0;
      for (Eigen::Index i = 0; i < n; ++i)
        if (r(k, i) > 0) scaled.col(members++) = std::sqrt(r(k, i)) * (points.col(i) - means[k]);
      Eigen::MatrixXd& S = covariances[k];
      S.setZero();
      S.selfadjointView<Eigen::Lower>().rankUpdate(scaled.leftCols(members));
      S.diagonal().array() += s.regularization;
      S /= nk;
      S.triangularView<Eigen::StrictlyUpper>() = S.transpose();
    });
  };

  // Start: seeds by D^2 sampling (k-means++: each next seed is a point drawn with probability
  // proportional to its squared distance to the nearest seed so far), every point assigned to
  // its nearest seed, and one M-step on that hard assignment. (Starting every cluster at the
  // overall covariance instead lets EM drift into merged clusters.)
  weights.assign(K, 1.0 / K);
  means.assign(K, Eigen::VectorXd::Zero(d));
  covariances.assign(K, Eigen::MatrixXd::Identity(d, d));
  NormalNoise rng(seed);
  Eigen::VectorXd nearest = Eigen::VectorXd::Constant(n, std::numeric_limits<double>::infinity());
  Eigen::VectorXi owner = Eigen::VectorXi::Zero(n);
  Eigen::Index pick = std::min<Eigen::Index>(static_cast<Eigen::Index>(rng.uniform() * n), n - 1);
  for (int k = 0; k < K; ++k) {
    means[k] = points.col(pick);
    const Eigen::VectorXd dist = (points.colwise() - means[k]).colwise().squaredNorm().transpose();
    for (Eigen::Index i = 0; i < n; ++i)
      if (dist[i] < nearest[i]) {
        nearest[i] = dist[i];
        owner[i] = k;
      }
    const double total = nearest.sum();
    if (!(total > 0)) continue;  // fewer distinct points than clusters: keep the last pick
    double target = rng.uniform() * total;
    for (pick = 0; pick < n - 1 && target >= nearest[pick]; ++pick) target -= nearest[pick];
  }
  Eigen::MatrixXd hard = Eigen::MatrixXd::Zero(K, n);
  for (Eigen::Index i = 0; i < n; ++i) hard(owner[i], i) = 1.0;
  maximise(hard);

  // One factorisation and one log-joint per iteration: the objective of the current
  // parameters and the next E-step's responsibilities come from the same evaluation. The
  // E-step prunes against `owner`: the hard start's assignment, then each point's most
  // responsible cluster of the last E-step.
  GmmFactors factors;
  Eigen::MatrixXd lj;
  const auto objective = [&]() {
    factors.compute(covariances, s.pool);
    logJointFactored(*this, factors, points, lj, scratch, s.pool, &owner);
    return normaliseColumns(lj).sum() - 0.5 * s.regularization * factors.traceOfInverses(s.pool);
  };
  history.assign(1, objective());
  for (int it = 0; it < s.max_iterations; ++it) {
    maximise(lj);  // lj holds the responsibilities of the current parameters
    for (Eigen::Index i = 0, best = 0; i < n; ++i) {
      lj.col(i).maxCoeff(&best);
      owner[i] = static_cast<int>(best);
    }
    history.push_back(objective());
    if (history.back() - history[history.size() - 2] < s.tolerance * static_cast<double>(n)) break;
  }
  return history.back();
}

LgDynamics fitDynamics(const std::vector<Rollout>& rollouts, const Gmm* prior, const DynamicsFitSettings& s) {
  if (rollouts.empty()) throw std::invalid_argument("fitDynamics: no rollouts");
  const int nx = static_cast<int>(rollouts[0].x.rows()), nu = static_cast<int>(rollouts[0].u.rows());
  const int T = static_cast<int>(rollouts[0].u.cols());
  const int nxu = nx + nu, d = 2 * nx + nu;
  for (const Rollout& r : rollouts)
    if (r.x.rows() != nx || r.u.rows() != nu || r.u.cols() != T || r.x.cols() != T + 1 || !r.x.allFinite() ||
        !r.u.allFinite())
      throw std::invalid_argument("fitDynamics: rollouts must be finite, nx x (T+1) and nu x T, all the same");
  if (prior && (prior->clusters() == 0 || prior->means[0].size() != d))
    throw std::invalid_argument("fitDynamics: the prior is not over (x, u, x') of dimension " + std::to_string(d));
  const double N = static_cast<double>(rollouts.size());
  const double n0 = s.prior_strength, m = s.prior_strength;

  LgDynamics dyn(nx, nu, T);
  Eigen::MatrixXd x0(nx, rollouts.size());
  for (size_t i = 0; i < rollouts.size(); ++i) x0.col(i) = rollouts[i].x.col(0);
  moments(x0, dyn.x0_mean, dyn.x0_cov);
  dyn.x0_cov.diagonal().array() += s.regularization;

  GmmFactors prior_factors;  // the prior's Cholesky factors, once for all steps
  if (prior) prior_factors.compute(prior->covariances, s.pool);
  // The steps are independent: on the pool's workers, each with its own scratch.
  struct Scratch {
    std::vector<Eigen::MatrixXd> whitened{1};
    Eigen::MatrixXd lj, z, S, S0, Szz, Fxu_t, sigma;
    Eigen::VectorXd mu, mu0, diff;
    Eigen::LLT<Eigen::MatrixXd> llt;
  };
  std::vector<Scratch> scratch(workerCount(s.pool));
  forEachIndex(s.pool, T, [&](std::size_t step, std::size_t worker) {
    const int t = static_cast<int>(step);
    Scratch& w = scratch[worker];
    w.z.resize(d, rollouts.size());
    for (size_t i = 0; i < rollouts.size(); ++i)
      w.z.col(i) << rollouts[i].x.col(t), rollouts[i].u.col(t), rollouts[i].x.col(t + 1);
    moments(w.z, w.mu, w.S);
    if (prior) {
      // Step t's prior: the mixture moment-matched with the points' mean responsibilities.
      logJointFactored(*prior, prior_factors, w.z, w.lj, w.whitened, nullptr);
      normaliseColumns(w.lj);
      const Eigen::VectorXd weight = w.lj.rowwise().mean();
      w.mu0.setZero(d);
      for (int k = 0; k < prior->clusters(); ++k) w.mu0 += weight[k] * prior->means[k];
      w.S0.setZero(d, d);
      for (int k = 0; k < prior->clusters(); ++k) {
        if (weight[k] == 0) continue;  // usual: the step's points all sit in one cluster
        w.diff = prior->means[k] - w.mu0;
        w.S0.noalias() += weight[k] * prior->covariances[k];
        w.S0.noalias() += (weight[k] * w.diff) * w.diff.transpose();
      }
      w.diff = w.mu - w.mu0;
      w.S = (n0 * w.S0 + N * w.S + (N * m / (N + m)) * w.diff * w.diff.transpose()) / (N + n0);
      w.mu = (m * w.mu0 + N * w.mu) / (m + N);
    }
    // Condition the joint Gaussian on (x, u) through S_zz = L L':  with W = L^-1 S_zx',
    // F' = S_zz^-1 S_zx' = L'^-1 W and Sigma = S_x'x' - S_x'z S_zz^-1 S_zx' = S_x'x' - W'W.
    w.Szz = w.S.topLeftCorner(nxu, nxu);
    w.Szz.diagonal().array() += s.regularization;
    w.llt.compute(w.Szz);
    if (w.llt.info() != Eigen::Success) throw std::runtime_error("fitDynamics: (x, u) covariance not positive definite");
    w.Fxu_t = w.S.bottomLeftCorner(nx, nxu).transpose();
    w.llt.matrixL().solveInPlace(w.Fxu_t);  // W
    w.sigma = w.S.bottomRightCorner(nx, nx);
    w.sigma.selfadjointView<Eigen::Lower>().rankUpdate(w.Fxu_t.transpose(), -1.0);
    w.llt.matrixU().solveInPlace(w.Fxu_t);  // (nxu x nx) = F'
    dyn.Fx[t] = w.Fxu_t.topRows(nx).transpose();
    dyn.Fu[t] = w.Fxu_t.bottomRows(nu).transpose();
    dyn.f[t] = w.mu.tail(nx) - dyn.Fx[t] * w.mu.head(nx) - dyn.Fu[t] * w.mu.segment(nx, nu);
    dyn.Sigma[t] = w.sigma.selfadjointView<Eigen::Lower>();
    dyn.Sigma[t].diagonal().array() += s.regularization;
  });
  return dyn;
}

}  // namespace adroit
