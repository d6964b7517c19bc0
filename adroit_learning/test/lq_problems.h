// Random linear-Gaussian dynamics and convex quadratic costs for the adroit_learning tests.
#pragma once

#include <random>

#include "adroit_learning/kl_update.h"

namespace test_problems {

inline Eigen::MatrixXd randn(std::mt19937& rng, int rows, int cols, double scale) {
  std::normal_distribution<double> n(0.0, scale);
  Eigen::MatrixXd m(rows, cols);
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j) m(i, j) = n(rng);
  return m;
}

inline adroit::LgDynamics randomDynamics(std::mt19937& rng, int nx, int nu, int T) {
  adroit::LgDynamics d(nx, nu, T);
  d.x0_mean = randn(rng, nx, 1, 1.0);
  d.x0_cov = 0.01 * Eigen::MatrixXd::Identity(nx, nx);
  for (int t = 0; t < T; ++t) {
    d.Fx[t] = Eigen::MatrixXd::Identity(nx, nx) + randn(rng, nx, nx, 0.1);
    d.Fu[t] = randn(rng, nx, nu, 0.3);
    d.f[t] = randn(rng, nx, 1, 0.1);
    const Eigen::MatrixXd S = randn(rng, nx, nx, 0.05);
    d.Sigma[t] = S * S.transpose() + 1e-3 * Eigen::MatrixXd::Identity(nx, nx);
  }
  return d;
}

// Jointly convex in (x, u) at every step, with random linear terms.
inline adroit::QuadraticCost randomCost(std::mt19937& rng, int nx, int nu, int T) {
  adroit::QuadraticCost c(nx, nu, T);
  for (int t = 0; t <= T; ++t) {
    const Eigen::MatrixXd N = randn(rng, nx + nu, nx + nu, 0.5);
    const Eigen::MatrixXd H = N * N.transpose() + 0.1 * Eigen::MatrixXd::Identity(nx + nu, nx + nu);
    c.cxx[t] = H.topLeftCorner(nx, nx);
    c.cx[t] = randn(rng, nx, 1, 1.0);
    if (t == T) break;
    c.cuu[t] = H.bottomRightCorner(nu, nu);
    c.cux[t] = H.bottomLeftCorner(nu, nx);
    c.cu[t] = randn(rng, nu, 1, 1.0);
  }
  return c;
}

}  // namespace test_problems
