#include "adroit_learning/lg_controller.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace adroit {

LgController::LgController(int nx, int nu, int horizon) : nx_(nx), nu_(nu), horizon_(horizon) {
  if (nx <= 0 || nu <= 0 || horizon <= 0)
    throw std::invalid_argument("LgController: nx, nu and horizon must be positive, got " + std::to_string(nx) +
                                ", " + std::to_string(nu) + ", " + std::to_string(horizon));
  K.assign(horizon, Eigen::MatrixXd::Zero(nu, nx));
  k.assign(horizon, Eigen::VectorXd::Zero(nu));
  C_.assign(horizon, Eigen::MatrixXd::Identity(nu, nu));
  L_.assign(horizon, Eigen::MatrixXd::Identity(nu, nu));
}

LgController LgController::initial(int nx, int horizon, const Eigen::VectorXd& u0, const Eigen::VectorXd& variance,
                                   const Eigen::MatrixXd& K0) {
  const int nu = static_cast<int>(u0.size());
  if (variance.size() != nu)
    throw std::invalid_argument("LgController::initial: variance has " + std::to_string(variance.size()) +
                                " entries, u0 has " + std::to_string(nu));
  if (!((variance.array() > 0).all() && variance.allFinite()))
    throw std::invalid_argument("LgController::initial: variances must be finite and positive");
  if (K0.size() != 0 && (K0.rows() != nu || K0.cols() != nx))
    throw std::invalid_argument("LgController::initial: K0 must be " + std::to_string(nu) + "x" + std::to_string(nx));
  LgController c(nx, nu, horizon);
  const Eigen::MatrixXd C = variance.asDiagonal();
  for (int t = 0; t < horizon; ++t) {
    c.k[t] = u0;
    if (K0.size() != 0) c.K[t] = K0;
    c.setCovariance(t, C);
  }
  return c;
}

void LgController::setCovariance(int t, const Eigen::MatrixXd& C) {
  if (t < 0 || t >= horizon_) throw std::out_of_range("LgController::setCovariance: step " + std::to_string(t));
  if (C.rows() != nu_ || C.cols() != nu_)
    throw std::invalid_argument("LgController::setCovariance: C[" + std::to_string(t) + "] is " +
                                std::to_string(C.rows()) + "x" + std::to_string(C.cols()) + ", expected " +
                                std::to_string(nu_) + "x" + std::to_string(nu_));
  if (!C.allFinite() || (C - C.transpose()).norm() > 1e-9 * (1.0 + C.norm()))
    throw std::invalid_argument("LgController::setCovariance: C[" + std::to_string(t) +
                                "] is not a finite symmetric matrix");
  Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (C + C.transpose()));
  if (llt.info() != Eigen::Success)
    throw std::invalid_argument("LgController::setCovariance: C[" + std::to_string(t) +
                                "] is not positive definite");
  C_[t] = 0.5 * (C + C.transpose());
  L_[t] = llt.matrixL();
}

void LgController::action(int t, const Eigen::Ref<const Eigen::VectorXd>& x,
                          const Eigen::Ref<const Eigen::VectorXd>& noise_t, Eigen::Ref<Eigen::VectorXd> u) const {
  u = k[t];
  u.noalias() += K[t] * x;
  u.noalias() += L_[t].triangularView<Eigen::Lower>() * noise_t;
}

Eigen::MatrixXd smoothedNoise(NormalNoise& rng, int nu, int horizon, double width) {
  Eigen::MatrixXd white(nu, horizon);
  for (int t = 0; t < horizon; ++t)
    for (int i = 0; i < nu; ++i) white(i, t) = rng();
  if (!(width > 0)) return white;

  const int radius = static_cast<int>(std::ceil(4.0 * width));
  Eigen::VectorXd w(2 * radius + 1);
  for (int j = -radius; j <= radius; ++j) w[j + radius] = std::exp(-0.5 * (j / width) * (j / width));

  Eigen::MatrixXd smooth = Eigen::MatrixXd::Zero(nu, horizon);
  for (int t = 0; t < horizon; ++t) {
    double taps_sq = 0;  // variance of the sum: only the taps inside the rollout count
    for (int j = -radius; j <= radius; ++j) {
      const int s = t + j;
      if (s < 0 || s >= horizon) continue;
      smooth.col(t) += w[j + radius] * white.col(s);
      taps_sq += w[j + radius] * w[j + radius];
    }
    smooth.col(t) /= std::sqrt(taps_sq);
  }
  return smooth;
}

}  // namespace adroit
