#include "adroit_pneumatics/parametric_model.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "adroit_pneumatics/fast_exp.h"

namespace adroit::pneumatics {

namespace {
constexpr double kCc = 1e6;  // m^3 -> cm^3
// Saturating form: the compression term may lower k = (r - c5 vdot) lambda at most to this
// fraction of the valve's own rate r lambda. k -> 0 would send s* = a / k to infinity; it
// only happens when the piston compresses the chamber faster than the valve can act, far
// outside any identification data.
constexpr double kMinRateFraction = 0.25;
}  // namespace

void ParametricParams::validate() const {
  const bool saturating = form == ParametricForm::kSaturating;
  const std::pair<const char*, double> fields[] = {{"c2", c2}, {"c3", c3}, {"c4", c4}, {"c5", c5}, {"c6", c6},
                                                   {"c7", c7}, {"c8", c8}, {"c9", c9}, {"cg", cg}, {"td", td},
                                                   {"v0", v0}, {"u_sat", u_sat}, {"e_fill", e_fill},
                                                   {"e_exhaust", e_exhaust}};
  for (const auto& [name, value] : fields)
    if (!std::isfinite(value)) throw std::invalid_argument(std::string("parametric model: ") + name + " is not finite");
  if (!(cg > 0)) throw std::invalid_argument("parametric model: cg must be > 0");
  if (!(c9 > 0)) throw std::invalid_argument("parametric model: c9 must be > 0 (rate at the valve centre)");
  if (!(c7 >= 0)) throw std::invalid_argument("parametric model: c7 must be >= 0");
  if (!(std::abs(c8) < 1)) throw std::invalid_argument("parametric model: |c8| must be < 1 (rate must stay > 0)");
  if (!(td >= 0 && td <= 0.05)) throw std::invalid_argument("parametric model: td must be in [0, 0.05] s");
  if (!(c3 > 0) || !(c4 >= 0)) throw std::invalid_argument("parametric model: c3 must be > 0 and c4 >= 0 (monotone s(u))");
  if (!saturating) return;
  if (!(v0 > 0)) throw std::invalid_argument("parametric model: v0 must be > 0 (cm^3)");
  if (!(u_sat > 0)) throw std::invalid_argument("parametric model: u_sat must be > 0");
  if (!(e_fill > 0)) throw std::invalid_argument("parametric model: e_fill must be > 0");
  if (!(e_exhaust > 0)) throw std::invalid_argument("parametric model: e_exhaust must be > 0");
}

ParametricParams saturatingFromEq55(const ParametricParams& eq55, double e_fill, double e_exhaust, double u_sat) {
  ParametricParams q = eq55;
  q.form = ParametricForm::kSaturating;
  // (r / (1 + c6 v)) = (r / (1 + c6)) (1 + v0) / (v + v0) with v0 = 1 / c6.
  const double scale = eq55.c6 > 0 ? 1.0 / (1.0 + eq55.c6) : 1.0;
  q.v0 = eq55.c6 > 0 ? 1.0 / eq55.c6 : 1e6;
  q.c5 *= scale, q.c7 *= scale, q.c9 *= scale;
  q.c6 = 0.0;
  q.e_fill = e_fill, q.e_exhaust = e_exhaust, q.u_sat = u_sat;
  return q;
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
  const double sabs = root - params_.cg, dsabs = uh / root;
  const double linear = params_.c7 * (sabs + params_.c8 * uh) + params_.c9;
  const double dlinear = params_.c7 * (dsabs + params_.c8);
  if (params_.form == ParametricForm::kEq55) {
    if (dr_du) *dr_du = dlinear;
    return linear;
  }
  const double inv_sat = 1.0 / (1.0 + sabs / params_.u_sat);
  if (dr_du) *dr_du = (dlinear - linear * inv_sat * dsabs / params_.u_sat) * inv_sat;
  return linear * inv_sat;
}

ParametricModel::CommandTerms ParametricModel::terms(double u, const ParametricInputs& in) const {
  double ds, dr;
  const double s = steadyState(u, in, &ds);
  const double r = rate(u, &dr);
  const double vdot = in.volume_rate * kCc;
  // Volume factor: eq. 5.5's 1 / tau, or the saturating form's lambda(v).
  const double factor = params_.form == ParametricForm::kEq55
                            ? 1.0 / (1.0 + params_.c6 * in.volume * kCc)
                            : (1.0 + params_.v0) / (std::max(in.volume * kCc, 0.0) + params_.v0);
  CommandTerms t;
  t.a = s * r * factor;
  t.da = (ds * r + s * dr) * factor;
  t.k = (r - params_.c5 * vdot) * factor;
  t.dk = dr * factor;
  if (params_.form == ParametricForm::kSaturating && t.k < kMinRateFraction * r * factor) {
    t.k = kMinRateFraction * r * factor;
    t.dk = kMinRateFraction * dr * factor;
  }
  return t;
}

double ParametricModel::pressureRate(double p, double u, const ParametricInputs& in) const {
  const CommandTerms t = terms(u, in);
  if (params_.form == ParametricForm::kEq55) return t.a - t.k * p;
  const double e = t.a / t.k - p;
  return t.k * e / (1.0 + std::abs(e) / (e > 0 ? params_.e_fill : params_.e_exhaust));
}

double ParametricModel::advance(double p, const CommandTerms& t, double dt, double* dp_dp, double* dp_du) const {
  return params_.form == ParametricForm::kEq55 ? linearAdvance(p, t, dt, dp_dp, dp_du)
                                               : saturatingAdvance(p, t, dt, dp_dp, dp_du);
}

double ParametricModel::linearAdvance(double p, const CommandTerms& t, double dt, double* dp_dp, double* dp_du) const {
  // pdot = a - k p: p(dt) = p E + a E1 with E = exp(-k dt), E1 = (1 - E) / k.
  const double x = t.k * dt;
  const double E = fastExp(-x);
  // E1 and its k-derivative by series near k = 0.
  double E1, dE1;
  if (std::abs(x) < 1e-4) {
    E1 = dt * (1.0 - x * (0.5 - x / 6.0));
    dE1 = dt * dt * (-0.5 + x / 3.0);
  } else {
    const double inv_k = 1.0 / t.k;
    E1 = (1.0 - E) * inv_k;
    dE1 = (dt * E - E1) * inv_k;
  }
  if (dp_dp) *dp_dp = E;
  if (dp_du) *dp_du = t.da * E1 + (t.a * dE1 - dt * p * E) * t.dk;
  return p * E + t.a * E1;
}

double ParametricModel::saturatingAdvance(double p, const CommandTerms& t, double dt, double* dp_dp,
                                          double* dp_du) const {
  // With e = s* - p (its sign is kept: p never crosses s*) and x = |e| / e_c,
  // xdot = -k x / (1 + x), so x + ln x falls linearly: x + ln x = y = x0 + ln x0 - k dt.
  const double s_eq = t.a / t.k;
  const double e0 = s_eq - p;
  const double sign = e0 >= 0 ? 1.0 : -1.0;
  const double ec = e0 >= 0 ? params_.e_fill : params_.e_exhaust;
  const double x0 = std::abs(e0) / ec, kdt = t.k * dt;
  double x = 0, dp_ds, dp_dk = 0;
  if (x0 > 0) {
    // Newton on xi = ln x for xi + e^xi = y: convex and increasing, so from the upper bound
    // xi = y - x0 e^{-k dt} (x is at least the linear decay x0 e^{-k dt}) it falls to the
    // root without overshoot; 2-6 iterations.
    const double ln_x0 = std::log(x0);
    const double y = x0 + ln_x0 - kdt;
    double xi = y - x0 * fastExp(-kdt);
    for (int it = 0; it < 60; ++it) {
      x = fastExp(xi);
      const double delta = (xi + x - y) / (1.0 + x);
      xi -= delta;
      if (std::abs(delta) <= 1e-14 * std::max(1.0, std::abs(xi))) break;
    }
    x = fastExp(xi);
    // dx/dx0 = (x / x0) (1 + x0) / (1 + x); x / x0 = e^{xi - ln x0} stays finite as x0 -> 0.
    const double dx_dx0 = fastExp(xi - ln_x0) * (1.0 + x0) / (1.0 + x);
    dp_ds = 1.0 - dx_dx0;
    if (dp_dp) *dp_dp = dx_dx0;
    dp_dk = sign * ec * dt * x / (1.0 + x);
  } else {
    const double E = fastExp(-kdt);
    dp_ds = 1.0 - E;
    if (dp_dp) *dp_dp = E;
  }
  if (dp_du) *dp_du = dp_ds * (t.da - s_eq * t.dk) / t.k + dp_dk * t.dk;
  return s_eq - sign * ec * x;
}

double ParametricModel::step(double p, double u, double dt, const ParametricInputs& in, double* dp_dp,
                             double* dp_du) const {
  return advance(p, terms(u, in), dt, dp_dp, dp_du);
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
