#include "adroit_core/lq_backward_pass.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace adroit {

namespace {

void checkDimensions(const char* where, int nx, int nu, int horizon) {
  if (nx <= 0 || nu <= 0 || horizon <= 0)
    throw std::invalid_argument(std::string(where) + ": nx, nu and horizon must be positive, got " +
                                std::to_string(nx) + ", " + std::to_string(nu) + ", " + std::to_string(horizon));
}

[[noreturn]] void badShape(const char* name, int t, Eigen::Index rows, Eigen::Index cols, int want_rows,
                           int want_cols) {
  throw std::invalid_argument("BackwardPass::run: " + std::string(name) + "[" + std::to_string(t) + "] is " +
                              std::to_string(rows) + "x" + std::to_string(cols) + ", expected " +
                              std::to_string(want_rows) + "x" + std::to_string(want_cols));
}

template <typename M>
void checkShape(const char* name, int t, const M& m, int rows, int cols) {
  if (m.rows() != rows || m.cols() != cols) badShape(name, t, m.rows(), m.cols(), rows, cols);
}

template <typename V>
void checkCount(const char* name, const std::vector<V>& v, int count) {
  if (static_cast<int>(v.size()) != count)
    throw std::invalid_argument("BackwardPass::run: " + std::string(name) + " has " + std::to_string(v.size()) +
                                " entries, expected " + std::to_string(count));
}

// Copies the lower triangle onto the upper one (the products below fill the lower only).
void mirrorLower(Eigen::MatrixXd& m) {
  const Eigen::Index n = m.rows();
  for (Eigen::Index j = 1; j < n; ++j)
    for (Eigen::Index i = 0; i < j; ++i) m(i, j) = m(j, i);
}

}  // namespace

void LqApproximation::resize(int nx_, int nu_, int horizon_) {
  checkDimensions("LqApproximation::resize", nx_, nu_, horizon_);
  nx = nx_;
  nu = nu_;
  horizon = horizon_;
  A.assign(horizon, Eigen::MatrixXd::Zero(nx, nx));
  B.assign(horizon, Eigen::MatrixXd::Zero(nx, nu));
  lx.assign(horizon + 1, Eigen::VectorXd::Zero(nx));
  lxx.assign(horizon + 1, Eigen::MatrixXd::Zero(nx, nx));
  lu.assign(horizon, Eigen::VectorXd::Zero(nu));
  luu.assign(horizon, Eigen::MatrixXd::Zero(nu, nu));
  lux.assign(horizon, Eigen::MatrixXd::Zero(nu, nx));
}

void FeedbackGains::resize(int nx, int nu, int horizon) {
  checkDimensions("FeedbackGains::resize", nx, nu, horizon);
  k.assign(horizon, Eigen::VectorXd::Zero(nu));
  K.assign(horizon, Eigen::MatrixXd::Zero(nu, nx));
}

BackwardPass::BackwardPass(int nx, int nu, int horizon, BackwardPassSettings settings)
    : nx_(nx),
      nu_(nu),
      horizon_(horizon),
      settings_(settings),
      qp_((checkDimensions("BackwardPass", nx, nu, horizon), nu), settings.qp),
      llt_(nu),
      Vx_(horizon + 1, Eigen::VectorXd::Zero(nx)),
      Vxx_(horizon + 1, Eigen::MatrixXd::Zero(nx, nx)),
      Quu_steps_(horizon, Eigen::MatrixXd::Zero(nu, nu)),
      Qx_(nx),
      Qu_(nu),
      lower_(nu),
      upper_(nu),
      du_(nu),
      Quu_(nu, nu),
      Qux_(nu, nx),
      Quu_reg_(nu, nu),
      Qux_reg_(nu, nx),
      VxxA_(nx, nx),
      VxxB_(nx, nu),
      QuuK_(nu, nx) {
  // Give the LLT its nu x nu storage now so the first run() does not allocate it.
  llt_.compute(Eigen::MatrixXd::Identity(nu, nu));
}

