// Time-varying linear-Gaussian controller of trajectory-centric RL (thesis 8.2):
//   p(u_t | x_t) = N(K_t x_t + k_t, C_t),   t = 0..T-1,
// in absolute state coordinates. The Cholesky factor L_t (C_t = L_t L_t') is kept next to
// C_t so that sampling an action is one triangular product: u = K x + k + L noise_t with
// noise_t ~ N(0, I), drawn for the whole rollout in advance (smoothedNoise).
#pragma once

#include <adroit_core/normal_noise.h>

#include <Eigen/Dense>
#include <vector>

namespace adroit {

class LgController {
 public:
  LgController() = default;
  LgController(int nx, int nu, int horizon);  // K = 0, k = 0, C = I; allocates

  // Initial controller: u_t = u0 + K0 x (K0 may be empty = zero gains), C_t = diag(variance).
  static LgController initial(int nx, int horizon, const Eigen::VectorXd& u0, const Eigen::VectorXd& variance,
                              const Eigen::MatrixXd& K0 = Eigen::MatrixXd());

  int nx() const { return nx_; }
  int nu() const { return nu_; }
  int horizon() const { return horizon_; }

  // Sets C_t and its Cholesky factor; throws std::invalid_argument when C is not symmetric
  // positive definite or has the wrong shape.
  void setCovariance(int t, const Eigen::MatrixXd& C);
  const Eigen::MatrixXd& covariance(int t) const { return C_[t]; }
  const Eigen::MatrixXd& choleskyFactor(int t) const { return L_[t]; }  // lower triangular

  // u = K_t x + k_t + L_t noise_t (noise_t ~ N(0, I); zero gives the mean action).
  // Allocates nothing.
  void action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& noise_t,
              Eigen::Ref<Eigen::VectorXd> u) const;

  std::vector<Eigen::MatrixXd> K;  // nu x nx
  std::vector<Eigen::VectorXd> k;  // nu

 private:
  int nx_ = 0, nu_ = 0, horizon_ = 0;
  std::vector<Eigen::MatrixXd> C_, L_;
};

// Exploration noise of one rollout: column t is noise_t for LgController::action. White
// N(0, 1) samples convolved over time with a Gaussian kernel of standard deviation `width`
// steps (truncated at 4 width; width <= 0: white noise), then each sample divided by the
// norm of the kernel taps that reached it, so every entry stays N(0, 1) (also at the ends)
// and the controller's C_t stays the per-step covariance. Interior lag-1 autocorrelation:
// sum_j w_j w_{j+1} / sum_j w_j^2 (about exp(-1 / (4 width^2)) for width >~ 1).
Eigen::MatrixXd smoothedNoise(NormalNoise& rng, int nu, int horizon, double width);

}  // namespace adroit
