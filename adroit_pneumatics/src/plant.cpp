#include "adroit_pneumatics/plant.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "adroit_description/cylinder_catalogue.h"

namespace adroit::pneumatics {

using namespace constants;

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kMinPressure = 1e3;  // Pa; keeps the flow function's ratios finite

// (exp(z) - 1) / z, finite at z = 0. Near zero (|z| <= 0.5, the usual non-stiff step) its
// Taylor series to z^9 (truncation < 3e-11 relative), which is cheaper than an exp and a
// division; beyond, the exp form (cancellation costs < 1e-15 there).
inline double phi1(double z) {
  if (std::abs(z) <= 0.5) {
    double p = 1.0 / 3628800.0;
    p = p * z + 1.0 / 362880.0;
    p = p * z + 1.0 / 40320.0;
    p = p * z + 1.0 / 5040.0;
    p = p * z + 1.0 / 720.0;
    p = p * z + 1.0 / 120.0;
    p = p * z + 1.0 / 24.0;
    p = p * z + 1.0 / 6.0;
    p = p * z + 0.5;
    return p * z + 1.0;
  }
  if (z < -37.0) return -1.0 / z;  // exp(z) < 1e-16: below the rounding of 1
  return (fastExp(z) - 1.0) / z;
}

// Right-hand side of eq. 5.3 with the tabulated flow; with_jacobian also gives d/dp.
// Written out for the usual orientation (room <= p <= supply) so only the flow-reversal
// cases take the general path.
template <bool with_jacobian>
__attribute__((always_inline)) inline double rhs(double p, const ChamberInputs& in, double gain, double volume_term, double* jac,
                  double* inflow, double inv_supply) {
  static const FlowTable& table = flowTable();
  double phi_in, din_p, phi_out, dout_p, dummy;
  if (p <= in.supply) {
    phi_in = in.supply * table.g(p * inv_supply, &din_p);
  } else {
    phi_in = table.phi(in.supply, p, &dummy, &din_p);
  }
  if (p >= in.room) {
    const double r = in.room / p;
    double dg;
    const double gv = table.g(r, &dg);
    phi_out = p * gv;
    dout_p = gv - r * dg;
  } else {
    phi_out = table.phi(p, in.room, &dout_p, &dummy);
  }
  if (with_jacobian) *jac = gain * (in.inlet_area * din_p - in.outlet_area * dout_p) - volume_term;
  *inflow = in.inlet_area * phi_in;
  return gain * (*inflow - in.outlet_area * phi_out) - volume_term * p;
}
}  // namespace

CylinderSpec cylinderSpec(const std::string& type) {
  // The catalogue is adroit_description's (config/cylinders.yaml, the one source of the
  // cylinder data; its comments give the values' sources and assumptions).
  const description::CylinderType* c = description::findCylinderType(type);
  if (!c) {
    std::string known;
    for (const auto& entry : description::kCylinderCatalogue) known += (known.empty() ? "" : ", ") + std::string(entry.type);
    throw std::invalid_argument("cylinderSpec: unknown cylinder type '" + type + "' (known: " + known + ")");
  }
  CylinderSpec s;
  s.type = type;
  s.bore_diameter = c->bore_diameter;
  s.bore_area = kPi * c->bore_diameter * c->bore_diameter / 4.0;
  s.stroke = c->stroke;
  s.dead_volume = c->dead_volume;
  s.leak_area = kPi * c->leak_diameter * c->leak_diameter / 4.0;
  s.valve = valveParams(c->valve);
  for (GompertzArea* port : {&s.valve.inlet, &s.valve.exhaust}) port->offset *= c->valve_scale, port->a *= c->valve_scale;
  return s;
}

double chamberPressureRate(double p, const ChamberInputs& in) {
  const double mdot = in.inlet_area * flowPhi(in.supply, p) - in.outlet_area * flowPhi(p, in.room);
  return kKappa / in.volume * (kRsT * mdot - p * in.volume_rate);
}

