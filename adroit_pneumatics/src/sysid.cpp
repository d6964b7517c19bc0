#include "adroit_pneumatics/sysid.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "adroit_core/bounded_file.h"

namespace adroit::pneumatics {

ParametricInputs Recording::inputs(std::size_t k) const {
  ParametricInputs in;
  in.volume = volume[k];
  in.volume_rate = volume_rate[k];
  in.supply = supply[k];
  in.room = room;
  return in;
}

void Recording::validate() const {
  const std::size_t n = pressure.size();
  const std::pair<const char*, const std::vector<double>*> cols[] = {
      {"volts", &volts}, {"pressure", &pressure}, {"volume", &volume}, {"volume_rate", &volume_rate}, {"supply", &supply}};
  for (const auto& [name, col] : cols) {
    if (col->size() != n) throw std::invalid_argument(std::string("recording: column '") + name + "' has the wrong length");
    for (double v : *col)
      if (!std::isfinite(v)) throw std::invalid_argument(std::string("recording: column '") + name + "' has a non-finite value");
  }
  if (!(dt > 0)) throw std::invalid_argument("recording: dt must be > 0");
  if (n < 2) throw std::invalid_argument("recording: fewer than 2 samples");
}

Recording readRecordingCsv(const std::string& path) {
  // An hour of one cylinder at 1 kHz is ~200 MB of CSV: far more than any identification uses.
  std::istringstream f(adroit::readBoundedFile(path, 256 * adroit::kMiB));
  std::string line;
  if (!std::getline(f, line) || line.rfind("t,volts,pressure,volume,volume_rate,supply", 0) != 0)
    throw std::runtime_error(path + ":1: expected header t,volts,pressure,volume,volume_rate,supply");
  Recording rec;
  std::vector<double> t;
  int lineno = 1;
  while (std::getline(f, line)) {
    ++lineno;
    if (line.empty()) continue;
    std::stringstream ss(line);
    double v[6];
    for (int i = 0; i < 6; ++i) {
      std::string cell;
      if (!std::getline(ss, cell, ',')) throw std::runtime_error(path + ":" + std::to_string(lineno) + ": expected 6 columns");
      try {
        std::size_t used = 0;
        v[i] = std::stod(cell, &used);
      } catch (const std::exception&) {
        throw std::runtime_error(path + ":" + std::to_string(lineno) + ": not a number: '" + cell + "'");
      }
    }
    t.push_back(v[0]);
    rec.volts.push_back(v[1]);
    rec.pressure.push_back(v[2]);
    rec.volume.push_back(v[3]);
    rec.volume_rate.push_back(v[4]);
    rec.supply.push_back(v[5]);
  }
  if (t.size() < 2) throw std::runtime_error(path + ": fewer than 2 samples");
  rec.dt = (t.back() - t.front()) / (t.size() - 1);
  rec.validate();
  return rec;
}

void writeRecordingCsv(const std::string& path, const Recording& rec) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write " + path);
  f.precision(10);
  f << "t,volts,pressure,volume,volume_rate,supply\n";
  for (std::size_t k = 0; k < rec.size(); ++k)
    f << k * rec.dt << ',' << rec.volts[k] << ',' << rec.pressure[k] << ',' << rec.volume[k] << ','
      << rec.volume_rate[k] << ',' << rec.supply[k] << '\n';
}

