// Parametric pressure models of thesis chapter 5 (eq. 5.4's family), two forms:
//
// Eq55 (eq. 5.5; eq. 5.7 is the case c5 = c6 = 0):
//   pdot = (s(u) - p) r(u) / tau + c5 vdot p / tau,  tau = 1 + c6 v
//   s(u) = c_b + c_s sigmoid(c3 uh + c4 uh^3),  r(u) = c7 (sabs(uh) + c8 uh) + c9
//   uh = u - c2, sigmoid(z) = z / sqrt(1 + z^2), sabs(z) = sqrt(z^2 + cg^2) - cg
//   c_b = (P_supply + P_room) / 2, c_s = (P_supply - P_room) / 2 (real-time inputs)
// Volume enters as tau = 1 + c6 v (the text's constant tau = 1 + c6 cannot express the
// volume dependence eq. 5.4 describes); v and vdot are in cm^3 and cm^3/s. Linear in p, so
// a step with constant inputs is integrated exactly. Fitted c6 are ~1e6 (tau ~ c6 v), and
// c5, c7, c9 scale with it: the parametrisation is scale-degenerate.
//
// Saturating (the thin-port chamber's shape in eq. 5.4's form, README "Parametric model"):
//   pdot = k (s* - p) / (1 + |s* - p| / e),  e = e_fill if p < s* else e_exhaust
//   k = (r(u) - c5 vdot) lambda(v),  s* = s(u) r(u) / (r(u) - c5 vdot)
//   r(u) = (c7 (sabs(uh) + c8 uh) + c9) / (1 + sabs(uh) / u_sat),  lambda = (1 + v0) / (v + v0)
// Far from equilibrium the rate saturates at k e (the choked fill of a thin port runs at a
// constant rate); near it the approach is eq. 5.5's exponential. r(u) saturates in |u| as
// the Gompertz port areas do. lambda is 1 at v = 1 cm^3, so c5, c7, c9 are rates at 1 cm^3
// and v0 (cm^3) alone sets the volume dependence (v0 = 0: rate ~ 1/v, the thin-port
// scaling; v0 large: none). With e_fill, e_exhaust, u_sat -> infinity and v0 = 1/c6 it is
// eq. 5.5 (c5, c7, c9 divided by 1 + c6 cm^3). The step is exact: x = |s* - p| / e obeys
// x + ln x = x0 + ln x0 - k t.
#pragma once

#include "adroit_pneumatics/flow.h"

namespace adroit::pneumatics {

enum class ParametricForm { kEq55, kSaturating };

struct ParametricParams {
  ParametricForm form = ParametricForm::kEq55;
  double c2 = 0.0;    // V, valve centre
  double c3 = 2.0;    // 1/V
  double c4 = 0.5;    // 1/V^3
  double c5 = 0.0;    // volume-rate coefficient, per cm^3 (physically about -kappa / v;
                      // saturating form: -kappa at 1 cm^3)
  double c6 = 0.0;    // (cm^3)^-1, eq. 5.5 only: tau = 1 + c6 v
  double c7 = 100.0;  // 1/(s V), rate growth with |u| (saturating form: at 1 cm^3)
  double c8 = 0.0;    // asymmetry of the rate between inlet and exhaust
  double c9 = 20.0;   // 1/s, rate at the centre (saturating form: at 1 cm^3)
  double cg = 0.2;    // V, smoothing of |uh|
  double td = 0.0;    // s, input dead time (tube transport delay, fig. 3.8), in [0, 0.05]:
                      // a command acts td after it is issued (stepDelayed)
  // Saturating form only:
  double v0 = 0.1;          // cm^3, lambda(v) = (1 + v0) / (v + v0), >= 0
  double u_sat = 3.0;       // V, saturation of the rate in |u|, > 0
  double e_fill = 300e3;    // Pa, |s* - p| beyond which filling runs at a constant rate, > 0
  double e_exhaust = 1e6;   // Pa, the same for exhausting, > 0
  // Throws std::invalid_argument naming the first bad field (non-finite, cg <= 0,
  // c9 <= 0, or |c8| >= 1 which would let the rate go negative; saturating form: v0 < 0,
  // u_sat, e_fill, e_exhaust <= 0).
  void validate() const;
};

// The saturating form equal to an eq. 5.5 set with c6 > 0 except for the saturation (e_fill,
// e_exhaust, u_sat as given); c6 = 0 (no volume dependence) maps to v0 = 1e6 cm^3.
ParametricParams saturatingFromEq55(const ParametricParams& eq55, double e_fill, double e_exhaust, double u_sat);

struct ParametricInputs {
  double volume = 0;        // m^3
  double volume_rate = 0;   // m^3/s
  double supply = 620e3;    // Pa
  double room = constants::kAtmosphere;  // Pa
};

class ParametricModel {
 public:
  explicit ParametricModel(const ParametricParams& params = {});
  const ParametricParams& params() const { return params_; }

  double steadyState(double u, const ParametricInputs& in, double* ds_du = nullptr) const;
  double rate(double u, double* dr_du = nullptr) const;  // r(u) > 0, 1/s
  double pressureRate(double p, double u, const ParametricInputs& in) const;

  // What one command contributes to a step with the inputs held: the linear part
  // pdot = a - k p (eq. 5.5; the saturating form's s* = a / k) and its u-derivatives. A
  // rollout reuses them for the steps a command acts in (the controller caches them).
  struct CommandTerms {
    double a = 0, da = 0, k = 0, dk = 0;
  };
  CommandTerms terms(double u, const ParametricInputs& in) const;
  // Exact solution after dt from p under one command's terms; optional d/dp and d/du.
  double advance(double p, const CommandTerms& t, double dt, double* dp_dp = nullptr, double* dp_du = nullptr) const;

  // Exact solution after dt with u, v, vdot, supply held; optional derivatives of the
  // result wrt the start pressure and the command (used by iLQG).
  double step(double p, double u, double dt, const ParametricInputs& in, double* dp_dp = nullptr,
              double* dp_du = nullptr) const;

  // Step of dt in which the previous command w still acts for the first min(td, dt) (the
  // dead time of the tube) and u for the rest; exact for piecewise-constant commands when
  // td <= dt. With td = 0 it equals step(p, u, ...). Optional derivatives wrt p, w, u.
  double stepDelayed(double p, double w, double u, double dt, const ParametricInputs& in, double* dp_dp = nullptr,
                     double* dp_dw = nullptr, double* dp_du = nullptr) const;

  // Command whose steady state is p_des (Newton on the monotone s(u)), clamped to
  // [u_min, u_max]; targets outside the reachable range give the nearer limit.
  double inverseSteadyState(double p_des, const ParametricInputs& in, double u_min, double u_max) const;

 private:
  double linearAdvance(double p, const CommandTerms& t, double dt, double* dp_dp, double* dp_du) const;
  double saturatingAdvance(double p, const CommandTerms& t, double dt, double* dp_dp, double* dp_du) const;
  ParametricParams params_;
};

}  // namespace adroit::pneumatics