namespace {
// The stages of chamberStep, shared by the scalar function and the plant's batched loop
// (which runs each stage over all cylinders before the next, so the independent chains of
// 48 cylinders overlap in the CPU instead of waiting on each other's sqrt/div/exp latency).
// Both paths do the same operations in the same order: the plant's result is bit-identical
// to calling chamberStep per cylinder.
struct Coeffs {
  double gain, volume_term, inv_supply;
};
inline Coeffs coeffs(const ChamberInputs& in, double inv_supply) {
  const double inv_volume = 1.0 / in.volume;
  return {kKappa * kRsT * inv_volume, kKappa * in.volume_rate * inv_volume, inv_supply};
}
// Predictor: exact solution of the linearisation at p0. Bounded so the secant below is
// taken over a physically meaningful interval.
inline double predictor(double p0, double dt, const ChamberInputs& in, double f0, double j0) {
  const double lo = 0.5 * std::min(p0, in.room);
  const double hi = 2.0 * std::max(p0, in.supply);
  return std::clamp(p0 + dt * phi1(j0 * dt) * f0, std::max(lo, kMinPressure), hi);
}
// Corrector: same exponential step with the secant slope over [p0, p1]. Returns p2 and
// z = the steeper slope times dt: the step is stiff (stiffTail decides) when z <= -1.
inline double corrector(double p0, double p1, double dt, double f0, double f1, double j0, double* z) {
  const double js = (p1 != p0) ? (f1 - f0) / (p1 - p0) : j0;
  *z = std::min(j0, js) * dt;  // stiff when <= -1 (NaN counts as stiff)
  return std::max(p0 + dt * phi1(js * dt) * f0, kMinPressure);
}
// The equilibrium of f between pa and pb (f(pa), f(pb) of opposite signs) by Illinois
// regula falsi, to within 1 Pa or a residual that moves p by < 0.5 Pa over dt.
inline double equilibrium(double pa, double fa, double pb, double fb, double dt, const ChamberInputs& in,
                          const Coeffs& k) {
  double root = pb, j, q;
  int side = 0;
  for (int it = 0; it < 40; ++it) {
    root = (pa * fb - pb * fa) / (fb - fa);
    const double fr = rhs<false>(root, in, k.gain, k.volume_term, &j, &q, k.inv_supply);
    if (std::abs(pb - pa) < 1.0 || fr == 0.0) break;
    if ((fr > 0) == (fb > 0)) {
      pb = root, fb = fr;
      if (side == -1) fa *= 0.5;
      side = -1;
    } else {
      pa = root, fa = fr;
      if (side == 1) fb *= 0.5;
      side = 1;
    }
    if (std::abs(fr) * dt < 0.5) break;
  }
  return root;
}
// Stiff (small volume, or the square-root edge of the flow near equilibrium). With
// constant inputs the scalar solution is monotone and cannot cross an equilibrium; if a
// stage crossed one, find that root of f (Illinois regula falsi on the bracket) and take
// the exponential approach to it with the secant rate from p0. Exact for linear f, never
// overshoots, and lands on the quasi-static equilibrium in the stiff limit.
// Needs f2 = f(p2) only when f1 has the sign of f0 and p2 is not between p0 and p1 (see
// needF2; otherwise it is unused).
inline double stiffTail(double p0, double p1, double p2, double dt, double f0, double f1, double f2,
                        const ChamberInputs& in, const Coeffs& k) {
  double pa = p0, fa = f0, pb = p1, fb = f1;
  if ((f1 > 0) == (f0 > 0)) {
    // f is monotone in p (flow decreasing, compression term small against it), so with f0
    // and f1 of one sign nothing between p0 and p1 crosses zero.
    if ((p2 - p0) * (p2 - p1) <= 0.0) return p2;
    pa = p1, fa = f1;
    pb = p2;
    fb = f2;
    if ((fb > 0) == (f0 > 0)) return p2;  // no crossing: the corrector is monotone
  }
  const double root = equilibrium(pa, fa, pb, fb, dt, in, k);
  if (root == p0) return p0;
  const double rate = f0 / (p0 - root);  // < 0: secant slope from p0 to the equilibrium
  return std::max(root + (p0 - root) * fastExp(rate * dt), kMinPressure);
}
inline bool needF2(double p0, double p1, double p2, double f0, double f1) {
  return ((f1 > 0) == (f0 > 0)) && (p2 - p0) * (p2 - p1) > 0.0;
}

// A step is redone by transient() when it moves the pressure more than the threshold and the
// chamber is fast against dt (z = slope * dt below -0.25: a small volume or a steep flow
// edge). Slower chambers stay with the two-stage step, which is second order there: with
// -0.1 instead the worst error over the catalogue's cylinders was the same and the 48-cylinder
// step cost 15 % more (pneumatics_bench --only plant).
inline bool needsTransient(double change, double z, double threshold) {
  return std::abs(change) > threshold && !(z > -0.25);
}

// log(1 + x) / x, finite at x = 0.
inline double log1pOverX(double x) { return std::abs(x) < 1e-6 ? 1.0 - 0.5 * x : std::log1p(x) / x; }

// transientStep with the coefficients and f0 = f(p0) at hand (see plant.h).
inline double transient(double p0, double dt, const ChamberInputs& in, const Coeffs& k, double f0) {
  if (f0 == 0.0) return p0;
  double j, q;
  const double far = f0 > 0 ? 2.0 * std::max(p0, in.supply) : std::max(0.5 * std::min(p0, in.room), kMinPressure);
  const double f_far = rhs<false>(far, in, k.gain, k.volume_term, &j, &q, k.inv_supply);
  if ((f_far > 0) == (f0 > 0)) return std::nan("");
  const double root = equilibrium(p0, f0, far, f_far, dt, in, k);
  // Segment ends as fractions of the way from p0 to p*: 1/8 and 1/2 resolve the edge at p0,
  // then the distance to p* halves (3/4 ... 1 - 2^-8) to resolve the approach.
  static constexpr double kFractions[] = {0.125, 0.5, 0.75, 0.875, 0.9375, 0.96875, 0.984375, 0.9921875, 0.99609375};
  double p = p0, fp = f0, t = 0;
  for (double fraction : kFractions) {
    const double next = p0 + (root - p0) * fraction;
    const double fn = rhs<false>(next, in, k.gain, k.volume_term, &j, &q, k.inv_supply);
    if (fn == 0.0 || (fn > 0) != (f0 > 0)) break;  // at p* within the root's tolerance
    // f linear on [p, next]: the time across is (next - p) / fp * log(fn / fp) / (fn / fp - 1).
    const double span = (next - p) / fp * log1pOverX(fn / fp - 1.0);
    if (t + span >= dt) {
      const double h = dt - t;
      return std::max(p + fp * h * phi1((fn - fp) / (next - p) * h), kMinPressure);
    }
    t += span;
    p = next;
    fp = fn;
  }
  if (p == root) return root;
  return std::max(root + (p - root) * fastExp(fp / (p - root) * (dt - t)), kMinPressure);
}
}  // namespace

