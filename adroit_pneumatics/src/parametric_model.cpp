#include "adroit_pneumatics/parametric_model.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace adroit::pneumatics {

namespace {
constexpr double kCc = 1e6;  // m^3 -> cm^3
}

void ParametricParams::validate() const {
  const std::pair<const char*, double> fields[] = {{"c2", c2}, {"c3", c3}, {"c4", c4}, {"c5", c5}, {"c6", c6},
                                                   {"c7", c7}, {"c8", c8}, {"c9", c9}, {"cg", cg}, {"td", td}};
  for (const auto& [name, value] : fields)
    if (!std::isfinite(value)) throw std::invalid_argument(std::string("parametric model: ") + name + " is not finite");
  if (!(cg > 0)) throw std::invalid_argument("parametric model: cg must be > 0");
  if (!(c9 > 0)) throw std::invalid_argument("parametric model: c9 must be > 0 (rate at the valve centre)");
  if (!(c7 >= 0)) throw std::invalid_argument("parametric model: c7 must be >= 0");
  if (!(std::abs(c8) < 1)) throw std::invalid_argument("parametric model: |c8| must be < 1 (rate must stay > 0)");
  if (!(td >= 0 && td <= 0.05)) throw std::invalid_argument("parametric model: td must be in [0, 0.05] s");
  if (!(c3 > 0) || !(c4 >= 0)) throw std::invalid_argument("parametric model: c3 must be > 0 and c4 >= 0 (monotone s(u))");
}

ParametricModel::ParametricModel(const ParametricParams& params) : params_(params) { params_.validate(); }

double ParametricModel::steadyState(double u, const ParametricInputs& in, double* ds_du) const {
  const double cb = 0.5 * (in.supply + in.room), cs = 0.5 * (in.supply - in.room);
  const double uh = u - params_.c2;
  const double z = params_.c3 * uh + params_.c4 * uh * uh * uh;
  const double q = 1.0 / std::sqrt(1.0 + z * z);
  if (ds_du) *ds_du = cs * q * q * q * (params_.c3 + 3.0 * params_.c4 * uh * uh);
  return cb + cs * z * q;
}

double ParametricModel::rate(double u, double* dr_du) const {
  const double uh = u - params_.c2;
  const double root = std::sqrt(uh * uh + params_.cg * params_.cg);
  if (dr_du) *dr_du = params_.c7 * (uh / root + params_.c8);
  return params_.c7 * (root - params_.cg + params_.c8 * uh) + params_.c9;
}

double ParametricModel::tau(const ParametricInputs& in) const { return 1.0 + params_.c6 * in.volume * kCc; }

double ParametricModel::pressureRate(double p, double u, const ParametricInputs& in) const {
  const double t = tau(in);
  return (steadyState(u, in) - p) * rate(u) / t + params_.c5 * in.volume_rate * kCc * p / t;
}

double ParametricModel::step(double p, double u, double dt, const ParametricInputs& in, double* dp_dp,
                             double* dp_du) const {
  // pdot = A - k p with A = s r / tau, k = (r - c5 vdot) / tau.
  double ds, dr;
  const double s = steadyState(u, in, &ds);
  const double r = rate(u, &dr);
  const double inv_tau = 1.0 / tau(in);
  const double A = s * r * inv_tau;
  const double k = (r - params_.c5 * in.volume_rate * kCc) * inv_tau;
  const double x = k * dt;
  const double E = std::exp(-x);
  // E1 = (1 - exp(-k dt)) / k and its k-derivative, by series near k = 0.
  double E1, dE1;
  if (std::abs(x) < 1e-4) {
    E1 = dt * (1.0 - x * (0.5 - x / 6.0));
    dE1 = dt * dt * (-0.5 + x / 3.0);
  } else {
    E1 = -std::expm1(-x) / k;
    dE1 = (dt * E - E1) / k;
  }
  if (dp_dp) *dp_dp = E;
  if (dp_du) {
    const double dA = (ds * r + s * dr) * inv_tau;
    const double dk = dr * inv_tau;
    *dp_du = dA * E1 + (A * dE1 - dt * p * E) * dk;
  }
  return p * E + A * E1;
}

double ParametricModel::stepDelayed(double p, double w, double u, double dt, const ParametricInputs& in,
                                    double* dp_dp, double* dp_dw, double* dp_du) const {
  const double d = std::min(params_.td, dt);
  if (d <= 0.0) {
    if (dp_dw) *dp_dw = 0.0;
    return step(p, u, dt, in, dp_dp, dp_du);
  }
  double a1, b1, a2, b2;
  const double mid = step(p, w, d, in, &a1, &b1);
  if (d >= dt) {
    if (dp_dp) *dp_dp = a1;
    if (dp_dw) *dp_dw = b1;
    if (dp_du) *dp_du = 0.0;
    return mid;
  }
  const double next = step(mid, u, dt - d, in, &a2, &b2);
  if (dp_dp) *dp_dp = a2 * a1;
  if (dp_dw) *dp_dw = a2 * b1;
  if (dp_du) *dp_du = b2;
  return next;
}

double ParametricModel::inverseSteadyState(double p_des, const ParametricInputs& in, double u_min,
                                           double u_max) const {
  if (p_des <= steadyState(u_min, in)) return u_min;
  if (p_des >= steadyState(u_max, in)) return u_max;
  // s is monotone increasing: bisection-safeguarded Newton.
  double lo = u_min, hi = u_max, u = std::clamp(params_.c2, lo, hi);
  for (int it = 0; it < 60; ++it) {
    double ds;
    const double e = steadyState(u, in, &ds) - p_des;
    if (e > 0) hi = u; else lo = u;
    if (std::abs(e) < 1e-3 || hi - lo < 1e-9) break;
    double next = ds > 0 ? u - e / ds : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    u = next;
  }
  return u;
}

}  // namespace adroit::pneumatics
