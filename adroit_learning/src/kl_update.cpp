#include "adroit_learning/kl_update.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace adroit {

namespace {

void checkDims(const char* where, int nx, int nu, int horizon) {
  if (nx <= 0 || nu <= 0 || horizon <= 0)
    throw std::invalid_argument(std::string(where) + ": nx, nu and horizon must be positive");
}

[[noreturn]] void badSize(const std::string& what) { throw std::invalid_argument("KlUpdate: " + what); }

template <typename M>
void checkEntries(const char* name, const std::vector<M>& v, int count, int rows, int cols) {
  if (static_cast<int>(v.size()) != count)
    badSize(std::string(name) + " has " + std::to_string(v.size()) + " entries, expected " + std::to_string(count));
  for (int t = 0; t < count; ++t)
    if (v[t].rows() != rows || v[t].cols() != cols)
      badSize(std::string(name) + "[" + std::to_string(t) + "] is " + std::to_string(v[t].rows()) + "x" +
              std::to_string(v[t].cols()) + ", expected " + std::to_string(rows) + "x" + std::to_string(cols));
}

double logDetFromCholesky(const Eigen::MatrixXd& L) { return 2.0 * L.diagonal().array().log().sum(); }

}  // namespace

void LgDynamics::resize(int nx_, int nu_, int horizon_) {
  checkDims("LgDynamics::resize", nx_, nu_, horizon_);
  nx = nx_;
  nu = nu_;
  horizon = horizon_;
  x0_mean = Eigen::VectorXd::Zero(nx);
  x0_cov = Eigen::MatrixXd::Zero(nx, nx);
  Fx.assign(horizon, Eigen::MatrixXd::Zero(nx, nx));
  Fu.assign(horizon, Eigen::MatrixXd::Zero(nx, nu));
  Sigma.assign(horizon, Eigen::MatrixXd::Zero(nx, nx));
  f.assign(horizon, Eigen::VectorXd::Zero(nx));
}

void QuadraticCost::resize(int nx, int nu, int horizon) {
  checkDims("QuadraticCost::resize", nx, nu, horizon);
  cxx.assign(horizon + 1, Eigen::MatrixXd::Zero(nx, nx));
  cx.assign(horizon + 1, Eigen::VectorXd::Zero(nx));
  cuu.assign(horizon, Eigen::MatrixXd::Zero(nu, nu));
  cux.assign(horizon, Eigen::MatrixXd::Zero(nu, nx));
  cu.assign(horizon, Eigen::VectorXd::Zero(nu));
}