void BackwardPass::checkInputs(const LqApproximation& lq, const std::vector<Eigen::VectorXd>& u_nominal,
                               const Eigen::VectorXd& u_min, const Eigen::VectorXd& u_max, double mu) const {
  if (lq.nx != nx_ || lq.nu != nu_ || lq.horizon != horizon_)
    throw std::invalid_argument("BackwardPass::run: problem is nx=" + std::to_string(lq.nx) + " nu=" +
                                std::to_string(lq.nu) + " T=" + std::to_string(lq.horizon) + ", pass built for nx=" +
                                std::to_string(nx_) + " nu=" + std::to_string(nu_) + " T=" + std::to_string(horizon_));
  checkCount("A", lq.A, horizon_);
  checkCount("B", lq.B, horizon_);
  checkCount("lx", lq.lx, horizon_ + 1);
  checkCount("lxx", lq.lxx, horizon_ + 1);
  checkCount("lu", lq.lu, horizon_);
  checkCount("luu", lq.luu, horizon_);
  checkCount("lux", lq.lux, horizon_);
  for (int t = 0; t <= horizon_; ++t) {
    checkShape("lx", t, lq.lx[t], nx_, 1);
    checkShape("lxx", t, lq.lxx[t], nx_, nx_);
    if (t == horizon_) break;
    checkShape("A", t, lq.A[t], nx_, nx_);
    checkShape("B", t, lq.B[t], nx_, nu_);
    checkShape("lu", t, lq.lu[t], nu_, 1);
    checkShape("luu", t, lq.luu[t], nu_, nu_);
    checkShape("lux", t, lq.lux[t], nu_, nx_);
  }
  if (u_min.size() != u_max.size() || (u_min.size() != 0 && u_min.size() != nu_))
    throw std::invalid_argument("BackwardPass::run: u_min and u_max must both be empty or of size " +
                                std::to_string(nu_) + ", got " + std::to_string(u_min.size()) + " and " +
                                std::to_string(u_max.size()));
  if (u_min.size() != 0) {
    checkCount("u_nominal", u_nominal, horizon_);
    for (int t = 0; t < horizon_; ++t) checkShape("u_nominal", t, u_nominal[t], nu_, 1);
    for (int i = 0; i < nu_; ++i)
      if (!(u_min[i] <= u_max[i]))
        throw std::invalid_argument("BackwardPass::run: u_min[" + std::to_string(i) + "] = " +
                                    std::to_string(u_min[i]) + " is not <= u_max = " + std::to_string(u_max[i]));
  }
  if (!(mu >= 0) || !std::isfinite(mu))
    throw std::invalid_argument("BackwardPass::run: mu must be finite and >= 0, got " + std::to_string(mu));
}

