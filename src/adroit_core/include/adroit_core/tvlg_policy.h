// A time-varying linear(-Gaussian) feedback policy on knots t_k = t0 + k dt (k = 0..T-1):
//   u(t, x) = u_k + K_k (x - x_k)   evaluated with linear interpolation between knots,
// clamped to the control box. The behaviour MPC publishes it (deterministic part) and the
// trainer adds the covariance C_k (TVLG controllers, thesis 8.2). The state difference
// x - x_k is computed by the caller (tangent space for MuJoCo states: mj_differentiatePos),
// so nominalState() gives the interpolated x_k first.
#pragma once

#include <Eigen/Dense>
#include <vector>

namespace adroit {

class TvlgPolicy {
 public:
  TvlgPolicy() = default;
  // nx_full: size of the stored nominal state (e.g. nq + nv + na); nx: size of the state
  // difference the gains act on (e.g. 2 nv + na). Allocates.
  TvlgPolicy(int nx_full, int nx, int nu, int knots);

  int knots() const;
  double t0 = 0, dt = 0;
  std::vector<Eigen::VectorXd> x;  // nominal states (nx_full)
  std::vector<Eigen::VectorXd> u;  // nominal controls (nu)
  std::vector<Eigen::MatrixXd> K;  // feedback gains (nu x nx)
  std::vector<Eigen::MatrixXd> covariance;  // optional (trainer); empty in the MPC
  Eigen::VectorXd u_min, u_max;    // empty = unbounded

  // Knot index and interpolation weight of time t (clamped to [t0, t0 + (T-1) dt]).
  void locate(double t, int& k, double& w) const;
  // Interpolated nominal state at t (allocates nothing; out has size nx_full).
  void nominalState(double t, Eigen::Ref<Eigen::VectorXd> out) const;
  // u(t) = interp(u) + interp(K) dx, clamped; dx = x - nominalState(t). feedback_scale in [0, 1]
  // scales K (MPC "nominal feedback scaling"). Allocates nothing.
  void action(double t, const Eigen::Ref<const Eigen::VectorXd>& dx, Eigen::Ref<Eigen::VectorXd> out,
              double feedback_scale = 1.0) const;
  // Shift by whole knots to start at or before t (warm start of the next MPC solve): drops
  // the knots before t and repeats the last knot at the end.
  void shiftTo(double t);
};

}  // namespace adroit
