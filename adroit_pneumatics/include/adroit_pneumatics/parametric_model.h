// Parametric pressure model (thesis eq. 5.5; eq. 5.7 is the case c5 = c6 = 0):
//   pdot = (s(u) - p) r(u) / tau + c5 vdot p / tau
//   s(u) = c_b + c_s sigmoid(c3 uh + c4 uh^3),  r(u) = c7 (sabs(uh) + c8 uh) + c9
//   uh = u - c2, sigmoid(z) = z / sqrt(1 + z^2), sabs(z) = sqrt(z^2 + cg^2) - cg
//   c_b = (P_supply + P_room) / 2, c_s = (P_supply - P_room) / 2 (real-time inputs)
// Volume enters as tau = 1 + c6 v (the text's constant tau = 1 + c6 cannot express the
// volume dependence eq. 5.4 describes); v and vdot are in cm^3 and cm^3/s so c5, c6 are
// of order one. Linear in p, so a step with constant inputs is integrated exactly.
#pragma once

#include "adroit_pneumatics/flow.h"

namespace adroit::pneumatics {

struct ParametricParams {
  double c2 = 0.0;    // V, valve centre
  double c3 = 2.0;    // 1/V
  double c4 = 0.5;    // 1/V^3
  double c5 = 0.0;    // (cm^3)^-1, volume-rate coefficient (physically about -kappa / v)
  double c6 = 0.0;    // (cm^3)^-1, tau = 1 + c6 v
  double c7 = 100.0;  // 1/(s V), rate growth with |u|
  double c8 = 0.0;    // asymmetry of the rate between inlet and exhaust
  double c9 = 20.0;   // 1/s, rate at the centre
  double cg = 0.2;    // V, smoothing of |uh|
  double td = 0.0;    // s, input dead time (tube transport delay, fig. 3.8), in [0, 0.05]:
                      // a command acts td after it is issued (stepDelayed)
  // Throws std::invalid_argument naming the first bad field (non-finite, cg <= 0,
  // c9 <= 0, or |c8| >= 1 which would let the rate go negative).
  void validate() const;
};

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
  double tau(const ParametricInputs& in) const;
  double pressureRate(double p, double u, const ParametricInputs& in) const;

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
  ParametricParams params_;
};

}  // namespace adroit::pneumatics