void forwardMarginals(const LgDynamics& dyn, const LgController& c, TrajectoryMarginals& out, ThreadPool* pool) {
  const int nx = dyn.nx, nu = dyn.nu, T = dyn.horizon;
  if (c.nx() != nx || c.nu() != nu || c.horizon() != T)
    throw std::invalid_argument("forwardMarginals: controller and dynamics sizes differ");
  if (static_cast<int>(out.xu_mean.size()) != T) {
    out.xu_mean.assign(T, Eigen::VectorXd::Zero(nx + nu));
    out.xu_cov.assign(T, Eigen::MatrixXd::Zero(nx + nu, nx + nu));
  }
  // The state marginals are a chain: x_{t+1} has mean G mu + Fu k + f and covariance
  // G sigma G' + Fu C Fu' + Sigma with G = Fx + Fu K, C = L L'. Only the lower triangles of
  // the symmetric products are computed.
  Eigen::VectorXd mu = dyn.x0_mean;
  Eigen::MatrixXd sigma = dyn.x0_cov;
  Eigen::VectorXd mu_next(nx);
  Eigen::MatrixXd G(nx, nx), GS(nx, nx), FuL(nx, nu), next(nx, nx);
  for (int t = 0; t < T; ++t) {
    out.xu_mean[t].head(nx) = mu;
    out.xu_cov[t].topLeftCorner(nx, nx) = sigma;
    G = dyn.Fx[t];
    G.noalias() += dyn.Fu[t] * c.K[t];
    mu_next = dyn.f[t];
    mu_next.noalias() += G * mu;
    mu_next.noalias() += dyn.Fu[t] * c.k[t];
    mu.swap(mu_next);
    GS.noalias() = G * sigma;
    FuL.noalias() = dyn.Fu[t] * c.choleskyFactor(t).triangularView<Eigen::Lower>();
    next = dyn.Sigma[t];
    next.triangularView<Eigen::Lower>() += GS * G.transpose();
    next.selfadjointView<Eigen::Lower>().rankUpdate(FuL);
    sigma = next.selfadjointView<Eigen::Lower>();
  }
  out.xT_mean = mu;
  out.xT_cov = sigma;
  // The action parts of each step's joint, given its state marginal: independent steps.
  std::vector<Eigen::MatrixXd> KS(workerCount(pool), Eigen::MatrixXd(nu, nx));
  forEachIndex(pool, T, [&](std::size_t t, std::size_t worker) {
    const Eigen::MatrixXd& K = c.K[t];
    Eigen::VectorXd& m = out.xu_mean[t];
    Eigen::MatrixXd& S = out.xu_cov[t];
    m.tail(nu).noalias() = K * m.head(nx);
    m.tail(nu) += c.k[t];
    KS[worker].noalias() = K * S.topLeftCorner(nx, nx);
    S.bottomLeftCorner(nu, nx) = KS[worker];
    S.topRightCorner(nx, nu) = KS[worker].transpose();
    S.bottomRightCorner(nu, nu) = c.covariance(t);
    S.bottomRightCorner(nu, nu).triangularView<Eigen::Lower>() += KS[worker] * K.transpose();
    S.bottomRightCorner(nu, nu).triangularView<Eigen::StrictlyUpper>() = S.bottomRightCorner(nu, nu).transpose();
  });
}

double expectedCost(const QuadraticCost& cost, const TrajectoryMarginals& m) {
  const int T = static_cast<int>(m.xu_mean.size());
  double total = 0;
  for (int t = 0; t < T; ++t) {
    const int nx = static_cast<int>(cost.cxx[t].rows()), nu = static_cast<int>(cost.cuu[t].rows());
    const auto x = m.xu_mean[t].head(nx);
    const auto u = m.xu_mean[t].tail(nu);
    const Eigen::MatrixXd& S = m.xu_cov[t];
    // E[0.5 z'Hz + h'z] = 0.5 (tr(H S) + m'Hm) + h'm, blockwise with H = [cxx cux'; cux cuu].
    total += 0.5 * (cost.cxx[t].cwiseProduct(S.topLeftCorner(nx, nx)).sum() +
                    cost.cuu[t].cwiseProduct(S.bottomRightCorner(nu, nu)).sum()) +
             cost.cux[t].cwiseProduct(S.bottomLeftCorner(nu, nx)).sum();
    total += 0.5 * x.dot(cost.cxx[t] * x) + 0.5 * u.dot(cost.cuu[t] * u) + u.dot(cost.cux[t] * x);
    total += cost.cx[t].dot(x) + cost.cu[t].dot(u);
  }
  total += 0.5 * (cost.cxx[T].cwiseProduct(m.xT_cov).sum() + m.xT_mean.dot(cost.cxx[T] * m.xT_mean)) +
           cost.cx[T].dot(m.xT_mean);
  return total;
}

