#include "adroit_core/tvlg_policy.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace adroit {

TvlgPolicy::TvlgPolicy(int nx_full, int nx, int nu, int knots) {
  if (nx_full <= 0 || nx <= 0 || nu <= 0 || knots <= 0)
    throw std::invalid_argument("TvlgPolicy: nx_full, nx, nu and knots must be positive, got " +
                                std::to_string(nx_full) + ", " + std::to_string(nx) + ", " + std::to_string(nu) +
                                ", " + std::to_string(knots));
  x.assign(knots, Eigen::VectorXd::Zero(nx_full));
  u.assign(knots, Eigen::VectorXd::Zero(nu));
  K.assign(knots, Eigen::MatrixXd::Zero(nu, nx));
}

int TvlgPolicy::knots() const { return static_cast<int>(u.size()); }

void TvlgPolicy::locate(double t, int& k, double& w) const {
  const int n = knots();
  if (n == 0) throw std::logic_error("TvlgPolicy: the policy has no knots");
  if (!std::isfinite(t)) throw std::invalid_argument("TvlgPolicy: time is not finite");
  if (n == 1) {
    k = 0;
    w = 0;
    return;
  }
  if (!(dt > 0)) throw std::logic_error("TvlgPolicy: dt must be > 0, is " + std::to_string(dt));
  const double s = (t - t0) / dt;
  if (!(s > 0)) {
    k = 0;
    w = 0;
  } else if (s >= n - 1) {
    k = n - 2;  // the last segment at its end: k + 1 is the last knot
    w = 1;
  } else {
    k = static_cast<int>(s);
    w = s - k;
  }
}

void TvlgPolicy::nominalState(double t, Eigen::Ref<Eigen::VectorXd> out) const {
  int k;
  double w;
  locate(t, k, w);
  if (out.size() != x[k].size())
    throw std::invalid_argument("TvlgPolicy::nominalState: out has size " + std::to_string(out.size()) +
                                ", the nominal state " + std::to_string(x[k].size()));
  // Component-wise: a quaternion in x comes out unnormalised (the caller renormalises it).
  if (w == 0)
    out = x[k];
  else
    out = (1 - w) * x[k] + w * x[k + 1];
}

void TvlgPolicy::action(double t, const Eigen::Ref<const Eigen::VectorXd>& dx, Eigen::Ref<Eigen::VectorXd> out,
                        double feedback_scale) const {
  int k;
  double w;
  locate(t, k, w);
  if (out.size() != u[k].size() || dx.size() != K[k].cols())
    throw std::invalid_argument("TvlgPolicy::action: out has size " + std::to_string(out.size()) + " (nu = " +
                                std::to_string(u[k].size()) + "), dx " + std::to_string(dx.size()) + " (nx = " +
                                std::to_string(K[k].cols()) + ")");
  if (!std::isfinite(feedback_scale))
    throw std::invalid_argument("TvlgPolicy::action: feedback_scale is not finite");
  out = u[k];
  out.noalias() += (feedback_scale * (1 - w)) * (K[k] * dx);
  if (w != 0) {
    out += w * (u[k + 1] - u[k]);
    out.noalias() += (feedback_scale * w) * (K[k + 1] * dx);
  }
  if (u_min.size() != 0) {
    if (u_min.size() != out.size() || u_max.size() != out.size())
      throw std::invalid_argument("TvlgPolicy::action: u_min/u_max must be empty or of size nu = " +
                                  std::to_string(out.size()));
    out = out.cwiseMax(u_min).cwiseMin(u_max);
  }
}

void TvlgPolicy::shiftTo(double t) {
  const int n = knots();
  if (n == 0 || !(dt > 0)) return;  // nothing to shift, or a single timeless knot
  if (!std::isfinite(t)) throw std::invalid_argument("TvlgPolicy::shiftTo: time is not finite");
  // A relative 1e-9 absorbs rounding of t computed as t0 + m * dt, so landing exactly on a
  // knot drops the knots before it.
  const double s = std::floor((t - t0) / dt + 1e-9);
  if (!(s >= 1)) return;
  const int drop = s >= n ? n - 1 : static_cast<int>(s);
  auto shift = [&](auto& knots_of) {
    if (knots_of.empty()) return;  // covariance is optional
    if (static_cast<int>(knots_of.size()) != n)
      throw std::logic_error("TvlgPolicy::shiftTo: x, K and covariance must have one entry per knot of u");
    for (int i = 0; i + drop < n; ++i) knots_of[i].swap(knots_of[i + drop]);  // storage swap, no allocation
    for (int i = n - drop; i < n; ++i) knots_of[i] = knots_of[n - drop - 1];
  };
  shift(x);
  shift(u);
  shift(K);
  shift(covariance);
  t0 += s * dt;
}

}  // namespace adroit