LmResult levenbergMarquardt(const std::function<void(const Eigen::VectorXd&, Eigen::VectorXd&)>& residual,
                            Eigen::VectorXd x, int max_iterations) {
  Eigen::VectorXd r, r_try;
  residual(x, r);
  double cost = 0.5 * r.squaredNorm();
  double lambda = 1e-3;
  LmResult out;
  const Eigen::Index n = x.size();
  Eigen::MatrixXd J(r.size(), n);
  for (int it = 0; it < max_iterations; ++it) {
    out.iterations = it + 1;
    for (Eigen::Index j = 0; j < n; ++j) {
      Eigen::VectorXd xp = x;
      const double h = 1e-6 * std::max(1.0, std::abs(x[j]));
      xp[j] += h;
      residual(xp, r_try);
      J.col(j) = (r_try - r) / h;
    }
    const Eigen::MatrixXd JtJ = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    bool improved = false;
    for (int attempt = 0; attempt < 12; ++attempt) {
      Eigen::MatrixXd A = JtJ;
      A.diagonal() += lambda * (JtJ.diagonal().array() + 1e-12).matrix();
      const Eigen::VectorXd dx = A.ldlt().solve(-g);
      const Eigen::VectorXd xt = x + dx;
      residual(xt, r_try);
      const double c = 0.5 * r_try.squaredNorm();
      if (std::isfinite(c) && c < cost) {
        const double rel = (cost - c) / std::max(cost, 1e-300);
        x = xt;
        r = r_try;
        cost = c;
        lambda = std::max(lambda * 0.3, 1e-9);
        improved = true;
        if (rel < 1e-10) it = max_iterations;  // converged
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) break;
  }
  out.x = x;
  out.cost = cost;
  return out;
}

namespace {

// Parameters are only accepted inside the validity region; outside it the residual is
// made large so LM steps back.
bool tryModel(const ParametricParams& p, ParametricModel* m) {
  try {
    *m = ParametricModel(p);
    return true;
  } catch (const std::invalid_argument&) {
    return false;
  }
}

// Multi-step simulation residuals over consecutive segments (each starts from the measured
// pressure). Residuals are in kPa to keep LM well scaled. The command of the previous
// sample acts for the first td of each sample (stepDelayed).
void segmentResiduals(const Recording& rec, const ParametricParams& prm, int segment, Eigen::VectorXd& r) {
  const std::size_t n = rec.size();
  const std::size_t count = (n - 1) / segment;
  r.resize(static_cast<Eigen::Index>(count * segment));
  ParametricModel m;
  if (!tryModel(prm, &m)) {
    r.setConstant(1e6);
    return;
  }
  Eigen::Index idx = 0;
  for (std::size_t s = 0; s < count; ++s) {
    std::size_t k = s * segment;
    double p = rec.pressure[k];
    for (int j = 0; j < segment; ++j, ++k) {
      p = m.stepDelayed(p, rec.volts[k > 0 ? k - 1 : 0], rec.volts[k], rec.dt, rec.inputs(k));
      r[idx++] = std::isfinite(p) ? (p - rec.pressure[k + 1]) * 1e-3 : 1e6;
    }
  }
}

double segmentCost(const Recording& rec, const ParametricParams& prm, int segment) {
  Eigen::VectorXd r;
  segmentResiduals(rec, prm, segment, r);
  return r.squaredNorm();
}

}  // namespace

FitReport fitParametricModel(const Recording& sweep, const Recording& random, bool fit_volume, int segment,
                             const ParametricParams& initial) {
  FitOptions o;
  o.fit_volume = fit_volume;
  o.segment = segment;
  return fitParametricModel(sweep, random, o, initial);
}

namespace {

// The rate stages of fitParametricModel for one form, from prm (steady state fitted):
// multi-start on short segments, then all parameters jointly, then on long segments.
// Scaled for LM: td in ms, e_fill and e_exhaust in kPa.
ParametricParams fitRate(const Recording& random, const FitOptions& opt, ParametricParams prm, double* segment_rmse) {
  const int segment = opt.segment;
  const bool saturating = prm.form == ParametricForm::kSaturating;
  const bool fit_volume = opt.fit_volume, fit_td = opt.fit_dead_time;
  // Without piston motion in the data c5 cannot be identified: it is tied to its physical
  // value, eq. 5.3a's compression term -kappa p vdot / v: c5 = -kappa c6 (eq. 5.5, tau ~ c6 v
  // for c6 v >> 1) or -kappa / (1 + v0) (saturating, lambda ~ (1 + v0) / v), so a model
  // identified at several locked volumes still knows vdot.
  const bool tie_c5 = fit_volume && std::all_of(random.volume_rate.begin(), random.volume_rate.end(),
                                                [](double v) { return v == 0.0; });
  const auto tie = [&](ParametricParams& q) {
    if (tie_c5) q.c5 = saturating ? -constants::kKappa / (1.0 + q.v0) : -constants::kKappa * q.c6;
  };
  const auto pack = [&](const ParametricParams& q, bool all) {
    std::vector<double> v = {q.c7, q.c8, q.c9, q.cg};
    if (fit_volume) { v.push_back(q.c5); v.push_back(saturating ? std::log(q.v0) : q.c6); }
    if (fit_td) v.push_back(q.td * 1e3);  // ms: same scale as the others
    if (saturating) { v.push_back(q.u_sat); v.push_back(q.e_fill * 1e-3); v.push_back(q.e_exhaust * 1e-3); }
    if (all) { v.push_back(q.c2); v.push_back(q.c3); v.push_back(q.c4); }
    return Eigen::Map<Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size())).eval();
  };
  const auto unpack = [&](const Eigen::VectorXd& x, bool all, const ParametricParams& base) {
    ParametricParams q = base;
    Eigen::Index i = 0;
    q.c7 = x[i++], q.c8 = x[i++], q.c9 = x[i++], q.cg = x[i++];
    if (fit_volume) {
      q.c5 = x[i++];
      // v0 below 1e-6 cm^3 changes nothing at the smallest dead volume (0.1 cm^3).
      if (saturating) q.v0 = std::max(std::exp(x[i++]), 1e-6); else q.c6 = x[i++];
    }
    if (fit_td) q.td = x[i++] * 1e-3;
    if (saturating) { q.u_sat = x[i++]; q.e_fill = x[i++] * 1e3; q.e_exhaust = x[i++] * 1e3; }
    if (all) { q.c2 = x[i++]; q.c3 = x[i++]; q.c4 = x[i++]; }
    tie(q);
    return q;
  };
  // Multi-start for the rate: the cost is evaluated at a small grid of starting points, and
  // LM starts from the best few. Eq. 5.5: (c7, c9, c6, td); saturating: the saturation
  // (u_sat, e_fill) and the volume scaling (v0) around the mapped eq. 5.5 fit.
  if (opt.multi_start) {
    std::vector<std::pair<double, ParametricParams>> cands;
    if (saturating) {
      for (double u_sat : {2.0, 5.0})
        for (double e_fill : {100e3, 300e3})
          for (double v0 : fit_volume ? std::vector<double>{prm.v0, 0.1} : std::vector<double>{prm.v0}) {
            ParametricParams q = prm;
            q.u_sat = u_sat, q.e_fill = e_fill, q.e_exhaust = 1e6;
            // The same rates at the identification data's mean volume.
            if (v0 != prm.v0) {
              double mean_v = 0;
              for (double v : random.volume) mean_v += v * 1e6 / random.size();
              const double scale = ((1 + prm.v0) / (mean_v + prm.v0)) / ((1 + v0) / (mean_v + v0));
              q.v0 = v0, q.c5 *= scale, q.c7 *= scale, q.c9 *= scale;
            }
            tie(q);
            cands.emplace_back(segmentCost(random, q, segment), q);
          }
    } else {
      for (double c7 : {30.0, 100.0, 300.0})
        for (double c9 : {5.0, 20.0})
          for (double c6 : fit_volume ? std::vector<double>{0.0, 1.0, 5.0} : std::vector<double>{prm.c6})
            for (double td : fit_td ? std::vector<double>{0.0, 0.002} : std::vector<double>{prm.td}) {
              ParametricParams q = prm;
              q.c7 = c7 * (1.0 + c6), q.c9 = c9 * (1.0 + c6), q.c6 = c6, q.td = td, q.c8 = 0.0, q.cg = 0.2;
              if (fit_volume) q.c5 = -1.4 * c6;  // physical ratio c5 / c6 = -kappa (README)
              cands.emplace_back(segmentCost(random, q, segment), q);
            }
    }
    cands.emplace_back(segmentCost(random, prm, segment), prm);
    std::sort(cands.begin(), cands.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    double best = 1e300;
    ParametricParams best_q = prm;
    for (std::size_t c = 0; c < std::min<std::size_t>(3, cands.size()); ++c) {
      const ParametricParams start = cands[c].second;
      auto res = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
        segmentResiduals(random, unpack(x, false, start), segment, r);
      };
      const LmResult lm = levenbergMarquardt(res, pack(start, false), 40);
      if (lm.cost < best) best = lm.cost, best_q = unpack(lm.x, false, start);
    }
    prm = best_q;
  }
  for (bool all : {false, true}) {
    auto res = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) { segmentResiduals(random, unpack(x, all, prm), segment, r); };
    const LmResult lm = levenbergMarquardt(res, pack(prm, all), 80);
    prm = unpack(lm.x, all, prm);
    *segment_rmse = std::sqrt(2.0 * lm.cost / std::max<Eigen::Index>(1, ((random.size() - 1) / segment) * segment)) * 1e3;
  }
  // Longer open-loop segments: the 2 s criterion punishes slow drift that 100 ms segments
  // hardly see (leak, volume terms).
  if (opt.long_segment > segment && static_cast<std::size_t>(opt.long_segment) < random.size()) {
    auto res = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
      segmentResiduals(random, unpack(x, true, prm), opt.long_segment, r);
    };
    const LmResult lm = levenbergMarquardt(res, pack(prm, true), 60);
    prm = unpack(lm.x, true, prm);
  }
  tie(prm);
  return prm;
}

}  // namespace