double klDivergence(const LgController& p, const LgController& q, const TrajectoryMarginals& m, ThreadPool* pool) {
  const int nx = p.nx(), nu = p.nu(), T = p.horizon();
  if (q.nx() != nx || q.nu() != nu || q.horizon() != T || static_cast<int>(m.xu_mean.size()) != T)
    throw std::invalid_argument("klDivergence: controller and marginal sizes differ");
  struct Scratch {
    Eigen::MatrixXd Linv_dK, Linv_Lp;
    Eigen::VectorXd d;
  };
  std::vector<Scratch> scratch(workerCount(pool));
  std::vector<double> step_kl(T);  // summed in step order: the same with any pool
  forEachIndex(pool, T, [&](std::size_t t, std::size_t worker) {
    Scratch& w = scratch[worker];
    // With q's covariance L L':  tr(P_q C_p) = |L^-1 L_p|_F^2 and the mean terms are
    // |L^-1 (dK mu + dk)|^2 + tr(dK' P_q dK Sigma_x) = |L^-1 dK Sigma_x^1/2|^2 (via trace).
    const auto Lq = q.choleskyFactor(t).triangularView<Eigen::Lower>();
    const auto mu = m.xu_mean[t].head(nx);
    const auto sigma = m.xu_cov[t].topLeftCorner(nx, nx);
    w.Linv_dK = p.K[t] - q.K[t];
    w.d = p.k[t] - q.k[t];
    w.d.noalias() += w.Linv_dK * mu;
    Lq.solveInPlace(w.Linv_dK);
    Lq.solveInPlace(w.d);
    w.Linv_Lp = p.choleskyFactor(t);
    Lq.solveInPlace(w.Linv_Lp);
    const double trace_term = w.Linv_Lp.squaredNorm();
    const double state_term = (w.Linv_dK * sigma).cwiseProduct(w.Linv_dK).sum();
    step_kl[t] = 0.5 * (trace_term - nu + logDetFromCholesky(q.choleskyFactor(t)) -
                        logDetFromCholesky(p.choleskyFactor(t)) + w.d.squaredNorm() + state_term);
  });
  double kl = 0;
  for (double v : step_kl) kl += v;
  return kl < 0 ? 0.0 : kl;  // rounding can leave -1e-16; a NaN (overflow) stays NaN
}

KlUpdate::KlUpdate(int nx, int nu, int horizon)
    : nx_(nx),
      nu_(nu),
      horizon_(horizon),
      lq_(nx + 1, nu, horizon),
      pass_(nx + 1, nu, horizon),
      inverse_(1, Eigen::MatrixXd(nu, nu)) {
  gains_.resize(nx + 1, nu, horizon);
  sizeWorkspaces(nullptr);
}

void KlUpdate::checkSizes(const LgDynamics& dyn, const QuadraticCost& cost, const LgController* prev) const {
  if (dyn.nx != nx_ || dyn.nu != nu_ || dyn.horizon != horizon_)
    badSize("dynamics are nx=" + std::to_string(dyn.nx) + " nu=" + std::to_string(dyn.nu) + " T=" +
            std::to_string(dyn.horizon) + ", update built for nx=" + std::to_string(nx_) + " nu=" +
            std::to_string(nu_) + " T=" + std::to_string(horizon_));
  const int T = horizon_;
  checkEntries("Fx", dyn.Fx, T, nx_, nx_);
  checkEntries("Fu", dyn.Fu, T, nx_, nu_);
  checkEntries("f", dyn.f, T, nx_, 1);
  checkEntries("Sigma", dyn.Sigma, T, nx_, nx_);
  if (dyn.x0_mean.size() != nx_ || dyn.x0_cov.rows() != nx_ || dyn.x0_cov.cols() != nx_)
    badSize("x0_mean / x0_cov have the wrong size");
  checkEntries("cxx", cost.cxx, T + 1, nx_, nx_);
  checkEntries("cx", cost.cx, T + 1, nx_, 1);
  checkEntries("cuu", cost.cuu, T, nu_, nu_);
  checkEntries("cux", cost.cux, T, nu_, nx_);
  checkEntries("cu", cost.cu, T, nu_, 1);
  if (prev && (prev->nx() != nx_ || prev->nu() != nu_ || prev->horizon() != T))
    badSize("previous controller sizes differ from the dynamics");
}

void KlUpdate::loadDynamics(const LgDynamics& dyn) {
  // Augmented state [x; 1]: dynamics [Fx f; 0 1], [Fu; 0]. Only the blocks that can change
  // are written; the rest stays as resize() left it (zeros, and the 1 below).
  const int nx = nx_;
  for (int t = 0; t < horizon_; ++t) {
    Eigen::MatrixXd& A = lq_.A[t];
    A.topLeftCorner(nx, nx) = dyn.Fx[t];
    A.topRightCorner(nx, 1) = dyn.f[t];
    A(nx, nx) = 1.0;
    lq_.B[t].topRows(nx) = dyn.Fu[t];
  }
}