BackwardPassResult BackwardPass::run(const LqApproximation& lq, const std::vector<Eigen::VectorXd>& u_nominal,
                                     const Eigen::VectorXd& u_min, const Eigen::VectorXd& u_max, double mu,
                                     FeedbackGains& gains) {
  checkInputs(lq, u_nominal, u_min, u_max, mu);
  if (static_cast<int>(gains.k.size()) != horizon_ || static_cast<int>(gains.K.size()) != horizon_ ||
      gains.k[0].size() != nu_ || gains.K[0].rows() != nu_ || gains.K[0].cols() != nx_)
    gains.resize(nx_, nu_, horizon_);  // first use only
  const bool bounded = u_min.size() != 0;
  const bool state_regularization = settings_.regularization == RegularizationType::kState;

  BackwardPassResult result;
  Vx_[horizon_] = lq.lx[horizon_];
  Vxx_[horizon_] = lq.lxx[horizon_];
  for (int t = horizon_ - 1; t >= 0; --t) {
    const Eigen::MatrixXd& A = lq.A[t];
    const Eigen::MatrixXd& B = lq.B[t];
    const Eigen::MatrixXd& Vxx_next = Vxx_[t + 1];
    Eigen::VectorXd& k = gains.k[t];
    Eigen::MatrixXd& K = gains.K[t];

    // Q-function of step t (Vxx_next is symmetric, so Vxx' A = Vxx A).
    Qx_ = lq.lx[t];
    Qx_.noalias() += A.transpose() * Vx_[t + 1];
    Qu_ = lq.lu[t];
    Qu_.noalias() += B.transpose() * Vx_[t + 1];
    VxxA_.noalias() = Vxx_next * A;
    VxxB_.noalias() = Vxx_next * B;
    Quu_ = lq.luu[t];
    Quu_.noalias() += B.transpose() * VxxB_;
    Qux_ = lq.lux[t];
    Qux_.noalias() += B.transpose() * VxxA_;
    Quu_steps_[t] = Quu_;

    // Regularised copies decide the step; the value update below uses the exact Q terms.
    Quu_reg_ = Quu_;
    const Eigen::MatrixXd* Qux_step = &Qux_;
    if (state_regularization) {  // Vxx + mu I:  Quu + mu B'B,  Qux + mu B'A
      Quu_reg_.noalias() += mu * (B.transpose() * B);
      Qux_reg_ = Qux_;
      Qux_reg_.noalias() += mu * (B.transpose() * A);
      Qux_step = &Qux_reg_;
    } else {
      Quu_reg_.diagonal().array() += mu;
    }

    if (bounded) {
      lower_ = u_min - u_nominal[t];
      upper_ = u_max - u_nominal[t];
      // k (the previous iteration's step) warm-starts the QP.
      const BoxQpStatus status = qp_.solve(Quu_reg_, Qu_, lower_, upper_, k);
      if (status == BoxQpStatus::kHessianNotPositiveDefinite || status == BoxQpStatus::kNoDescent) {
        result.failed_step = t;
        return result;
      }
      // Rows of clamped controls are zero: a small state change must not push them out.
      qp_.solveFree(*Qux_step, K);
      K *= -1.0;
      result.clamped_controls += nu_ - qp_.freeCount();
    } else {
      llt_.compute(Quu_reg_);
      if (llt_.info() != Eigen::Success) {
        result.failed_step = t;
        return result;
      }
      k = -Qu_;
      llt_.solveInPlace(k);
      K = -*Qux_step;
      llt_.solveInPlace(K);
    }
    if (!k.allFinite()) {
      result.failed_step = t;
      return result;
    }

    // Improved value update (Tassa 2012), exact for any k, K (clamped ones too):
    //   Vx  = Qx + K'Quu k + K'Qu + Qux'k
    //   Vxx = Qxx + K'Quu K + K'Qux + Qux'K        (lower triangle computed, then mirrored)
    du_.noalias() = Quu_ * k;
    result.dV[0] += k.dot(Qu_);
    result.dV[1] += 0.5 * k.dot(du_);
    du_ += Qu_;
    Eigen::VectorXd& Vx = Vx_[t];
    Vx = Qx_;
    Vx.noalias() += K.transpose() * du_;
    Vx.noalias() += Qux_.transpose() * k;

    QuuK_.noalias() = Quu_ * K;
    QuuK_ += Qux_;
    Eigen::MatrixXd& Vxx = Vxx_[t];
    Vxx = lq.lxx[t];
    Vxx.triangularView<Eigen::Lower>() += A.transpose() * VxxA_;
    Vxx.triangularView<Eigen::Lower>() += K.transpose() * QuuK_;
    Vxx.triangularView<Eigen::Lower>() += Qux_.transpose() * K;
    mirrorLower(Vxx);
  }
  result.ok = true;
  return result;
}

void RegularizationSchedule::increase() {
  delta = std::max(delta0, delta * delta0);
  mu = std::max(mu_min, mu * delta);
}

void RegularizationSchedule::decrease() {
  delta = std::min(1.0 / delta0, delta / delta0);
  mu = mu * delta;
  if (mu < mu_min) mu = 0;
}

}  // namespace adroit