double transientStep(double p0, double dt, const ChamberInputs& in) {
  const Coeffs k = coeffs(in, 1.0 / in.supply);
  double j, q;
  return transient(p0, dt, in, k, rhs<false>(p0, in, k.gain, k.volume_term, &j, &q, k.inv_supply));
}

// The two-stage step; a transient larger than the threshold is redone by transient().
double chamberStep(double p0, double dt, const ChamberInputs& in, double* inlet_mass_flow, double transient_threshold) {
  const Coeffs k = coeffs(in, 1.0 / in.supply);
  double j0, j1, q0, q1;
  const double f0 = rhs<true>(p0, in, k.gain, k.volume_term, &j0, &q0, k.inv_supply);
  if (inlet_mass_flow) *inlet_mass_flow = q0;
  if (f0 == 0.0) return p0;
  const double p1 = predictor(p0, dt, in, f0, j0);
  const double f1 = rhs<false>(p1, in, k.gain, k.volume_term, &j1, &q1, k.inv_supply);
  double z;
  double p2 = corrector(p0, p1, dt, f0, f1, j0, &z);
  if (!(z > -1.0)) {
    const double f2 = needF2(p0, p1, p2, f0, f1) ? rhs<false>(p2, in, k.gain, k.volume_term, &j1, &q1, k.inv_supply) : 0.0;
    p2 = stiffTail(p0, p1, p2, dt, f0, f1, f2, in, k);
  }
  if (needsTransient(p2 - p0, z, transient_threshold)) {
    const double exact = transient(p0, dt, in, k, f0);
    if (std::isfinite(exact)) return exact;
  }
  return p2;
}