void KlUpdate::sizeWorkspaces(ThreadPool* pool) {
  const std::size_t workers = workerCount(pool);
  if (inverse_.size() < workers) inverse_.resize(workers, Eigen::MatrixXd(nu_, nu_));
  // An LLT that has factored nothing has an uninitialised status, which copying it (when the
  // vector grows) reads (UBSan: invalid enum load): each one factors the identity once.
  while (llt_.size() < workers) {
    llt_.emplace_back(nu_);
    llt_.back().compute(Eigen::MatrixXd::Identity(nu_, nu_));
  }
}

void KlUpdate::loadPrevious(const LgController& prev, ThreadPool* pool) {
  // -log p_old(u|x) = 0.5 (u - Kx - k)' P (u - Kx - k) + const,  P = C_old^-1:
  //   xx: K'PK   ux: -PK   uu: P   x: K'Pk   u: -Pk
  // The same for every eta: computed once per update.
  const int nx = nx_, nu = nu_, T = horizon_;
  if (static_cast<int>(prev_P_.size()) != T) {
    prev_P_.assign(T, Eigen::MatrixXd(nu, nu));
    prev_PK_.assign(T, Eigen::MatrixXd(nu, nx));
    prev_KPK_.assign(T, Eigen::MatrixXd(nx, nx));
    prev_Pk_.assign(T, Eigen::VectorXd(nu));
    prev_KPk_.assign(T, Eigen::VectorXd(nx));
  }
  sizeWorkspaces(pool);
  forEachIndex(pool, T, [&](std::size_t t, std::size_t worker) {
    const Eigen::MatrixXd& K = prev.K[t];
    // P = L^-T L^-1 from the controller's Cholesky factor C = L L'.
    Eigen::MatrixXd& Linv = inverse_[worker];
    Linv.setIdentity();
    prev.choleskyFactor(t).triangularView<Eigen::Lower>().solveInPlace(Linv);
    prev_P_[t].noalias() = Linv.transpose() * Linv;
    prev_PK_[t].noalias() = prev_P_[t] * K;
    prev_Pk_[t].noalias() = prev_P_[t] * prev.k[t];
    prev_KPK_[t].noalias() = K.transpose() * prev_PK_[t];
    prev_KPk_[t].noalias() = K.transpose() * prev_Pk_[t];
  });
}

bool KlUpdate::solve(const LgDynamics& dyn, const QuadraticCost& cost, const LgController* prev, double eta,
                     LgController& out) {
  checkSizes(dyn, cost, prev);
  loadDynamics(dyn);
  if (prev) loadPrevious(*prev, nullptr);
  return solveLoaded(cost, prev != nullptr, eta, out, nullptr);
}

bool KlUpdate::solveLoaded(const QuadraticCost& cost, bool with_prev, double eta, LgController& out,
                           ThreadPool* pool) {
  const int nx = nx_, nu = nu_, T = horizon_;
  const double w = with_prev ? 1.0 / eta : 1.0;  // weight of the task cost
  if (!(w > 0) || !std::isfinite(w)) throw std::invalid_argument("KlUpdate::solve: eta must be positive and finite");

  forEachIndex(pool, T, [&](std::size_t t, std::size_t) {
    // Task cost times w.
    lq_.lxx[t].topLeftCorner(nx, nx) = w * cost.cxx[t];
    lq_.lx[t].head(nx) = w * cost.cx[t];
    lq_.luu[t] = w * cost.cuu[t];
    lq_.lux[t].leftCols(nx) = w * cost.cux[t];
    lq_.lu[t] = w * cost.cu[t];
    if (!with_prev) return;
    lq_.lxx[t].topLeftCorner(nx, nx) += prev_KPK_[t];
    lq_.lux[t].leftCols(nx) -= prev_PK_[t];
    lq_.luu[t] += prev_P_[t];
    lq_.lx[t].head(nx) += prev_KPk_[t];
    lq_.lu[t] -= prev_Pk_[t];
  });
  lq_.lxx[T].topLeftCorner(nx, nx) = w * cost.cxx[T];
  lq_.lx[T].head(nx) = w * cost.cx[T];

  static const std::vector<Eigen::VectorXd> kNoNominal;  // unconstrained: not read
  const BackwardPassResult r = pass_.run(lq_, kNoNominal, Eigen::VectorXd(), Eigen::VectorXd(), 0.0, gains_);
  if (!r.ok) return false;

  if (out.nx() != nx || out.nu() != nu || out.horizon() != T) out = LgController(nx, nu, T);
  sizeWorkspaces(pool);
  std::vector<char> step_ok(T, 0);
  forEachIndex(pool, T, [&](std::size_t t, std::size_t worker) {
    // u = k~ + K~ [x; 1]  ->  K = K~(:, 0:nx), k = k~ + K~(:, nx).
    out.K[t] = gains_.K[t].leftCols(nx);
    out.k[t] = gains_.k[t] + gains_.K[t].col(nx);
    Eigen::LLT<Eigen::MatrixXd>& llt = llt_[worker];
    Eigen::MatrixXd& C = inverse_[worker];
    llt.compute(pass_.Quu(t));
    if (llt.info() != Eigen::Success) return;
    C.setIdentity();
    llt.solveInPlace(C);  // C = Quu^-1
    if (!C.allFinite() || !out.K[t].allFinite() || !out.k[t].allFinite()) return;
    try {
      out.setCovariance(t, 0.5 * (C + C.transpose()));
    } catch (const std::invalid_argument&) {
      return;  // Quu^-1 numerically not PD (extremely ill-conditioned Quu)
    }
    step_ok[t] = 1;
  });
  return std::all_of(step_ok.begin(), step_ok.end(), [](char ok) { return ok != 0; });
}

