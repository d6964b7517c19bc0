#include "adroit_pneumatics/thin_port_id.h"

#include "adroit_pneumatics/excitation.h"

#include <cmath>
#include <stdexcept>

namespace adroit::pneumatics {

namespace {

// Scaled parameter vector: areas in 1e-7 m^2, volume in 1e-7 m^3 (0.1 cm^3), b, c, d as is,
// so every entry is of order one for LM's relative finite differences.
constexpr double kArea = 1e-7, kVolume = 1e-7;

// b and d of eq. 4.13 are one degree of freedom: b exp(-c (u + d)) = (b e^{-c d}) e^{-c u}.
// The fit keeps d at its starting value and moves b (the curve is unaffected by the choice);
// compare curves through gompertzCentre().
void packPort(const GompertzArea& g, std::vector<double>& v) {
  v.insert(v.end(), {g.offset / kArea, g.a / kArea, std::log(g.b), g.c});
}
GompertzArea unpackPort(const Eigen::VectorXd& x, Eigen::Index& i, double d) {
  GompertzArea g;
  g.offset = x[i++] * kArea;
  g.a = x[i++] * kArea;
  g.b = std::exp(x[i++]);
  g.c = x[i++];
  g.d = d;
  return g;
}

std::size_t residualCount(const std::vector<Recording>& recs) {
  std::size_t n = 0;
  for (const Recording& r : recs) n += r.size() - 1;
  return n;
}

// Rate residuals in kPa/s.
void rateResiduals(const std::vector<Recording>& recs, const ThinPortParams& prm, Eigen::VectorXd& r) {
  r.resize(static_cast<Eigen::Index>(residualCount(recs)));
  const bool valid = prm.dead_volume > 0 && prm.leak_area >= 0 && prm.valve.inlet.offset >= 0 &&
                     prm.valve.exhaust.offset >= 0 && prm.valve.inlet.a > 0 && prm.valve.exhaust.a > 0 &&
                     prm.valve.inlet.b > 0 && prm.valve.exhaust.b > 0;
  if (!valid) {
    r.setConstant(1e6);
    return;
  }
  const FlowTable& table = flowTable();
  Eigen::Index idx = 0;
  for (const Recording& rec : recs) {
    for (std::size_t k = 0; k + 1 < rec.size(); ++k) {
      // Average rate over the sample against the model's rate at the midpoint pressure
      // (midpoint rule, second order in dt, smooth in the parameters).
      const double a_in = prm.valve.inlet(rec.volts[k]);
      const double a_out = prm.valve.exhaust(rec.volts[k]) + prm.leak_area;
      const double v = rec.volume[k] + prm.dead_volume;
      const double p = 0.5 * (rec.pressure[k] + rec.pressure[k + 1]);
      const double mdot = a_in * table.phi(rec.supply[k], p) - a_out * table.phi(p, rec.room);
      const double model = constants::kKappa / v * (constants::kRsT * mdot - p * rec.volume_rate[k]);
      const double measured = (rec.pressure[k + 1] - rec.pressure[k]) / rec.dt;
      const double e = (model - measured) * 1e-3;
      r[idx++] = std::isfinite(e) ? e : 1e6;
    }
  }
}

}  // namespace

double gompertzCentre(const GompertzArea& g) { return std::log(g.b) / g.c - g.d; }

double thinPortRateRmse(const std::vector<Recording>& recs, const ThinPortParams& params) {
  Eigen::VectorXd r;
  rateResiduals(recs, params, r);
  return r.size() ? std::sqrt(r.squaredNorm() / r.size()) * 1e3 : 0.0;
}

ThinPortFitReport fitThinPort(const std::vector<Recording>& recs, const ThinPortParams& initial,
                              const ThinPortFitOptions& opt) {
  if (recs.empty()) throw std::invalid_argument("fitThinPort: no recordings");
  for (const Recording& r : recs) r.validate();
  const auto pack = [&](const ThinPortParams& p) {
    std::vector<double> v;
    if (opt.fit_valve) {
      packPort(p.valve.inlet, v);
      packPort(p.valve.exhaust, v);
    }
    if (opt.fit_dead_volume) v.push_back(p.dead_volume / kVolume);
    if (opt.fit_leak) v.push_back(p.leak_area / kArea);
    return Eigen::Map<Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size())).eval();
  };
  const auto unpack = [&](const Eigen::VectorXd& x) {
    ThinPortParams p = initial;
    Eigen::Index i = 0;
    if (opt.fit_valve) {
      p.valve.inlet = unpackPort(x, i, initial.valve.inlet.d);
      p.valve.exhaust = unpackPort(x, i, initial.valve.exhaust.d);
    }
    if (opt.fit_dead_volume) p.dead_volume = x[i++] * kVolume;
    if (opt.fit_leak) p.leak_area = x[i++] * kArea;
    return p;
  };
  ThinPortFitReport rep;
  const Eigen::VectorXd x0 = pack(initial);
  if (x0.size() == 0) {
    rep.params = initial;
  } else {
    auto res = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) { rateResiduals(recs, unpack(x), r); };
    const LmResult lm = levenbergMarquardt(res, x0, opt.max_iterations);
    rep.params = unpack(lm.x);
    rep.iterations = lm.iterations;
  }
  rep.rate_rmse = thinPortRateRmse(recs, rep.params);
  return rep;
}

Recording recordLockedCylinder(const CylinderSpec& spec, double travel, const std::string& kind, double seconds,
                               std::uint64_t seed) {
  PlantOptions o;
  o.tube_delay = 0, o.area_spread = 0, o.offset_spread = 0, o.initial_volts = -3.0;
  PneumaticPlant plant({spec}, SupplyParams{}, 1, o);
  ExcitationParams e;
  e.kind = kind;
  e.seed = seed;
  e.step_hold = 0.05;
  Excitation ex(e);
  Recording r;
  r.dt = 5e-4;
  const double rate = 0.0;
  for (int k = 0; k < static_cast<int>(seconds / r.dt); ++k) {
    const double u = ex.next(k * r.dt, r.dt);
    r.volts.push_back(u);
    r.pressure.push_back(plant.pressure()[0]);
    r.volume.push_back(spec.bore_area * travel);
    r.volume_rate.push_back(0.0);
    r.supply.push_back(plant.supplyPressure());
    for (int s = 0; s < 4; ++s) plant.step(r.dt / 4, &u, &travel, &rate);
  }
  return r;
}

}  // namespace adroit::pneumatics