PneumaticPlant::PneumaticPlant(std::vector<CylinderSpec> specs, const SupplyParams& supply,
                               std::uint64_t seed, const PlantOptions& options)
    : specs_(std::move(specs)), supply_params_(supply), options_(options) {
  if (specs_.empty()) throw std::invalid_argument("PneumaticPlant: no cylinders");
  if (!(supply.nominal_pressure > supply.atmospheric_pressure) || !(supply.atmospheric_pressure > 0))
    throw std::invalid_argument("PneumaticPlant: supply.nominal_pressure must exceed atmospheric_pressure > 0");
  if (!(supply.time_constant > 0)) throw std::invalid_argument("PneumaticPlant: supply.time_constant must be > 0");
  if (!(options.tube_delay >= 0)) throw std::invalid_argument("PneumaticPlant: tube_delay must be >= 0");
  for (const auto& s : specs_) {
    if (!(s.bore_area > 0) || !(s.stroke > 0) || !(s.dead_volume > 0) || !(s.leak_area >= 0))
      throw std::invalid_argument("PneumaticPlant: cylinder '" + s.type +
                                  "' needs bore_area > 0, stroke > 0, dead_volume > 0, leak_area >= 0");
  }
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> unit(0.0, 1.0);
  for (auto& s : specs_) {
    const double scale_in = std::exp(options.area_spread * unit(rng));
    const double scale_out = std::exp(options.area_spread * unit(rng));
    const double shift = options.offset_spread * unit(rng);  // spool zero offset
    s.valve.inlet.a *= scale_in;
    s.valve.inlet.offset *= scale_in;
    s.valve.exhaust.a *= scale_out;
    s.valve.exhaust.offset *= scale_out;
    s.valve.inlet.d += shift;
    s.valve.exhaust.d += shift;
  }
  const std::size_t n = specs_.size();
  supply_pressure_ = supply.nominal_pressure;
  pressure_.assign(n, options.initial_pressure);
  history_time_.assign(1, -1e30);  // the initial command has always been there
  history_volts_.assign(n, std::clamp(options.initial_volts, -5.0, 5.0));
  applied_volts_.assign(n, std::nan(""));
  inlet_area_.assign(n, 0.0);
  outlet_area_.assign(n, 0.0);
  last_volts_ = history_volts_;
  auto fast = [](const GompertzArea& g) {
    FastPort f;
    f.offset = g.offset, f.a = g.a, f.c = g.c, f.cd = g.c * g.d;
    f.table = &gompertzTable(g.b);
    return f;
  };
  for (const auto& s : specs_) {
    fast_inlet_.push_back(fast(s.valve.inlet));
    fast_exhaust_.push_back(fast(s.valve.exhaust));
  }
}


double PneumaticPlant::tension(std::size_t i) const {
  return std::max(0.0, (pressure_[i] - supply_params_.atmospheric_pressure) * specs_[i].bore_area);
}