FitReport fitParametricModel(const Recording& sweep, const Recording& random, const FitOptions& opt,
                             const ParametricParams& initial) {
  sweep.validate();
  random.validate();
  if (opt.segment < 1 || static_cast<std::size_t>(opt.segment) >= random.size())
    throw std::invalid_argument("fitParametricModel: segment must be in [1, samples)");
  FitReport rep;
  ParametricParams prm = initial;
  prm.form = ParametricForm::kEq55;
  // (a) Steady state: the slow sweep drags the equilibrium along, p ~ s(u). The valve's
  // steady state is a near-step around its centre (both ports almost closed, fig. 5.4), so
  // the starting points range from a gentle to a steep sigmoid; the best fit is kept.
  {
    auto res = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
      ParametricParams q = prm;
      q.c2 = x[0], q.c3 = x[1], q.c4 = x[2];
      r.resize(static_cast<Eigen::Index>(sweep.size()));
      ParametricModel m;
      if (!tryModel(q, &m)) { r.setConstant(1e6); return; }
      for (std::size_t k = 0; k < sweep.size(); ++k)
        r[k] = (m.steadyState(sweep.volts[k], sweep.inputs(k)) - sweep.pressure[k]) * 1e-3;
    };
    std::vector<Eigen::Vector3d> starts = {{prm.c2, prm.c3, prm.c4}};
    if (opt.multi_start)
      for (double c3 : {1.0, 4.0, 12.0})
        for (double c4 : {0.1, 5.0, 100.0}) starts.emplace_back(prm.c2, c3, c4);
    double best = 1e300;
    for (const Eigen::Vector3d& x0 : starts) {
      const LmResult lm = levenbergMarquardt(res, x0, 100);
      if (lm.cost < best) {
        best = lm.cost;
        prm.c2 = lm.x[0], prm.c3 = lm.x[1], prm.c4 = lm.x[2];
      }
    }
    rep.steady_rmse = std::sqrt(2.0 * best / sweep.size()) * 1e3;
  }
  // (b) Rate (and volume terms, dead time) from the random data, steady state held; the
  // saturating form starts from the eq. 5.5 fit mapped onto it (exactly eq. 5.5 but for
  // the saturation, whose start values the multi-start varies).
  prm = fitRate(random, opt, prm, &rep.segment_rmse);
  if (opt.form == ParametricForm::kSaturating) {
    prm = saturatingFromEq55(prm, 300e3, 1e6, 3.0);
    prm = fitRate(random, opt, prm, &rep.segment_rmse);
  }
  prm.validate();
  rep.params = prm;
  return rep;
}

