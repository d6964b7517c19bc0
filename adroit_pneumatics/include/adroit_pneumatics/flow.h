// Thin-plate port flow (thesis eq. 4.1-4.5, 5.1) and the Gompertz valve port areas
// (eq. 4.13, table 4.4). SI units: Pa absolute, m^2, kg/s.
#pragma once

#include <array>
#include <cmath>

#include "adroit_description/cylinder_catalogue.h"
#include "adroit_pneumatics/fast_exp.h"

namespace adroit::pneumatics {

// Physical constants of table 4.1.
namespace constants {
constexpr double kMolarMass = 0.029;      // kg/mol, air
constexpr double kGasConstant = 8.31;     // J/(mol K)
constexpr double kTemperature = 293.0;    // K, isothermal chamber assumption
constexpr double kDischarge = 0.72;       // C
constexpr double kCompressibility = 0.99; // Z
constexpr double kKappa = 1.4;            // specific heat ratio, polytropic index
constexpr double kAtmosphere = description::kAtmosphericPressure;  // Pa absolute, adroit_description's
constexpr double kSpecificGas = kGasConstant / kMolarMass;  // R_s, J/(kg K)
constexpr double kRsT = kSpecificGas * kTemperature;         // R_s T, J/kg
}  // namespace constants

// alpha, beta and the choke ratio theta of eq. 4.1-4.2.
double flowAlpha();
double flowBeta();
double chokeRatio();

// z(p_u, p_d) of eq. 5.1c for p_u >= p_d > 0 (kg/(s m^2)).
double flowZ(double p_up, double p_down);

// phi(p_u, p_d) of eq. 5.1b: mass flow per unit area from the first to the second
// pressure, antisymmetric (the chapter-4 form -z(p_u, p_d) is the slip noted in the notes).
// Evaluated with std::pow: the reference used by tests and identification.
double flowPhi(double p_up, double p_down);

// Same function from a table of the normalised flow, cheap enough for 48 cylinders in a
// simulation step. Also returns the partial derivatives wrt both pressures.
// Its error against flowPhi is below 1e-4 of the choked flow beta * p_up (tested).
class FlowTable {
 public:
  FlowTable();
  double phi(double p1, double p2) const {
    double d1, d2;
    return phi(p1, p2, &d1, &d2);
  }
  double phi(double p1, double p2, double* d_p1, double* d_p2) const {
    double dg;
    if (p1 >= p2) {
      const double r = p2 / p1;
      const double gv = g(r, &dg);
      *d_p1 = gv - r * dg;
      *d_p2 = dg;
      return p1 * gv;
    }
    const double r = p1 / p2;
    const double gv = g(r, &dg);
    *d_p1 = -dg;
    *d_p2 = -(gv - r * dg);
    return -p2 * gv;
  }
  // Normalised flow g(r) = phi(p_u, r p_u) / p_u for r = p_d / p_u in [0, 1], and dg/dr.
  double g(double r, double* dg) const {
    if (r <= r_choke_) {
      *dg = 0.0;
      return beta_;
    }
    const double x = (r - r_choke_) * inv_step_;
    const int i = x < kSegments - 1 ? static_cast<int>(x) : kSegments - 1;
    const double t = x - i;
    *dg = dg_[i];
    // g itself is smooth away from r = 1: interpolate it directly (no sqrt); only the
    // last kEdge segments, next to the square-root edge, interpolate h.
    if (i < kSegments - kEdge) return g_[i] + (g_[i + 1] - g_[i]) * t;
    return alpha_ * std::sqrt(h_[i] + (h_[i + 1] - h_[i]) * t);
  }

 private:
  static constexpr int kSegments = 512;
  static constexpr int kEdge = 16;
  // h = (g / alpha)^2 is smooth near r = 1 where g has a square-root edge, so h is what
  // gets interpolated.
  // dg_ is g' at each segment's midpoint: g' = alpha h' / (2 sqrt h) is unbounded at r = 1,
  // and the integrator only uses it as a first guess of the Jacobian (it corrects with a
  // secant), so a per-segment constant is enough.
  double r_choke_ = 0, inv_step_ = 0, alpha_ = 0, beta_ = 0;
  std::array<double, kSegments + 2> h_{};
  std::array<double, kSegments + 2> g_{};
  std::array<double, kSegments + 1> dg_{};
};

// Shared instance (immutable after construction).
const FlowTable& flowTable();

// Port area as a function of the valve command in volts (eq. 4.13):
// area = offset + a exp(-b exp(-c (u + d))). offset is the leak of the closed port.
struct GompertzArea {
  double offset = 0;  // m^2
  double a = 0;       // m^2
  double b = 0;
  double c = 0;       // 1/V; > 0 for an inlet, < 0 for an exhaust
  double d = 0;       // V
  double operator()(double volts) const {
    const double inner = b * fastExp(-c * (volts + d));
    return offset + a * fastExp(-inner);
  }
};

// The Gompertz shape H(x) = exp(-b exp(-x)) of one b, tabulated on a uniform grid in
// x = c (u + d) with linear interpolation, for the plant's inner loop (the exact form costs
// two nested exponentials per port and command change). Absolute error of H below 1e-5
// (so of the area below 1e-5 a; tested against GompertzArea).
class GompertzTable {
 public:
  explicit GompertzTable(double b);
  double b() const { return b_; }
  double operator()(double x) const {
    if (!(x > x_lo_)) return 0.0;  // H < 1e-17 below the grid
    if (x >= x_hi_) return 1.0;    // 1 - H < 1e-7 above the grid
    const double s = (x - x_lo_) * inv_step_;
    const int i = static_cast<int>(s);
    const double t = s - i;
    return h_[i] + (h_[i + 1] - h_[i]) * t;
  }

 private:
  static constexpr int kSegments = 4096;
  double b_ = 0, x_lo_ = 0, x_hi_ = 0, inv_step_ = 0;
  std::array<double, kSegments + 2> h_{};
};

// Shared table for a given b (built once per distinct b, thread-safe).
const GompertzTable& gompertzTable(double b);

struct ValveParams {
  GompertzArea inlet;    // supply -> chamber
  GompertzArea exhaust;  // chamber -> room
};

// Valves 1 and 2 of table 4.4; any other number throws std::invalid_argument.
ValveParams valveParams(int which);

}  // namespace adroit::pneumatics