void PneumaticPlant::step(double dt, const double* volts, const double* travel, const double* travel_rate) {
  if (!(dt > 0) || !std::isfinite(dt)) return;
  const std::size_t n = specs_.size();
  // Push this step's command into the delay line.
  if (volts) {
    for (std::size_t i = 0; i < n; ++i)
      last_volts_[i] = std::isfinite(volts[i]) ? std::clamp(volts[i], -5.0, 5.0) : 0.0;
  }
  history_time_.push_back(time_);
  history_volts_.insert(history_volts_.end(), last_volts_.begin(), last_volts_.end());
  // The command acting now is the newest frame at least tube_delay old; drop older ones.
  const double cutoff = time_ - options_.tube_delay + 1e-9;
  std::size_t acting = 0;
  while (acting + 1 < history_time_.size() && history_time_[acting + 1] <= cutoff) ++acting;
  if (acting > 0) {
    history_time_.erase(history_time_.begin(), history_time_.begin() + acting);
    history_volts_.erase(history_volts_.begin(), history_volts_.begin() + acting * n);
  }
  const double* acting_volts = history_volts_.data();

  const double room = supply_params_.atmospheric_pressure;
  double total_inflow = 0.0;
  // Stage-by-stage over all cylinders (see chamberStep; same operations, same result).
  Work& w = work_;
  w.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const CylinderSpec& s = specs_[i];
    updateAreas(i, acting_volts[i]);
    double x = travel ? travel[i] : 0.0;
    double xdot = travel_rate ? travel_rate[i] : 0.0;
    if (!std::isfinite(x)) x = 0.0;
    if (!std::isfinite(xdot)) xdot = 0.0;
    // At an end stop the piston cannot move further out of range.
    if (x <= 0.0) { x = 0.0; xdot = std::max(0.0, xdot); }
    if (x >= s.stroke) { x = s.stroke; xdot = std::min(0.0, xdot); }
    ChamberInputs& in = w.in[i];
    in.supply = supply_pressure_;
    in.room = room;
    in.inlet_area = inlet_area_[i];
    in.outlet_area = outlet_area_[i];
    in.volume = s.dead_volume + s.bore_area * x;
    in.volume_rate = s.bore_area * xdot;
  }
  double dummy_j, dummy_q;
  const double inv_supply = 1.0 / supply_pressure_;  // the same for every cylinder
  for (std::size_t i = 0; i < n; ++i) {
    const Coeffs k = coeffs(w.in[i], inv_supply);
    w.gain[i] = k.gain;
    w.volume_term[i] = k.volume_term;
    w.f0[i] = rhs<true>(pressure_[i], w.in[i], k.gain, k.volume_term, &w.j0[i], &w.q0[i], inv_supply);
    total_inflow += std::max(0.0, w.q0[i]);
  }
  for (std::size_t i = 0; i < n; ++i)
    w.p1[i] = w.f0[i] == 0.0 ? pressure_[i] : predictor(pressure_[i], dt, w.in[i], w.f0[i], w.j0[i]);
  for (std::size_t i = 0; i < n; ++i)
    w.f1[i] = rhs<false>(w.p1[i], w.in[i], w.gain[i], w.volume_term[i], &dummy_j, &dummy_q, inv_supply);
  w.stiff.clear();
  for (std::size_t i = 0; i < n; ++i) {
    if (w.f0[i] == 0.0) { w.p2[i] = pressure_[i]; continue; }
    w.p2[i] = corrector(pressure_[i], w.p1[i], dt, w.f0[i], w.f1[i], w.j0[i], &w.z[i]);
    if (!(w.z[i] > -1.0)) w.stiff.push_back(i);
  }
  for (std::size_t i : w.stiff)
    w.f2[i] = needF2(pressure_[i], w.p1[i], w.p2[i], w.f0[i], w.f1[i])
                  ? rhs<false>(w.p2[i], w.in[i], w.gain[i], w.volume_term[i], &dummy_j, &dummy_q, inv_supply)
                  : 0.0;
  for (std::size_t i : w.stiff)
    w.p2[i] = stiffTail(pressure_[i], w.p1[i], w.p2[i], dt, w.f0[i], w.f1[i], w.f2[i], w.in[i], Coeffs{w.gain[i], w.volume_term[i], inv_supply});
  const double threshold = options_.transient_threshold;
  for (std::size_t i = 0; i < n; ++i) {
    if (needsTransient(w.p2[i] - pressure_[i], w.z[i], threshold)) {
      const double exact = transient(pressure_[i], dt, w.in[i], Coeffs{w.gain[i], w.volume_term[i], inv_supply}, w.f0[i]);
      if (std::isfinite(exact)) w.p2[i] = exact;
    }
    pressure_[i] = w.p2[i];
  }
  // Supply: first-order lag towards its flow-dependent set point (exact over dt).
  const double target = supply_enabled_
                            ? supply_params_.nominal_pressure - supply_params_.sag_per_mass_flow * total_inflow
                            : room;
  const double blend = -std::expm1(-dt / supply_params_.time_constant);
  supply_pressure_ = std::max(room, supply_pressure_ + (target - supply_pressure_) * blend);
  time_ += dt;
}

void PneumaticPlant::Work::resize(std::size_t n) {
  if (in.size() == n) return;
  in.resize(n);
  for (auto* v : {&gain, &volume_term, &f0, &j0, &q0, &p1, &f1, &p2, &f2, &z}) v->resize(n);
  stiff.reserve(n);
}

PlantState PneumaticPlant::state() const {
  PlantState s;
  s.time = time_;
  s.supply_pressure = supply_pressure_;
  s.supply_enabled = supply_enabled_;
  s.pressure = pressure_;
  s.history_time = history_time_;
  s.history_volts = history_volts_;
  // The command to repeat when step() gets no volts is the newest frame.
  return s;
}

void PneumaticPlant::setState(const PlantState& s) {
  const std::size_t n = specs_.size();
  if (s.pressure.size() != n || s.history_time.empty() || s.history_volts.size() != s.history_time.size() * n)
    throw std::invalid_argument("PneumaticPlant::setState: state does not match a plant of " +
                                std::to_string(n) + " cylinders");
  time_ = s.time;
  supply_pressure_ = s.supply_pressure;
  supply_enabled_ = s.supply_enabled;
  pressure_ = s.pressure;
  history_time_ = s.history_time;
  history_volts_ = s.history_volts;
  last_volts_.assign(history_volts_.end() - n, history_volts_.end());
}

}  // namespace adroit::pneumatics