double parameterConditionNumber(const Recording& rec, const ParametricParams& prm, int segment) {
  rec.validate();
  const bool saturating = prm.form == ParametricForm::kSaturating;
  std::vector<std::pair<double ParametricParams::*, double>> columns = {
      {&ParametricParams::c2, 0.1}, {&ParametricParams::c3, 0.0}, {&ParametricParams::c4, 1.0},
      {&ParametricParams::c5, 0.0}, {&ParametricParams::c7, 0.0}, {&ParametricParams::c8, 0.1},
      {&ParametricParams::c9, 0.0}, {&ParametricParams::cg, 0.0}, {&ParametricParams::td, 1e-3}};
  if (saturating) {
    for (auto m : {&ParametricParams::u_sat, &ParametricParams::e_fill, &ParametricParams::e_exhaust}) columns.emplace_back(m, 0.0);
    columns.emplace_back(&ParametricParams::v0, 0.1);
  } else {
    columns.emplace_back(&ParametricParams::c6, 0.0);
  }
  // Forward differences: parameters at a bound (v0, c4) can only move inwards.
  Eigen::VectorXd r0, r;
  segmentResiduals(rec, prm, segment, r0);
  Eigen::MatrixXd J(r0.size(), static_cast<Eigen::Index>(columns.size()));
  for (std::size_t j = 0; j < columns.size(); ++j) {
    const auto [member, floor] = columns[j];
    ParametricParams moved = prm;
    moved.*member += 1e-4 * std::max(std::abs(prm.*member), floor);
    segmentResiduals(rec, moved, segment, r);
    J.col(static_cast<Eigen::Index>(j)) = (r - r0) / 1e-4;  // per relative change of the parameter
  }
  // Singular values of J: the square roots of those of the small square J^T J (descending).
  const Eigen::MatrixXd normal = J.transpose() * J;
  const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd, Eigen::NoQRPreconditioner>(normal).singularValues();
  return std::sqrt(sv[0] / std::max(sv[sv.size() - 1], 1e-300));
}