KlUpdateResult KlUpdate::update(const LgDynamics& dyn, const QuadraticCost& cost, const LgController& prev,
                                double epsilon, const KlUpdateSettings& s) {
  checkSizes(dyn, cost, &prev);
  if (!(epsilon > 0) || !std::isfinite(epsilon))
    throw std::invalid_argument("KlUpdate::update: epsilon must be positive and finite");
  if (!(s.eta_min > 0 && s.eta_min <= s.eta_max && std::isfinite(s.eta_max)))
    throw std::invalid_argument("KlUpdate::update: need 0 < eta_min <= eta_max < inf");
  if (!(s.kl_slope_init < 0)) throw std::invalid_argument("KlUpdate::update: kl_slope_init must be negative");

  // KL decreases with eta (eta -> inf: the old controller). lo: largest eta known to give
  // KL above the band (or a failed solve); hi: smallest eta known to give KL below it.
  loadDynamics(dyn);
  loadPrevious(prev, s.pool);
  double lo = 0, hi = std::numeric_limits<double>::infinity();
  double log_kl_lo = std::numeric_limits<double>::infinity(), log_kl_hi = 0;
  double eta = std::min(std::max(s.eta_init, s.eta_min), s.eta_max);
  // The secant of log KL over log eta (KL is close to a power law over a decade or two, slope
  // -2 for large eta, flatter below): extrapolates toward the band until it is bracketed,
  // then interpolates inside the bracket. Previous finite evaluation: for the slope.
  const double log_epsilon = std::log(epsilon);
  // Slope of log KL over log eta through the last two finite evaluations (kl_slope_init
  // before there are two), kept within [-4, -0.25] against noise and flat stretches.
  const auto clampSlope = [](double slope) { return std::min(-0.25, std::max(-4.0, slope)); };
  double slope = clampSlope(s.kl_slope_init);
  double last_log_eta = 0, last_log_kl = 0;
  bool have_last_point = false;
  int same_end_moves = 0;  // consecutive evaluations that moved the same end (lo or hi)
  bool last_moved_lo = false;
  // Fallbacks when the band is not reached: the last controller inside the constraint, else
  // the last one solved at all.
  KlUpdateResult current, best, last;
  bool have_best = false, have_last = false;
  int not_definite = 0, non_finite = 0;  // failed evaluations, by cause
  for (int it = 1; it <= s.max_iterations; ++it) {
    const bool ok = solveLoaded(cost, true, eta, current.controller, s.pool);
    double kl = std::numeric_limits<double>::infinity();
    if (ok) {
      forwardMarginals(dyn, current.controller, marginals_, s.pool);
      kl = klDivergence(current.controller, prev, marginals_, s.pool);
      current.predicted_cost = expectedCost(cost, marginals_);
      // An overflow (huge but finite inputs) is a failed evaluation, never a KL of 0.
      if (!std::isfinite(kl) || !std::isfinite(current.predicted_cost)) {
        kl = std::numeric_limits<double>::infinity();
        ++non_finite;
      }
    } else {
      ++not_definite;
    }
    const double log_eta = std::log(eta), log_kl = std::log(std::max(kl, 1e-300));
    if (std::isfinite(kl)) {
      if (have_last_point && log_eta != last_log_eta)
        slope = clampSlope((log_kl - last_log_kl) / (log_eta - last_log_eta));
      last_log_eta = log_eta;
      last_log_kl = log_kl;
      have_last_point = true;
      current.kl_slope = slope;
      current.eta = eta;
      current.kl = kl;
      current.iterations = it;
      const bool in_band = std::abs(kl - epsilon) <= s.tolerance * epsilon;
      const bool slack = kl < epsilon && eta <= s.eta_min;
      if (in_band || slack) {
        current.converged = true;
        return current;
      }
      if (kl < epsilon) {
        best = current;
        have_best = true;
      }
      last = current;
      have_last = true;
    }
    const bool moved_lo = !(kl < epsilon);
    if (moved_lo) {
      lo = eta;
      log_kl_lo = log_kl;
      if (eta >= s.eta_max) break;  // even the largest eta moves too far (or fails)
    } else {
      hi = eta;
      log_kl_hi = log_kl;
    }
    same_end_moves = moved_lo == last_moved_lo ? same_end_moves + 1 : 1;
    last_moved_lo = moved_lo;
    if (lo > 0 && std::isfinite(hi)) {
      const double log_lo = std::log(lo), log_hi = std::log(hi), width = log_hi - log_lo;
      // Bracketed: interpolate between its ends (regula falsi in log-log), kept off the ends;
      // geometric bisection when lo's solve failed, or when the same end moved three times
      // in a row (regula falsi then converges slowly).
      double next = 0.5 * (log_lo + log_hi);
      if (std::isfinite(log_kl_lo) && same_end_moves < 3) {
        next = log_lo + (log_epsilon - log_kl_lo) * width / (log_kl_hi - log_kl_lo);
        next = std::min(std::max(next, log_lo + 0.05 * width), log_hi - 0.05 * width);
      }
      eta = std::exp(next);
    } else if (lo > 0) {
      // KL above the band at every eta so far: larger eta, by the secant when lo was solved
      // (at most 100x per step), by 10x after a failed solve.
      const double factor = std::isfinite(log_kl_lo) ? std::exp((log_epsilon - log_kl_lo) / slope) : 10.0;
      eta = std::min(lo * std::min(factor, 100.0), s.eta_max);
    } else {
      eta = std::max(hi * std::max(std::exp((log_epsilon - log_kl_hi) / slope), 0.01), s.eta_min);
    }
  }
  if (have_best) return best;  // not converged, but inside the constraint
  if (have_last) return last;  // not converged: KL above epsilon even at the largest eta tried
  throw std::runtime_error("KlUpdate::update: no eta in [" + std::to_string(s.eta_min) + ", " +
                           std::to_string(s.eta_max) + "] gives an update: Q_uu not positive definite at " +
                           std::to_string(not_definite) + " etas, KL or expected cost not finite at " +
                           std::to_string(non_finite) + " (overflow: are the dynamics or costs too large?)");
}

double adjustEpsilon(double epsilon, double previous_expected, double predicted, double previous_actual,
                     double actual, const StepSizeSettings& s) {
  const double predicted_improvement = previous_expected - predicted;
  const double actual_improvement = previous_actual - actual;
  double multiplier;
  if (!(predicted_improvement > 0))
    multiplier = s.min_multiplier;  // the model promises nothing: smaller steps
  else if (!(predicted_improvement - actual_improvement > 0))
    multiplier = s.max_multiplier;  // reality did at least as well as predicted
  else
    multiplier = predicted_improvement / (2.0 * (predicted_improvement - actual_improvement));
  return epsilon * std::min(std::max(multiplier, s.min_multiplier), s.max_multiplier);
}

}  // namespace adroit