PredictionReport predictionRmse(const Recording& rec, const ParametricModel& model, double window) {
  rec.validate();
  const auto len = static_cast<std::size_t>(std::lround(window / rec.dt));
  PredictionReport rep;
  if (len < 1 || len >= rec.size()) return rep;
  double sq = 0, supply = 0;
  std::size_t count = 0;
  double window_sum = 0;
  for (std::size_t start = 0; start + len < rec.size(); start += len) {
    double p = rec.pressure[start], window_sq = 0;
    for (std::size_t k = start; k < start + len; ++k) {
      p = model.stepDelayed(p, rec.volts[k > 0 ? k - 1 : 0], rec.volts[k], rec.dt, rec.inputs(k));
      const double e = p - rec.pressure[k + 1];
      window_sq += e * e;
      supply += rec.supply[k];
      ++count;
    }
    sq += window_sq;
    window_sum += std::sqrt(window_sq / len);
    ++rep.windows;
  }
  const double range = supply / count - rec.room;
  rep.rmse = std::sqrt(sq / count);
  rep.percent = 100.0 * rep.rmse / range;
  rep.window_mean_rmse = window_sum / rep.windows;
  rep.window_mean_percent = 100.0 * rep.window_mean_rmse / range;
  return rep;
}

}  // namespace adroit::pneumatics
