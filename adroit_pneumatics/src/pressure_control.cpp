#include "adroit_pneumatics/pressure_control.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace adroit::pneumatics {

namespace {
const double kNaN = std::numeric_limits<double>::quiet_NaN();

bool allFinite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

// Parametric model (Pa) with inputs frozen over the horizon (v, vdot are sensor inputs,
// 5.5.5), the model's input dead time (the previous command w acts for the first td of each
// step), and the offset-free disturbance: a constant pressure-rate bias d added to the model,
// which over one step adds d * dt (the controller estimates d from its one-step prediction
// error, so model bias, leak and unmodelled volume effects do not leave a steady offset).
class ParametricDynamics : public ScalarDynamics {
 public:
  ParametricDynamics(const ParametricModel& m, const ParametricInputs& in, double dt, double bias_pa_per_s = 0.0)
      : m_(m), in_(in), dt_(dt), bias_(bias_pa_per_s * dt), td_(std::min(m.params().td, dt)) {}
  double step(double p, double u, double* dp, double* du) const override {
    return m_.advance(p, terms(u), dt_, dp, du) + bias_;
  }
  // ParametricModel::stepDelayed with each command's terms cached: in a rollout
  // w_i = u_{i-1}, so each command's terms are computed once.
  double stepWithMemory(double p, double w, double u, double* dp, double* dw, double* du) const override {
    if (td_ <= 0.0) {
      if (dw) *dw = 0.0;
      return step(p, u, dp, du);
    }
    if (!dp && !dw && !du) {  // rollout: values only
      const double mid = m_.advance(p, terms(w), td_);
      if (td_ >= dt_) return mid + bias_;
      return m_.advance(mid, terms(u), dt_ - td_) + bias_;
    }
    double a1, b1, a2, b2;
    const double mid = m_.advance(p, terms(w), td_, &a1, &b1);
    if (td_ >= dt_) {
      if (dp) *dp = a1;
      if (dw) *dw = b1;
      if (du) *du = 0.0;
      return mid + bias_;
    }
    const double next = m_.advance(mid, terms(u), dt_ - td_, &a2, &b2);
    if (dp) *dp = a2 * a1;
    if (dw) *dw = a2 * b1;
    if (du) *du = b2;
    return next + bias_;
  }

 private:
  const ParametricModel::CommandTerms& terms(double u) const {
    if (cache_u_[0] == u) return cache_[0];
    if (cache_u_[1] == u) return cache_[1];
    const int slot = next_;
    next_ ^= 1;
    cache_u_[slot] = u;
    cache_[slot] = m_.terms(u, in_);
    return cache_[slot];
  }

  const ParametricModel& m_;
  ParametricInputs in_;
  double dt_, bias_, td_;
  mutable ParametricModel::CommandTerms cache_[2];
  mutable double cache_u_[2] = {kNaN, kNaN};
  mutable int next_ = 0;
};
}  // namespace

void IlqgParams::validate() const {
  if (horizon < 1 || horizon > 10000) throw std::invalid_argument("ilqg: horizon must be in [1, 10000]");
  if (!(dt > 0) || !std::isfinite(dt)) throw std::invalid_argument("ilqg: dt must be > 0");
  if (!(alpha_p > 0) || !std::isfinite(alpha_p)) throw std::invalid_argument("ilqg: alpha_p must be > 0");
  if (!(alpha_u >= 0) || !std::isfinite(alpha_u)) throw std::invalid_argument("ilqg: alpha_u must be >= 0");
  if (!(alpha_w >= 0) || !std::isfinite(alpha_w)) throw std::invalid_argument("ilqg: alpha_w must be >= 0");
  if (!(u_min < u_max) || u_min < -5 || u_max > 5) throw std::invalid_argument("ilqg: need -5 <= u_min < u_max <= 5");
  if (iterations < 1) throw std::invalid_argument("ilqg: iterations must be >= 1");
  if (jump_iterations < 1) throw std::invalid_argument("ilqg: jump_iterations must be >= 1");
  if (!(feedback_fraction >= 0 && feedback_fraction <= 1))
    throw std::invalid_argument("ilqg: feedback_fraction must be in [0, 1]");
  if (!(disturbance_gain >= 0 && disturbance_gain <= 1))
    throw std::invalid_argument("ilqg: disturbance_gain must be in [0, 1]");
  if (!(measurement_gain > 0 && measurement_gain <= 1))
    throw std::invalid_argument("ilqg: measurement_gain must be in (0, 1]");
  if (!(jump_threshold >= 0) || !std::isfinite(jump_threshold))
    throw std::invalid_argument("ilqg: jump_threshold must be finite and >= 0");
  if (!(measurement_band >= 0) || !std::isfinite(measurement_band))
    throw std::invalid_argument("ilqg: measurement_band must be finite and >= 0");
  if (!(disturbance_limit >= 0) || !std::isfinite(disturbance_limit))
    throw std::invalid_argument("ilqg: disturbance_limit must be finite and >= 0");
}

namespace {
// The "limit, then hold" guess computes holding commands at every kHoldEvery-th sample.
constexpr int kHoldEvery = 10;
}  // namespace

IlqgSolver::IlqgSolver(const IlqgParams& params) : params_(params) {
  params_.validate();
  const auto n = static_cast<std::size_t>(params_.horizon);
  p_.assign(n + 1, 0.0);
  w_.assign(n + 1, 0.0);
  u_.assign(n, 0.0);
  a_.assign(n, 0.0);
  b_.assign(n, 0.0);
  c_.assign(n, 0.0);
  kff_.assign(n, 0.0);
  kp_.assign(n, 0.0);
  kw_.assign(n, 0.0);
  p_try_ = p_;
  w_try_ = w_;
  u_try_ = u_;
  u_start_ = u_;
  p_alt_ = p_;
  w_alt_ = w_;
  u_alt_ = u_;
  knots_.assign(n / kHoldEvery + 2, 0.0);
}

double IlqgSolver::rollout(const ScalarDynamics& f, double p0, double w0, const double* p_ref, const double* u_des,
                           const std::vector<double>& u_ff, double step, std::vector<double>& p,
                           std::vector<double>& w, std::vector<double>& u) const {
  // With step < 0 the controls are u_ff as given (initial rollout); otherwise the
  // iLQG update u_i + step k_i + K_i (x_i - x_i_nominal).
  const int n = params_.horizon;
  const double ap = params_.alpha_p, au = params_.alpha_u, aw = params_.alpha_w;
  p[0] = p0;
  w[0] = w0;
  double cost = 0;
  for (int i = 0; i < n; ++i) {
    double ui = u_ff[i];
    if (step >= 0) ui += step * kff_[i] + kp_[i] * (p[i] - p_[i]) + kw_[i] * (w[i] - w_[i]);
    ui = std::clamp(ui, params_.u_min, params_.u_max);
    u[i] = ui;
    const double ep = p_ref[i] - p[i], eu = u_des[i] - ui, ew = ui - w[i];
    cost += ap * ep * ep + au * eu * eu + aw * ew * ew;
    p[i + 1] = f.stepWithMemory(p[i], w[i], ui, nullptr, nullptr, nullptr);
    w[i + 1] = ui;
  }
  const double ep = p_ref[n] - p[n];
  return cost + ap * ep * ep;
}

bool IlqgSolver::backward(const double* p_ref, const double* u_des, double reg, double* expected) {
  const int n = params_.horizon;
  const double ap = params_.alpha_p, au = params_.alpha_u, aw = params_.alpha_w;
  // Value function V(p, w) ~ V1 dp + V2 dw + 1/2 [dp dw] [[V11 V12][V12 V22]] [dp dw]^T.
  double V1 = -2.0 * ap * (p_ref[n] - p_[n]), V2 = 0, V11 = 2.0 * ap, V12 = 0, V22 = 0;
  double dv = 0;
  for (int i = n - 1; i >= 0; --i) {
    const double a = a_[i], b = b_[i], c = c_[i], u = u_[i];
    // Cost derivatives (l = ap (pr - p)^2 + au (ud - u)^2 + aw (u - w)^2).
    const double lp = -2.0 * ap * (p_ref[i] - p_[i]);
    const double lw = -2.0 * aw * (u - w_[i]);
    const double lu = -2.0 * au * (u_des[i] - u) + 2.0 * aw * (u - w_[i]);
    // Next state [a p + c w + b u, u]: fx = [[a, c], [0, 0]], fu = [b, 1] (c = dp'/dw is
    // the dead time's share of the previous command; 0 without dead time).
    const double Qp = lp + a * V1;
    const double Qw = lw + c * V1;
    const double Qu = lu + b * V1 + V2;
    const double Qpp = 2.0 * ap + a * a * V11;
    const double Qpw = a * c * V11;
    const double Qww = 2.0 * aw + c * c * V11;
    const double Quu = 2.0 * au + 2.0 * aw + b * b * V11 + 2.0 * b * V12 + V22;
    const double Qup = a * (b * V11 + V12);
    const double Quw = -2.0 * aw + c * (b * V11 + V12);
    const double H = Quu + reg;
    if (!(H > 0)) return false;
    double k = -Qu / H, Kp = -Qup / H, Kw = -Quw / H;
    // Box constraint on u (scalar case of the projected Newton step): at an active
    // bound the feedback is dropped.
    if (u + k > params_.u_max) { k = params_.u_max - u; Kp = Kw = 0; }
    else if (u + k < params_.u_min) { k = params_.u_min - u; Kp = Kw = 0; }
    kff_[i] = k;
    kp_[i] = Kp;
    kw_[i] = Kw;
    dv += k * Qu + 0.5 * k * k * Quu;
    // V = Q with u = k + K dx substituted.
    V1 = Qp + Kp * Quu * k + Kp * Qu + Qup * k;
    V2 = Qw + Kw * Quu * k + Kw * Qu + Quw * k;
    V11 = Qpp + Kp * Quu * Kp + 2.0 * Kp * Qup;
    V12 = Qpw + Kp * Quu * Kw + Kp * Quw + Qup * Kw;
    V22 = Qww + Kw * Quu * Kw + 2.0 * Kw * Quw;
  }
  *expected = dv;
  return std::isfinite(dv);
}

void IlqgSolver::bangHoldGuess(const ScalarDynamics& f, double p0, double w0, const double* p_ref,
                               std::vector<double>& u) {
  const int n = params_.horizon;
  // Holding command for a pressure level: the u whose step keeps p where it is (the step is
  // increasing in u), by bisection.
  auto hold = [&](double level) {
    double lo = params_.u_min, hi = params_.u_max;
    for (int k = 0; k < 30; ++k) {
      const double mid = 0.5 * (lo + hi);
      (f.stepWithMemory(level, mid, mid, nullptr, nullptr, nullptr) < level ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
  };
  // Holding commands at every 10th sample, interpolated in between (the reference is smooth
  // between jumps, and a hold command costs a bisection).
  std::vector<double>& knots = knots_;  // n / kHoldEvery + 2 entries, allocated once
  for (int i = 0, k = 0; i < n + kHoldEvery; i += kHoldEvery, ++k) knots[k] = hold(p_ref[std::min(i, n)]);
  const int direction = p_ref[0] > p0 ? 1 : -1;
  double p = p0, w = w0;
  bool racing = true;
  for (int i = 0; i < n; ++i) {
    racing = racing && (p_ref[i] - p) * direction > 0;
    const int a = i / kHoldEvery;
    const double f_i = (i % kHoldEvery) / static_cast<double>(kHoldEvery);
    u[i] = racing ? (direction > 0 ? params_.u_max : params_.u_min) : knots[a] + f_i * (knots[a + 1] - knots[a]);
    p = f.stepWithMemory(p, w, u[i], nullptr, nullptr, nullptr);
    w = u[i];
  }
}

bool IlqgSolver::solve(const ScalarDynamics& f, double p0, double w0, const double* p_ref, const double* u_des,
                       const double* u_init, int n_init, int iterations) {
  // Only the preallocated workspaces are used (swapped, never resized): the first rollout
  // goes into the *_try_ buffers, the jump guess into the *_alt_ ones.
  const int n = params_.horizon;
  for (int i = 0; i < n; ++i) u_start_[i] = i < n_init ? u_init[i] : u_des[i];
  double cost = rollout(f, p0, w0, p_ref, u_des, u_start_, -1.0, p_try_, w_try_, u_try_);
  if (params_.jump_threshold > 0 && std::abs(p_ref[0] - p0) > params_.jump_threshold) {
    iterations = std::max(iterations, params_.jump_iterations);
    bangHoldGuess(f, p0, w0, p_ref, u_start_);  // u_start_ is free again: rolled out above
    const double c = rollout(f, p0, w0, p_ref, u_des, u_start_, -1.0, p_alt_, w_alt_, u_alt_);
    if (std::isfinite(c) && (c < cost || !std::isfinite(cost))) {
      cost = c;
      p_try_.swap(p_alt_);
      w_try_.swap(w_alt_);
      u_try_.swap(u_alt_);
    }
  }
  if (!std::isfinite(cost)) return false;
  p_.swap(p_try_);
  w_.swap(w_try_);
  u_.swap(u_try_);
  double reg = 0.0;
  // Gains of the last successful backward pass are kept for the policy (standard iLQG: the
  // policy is u_new + K (x - x_new) with K from the pass that produced u_new); only when no
  // backward pass succeeded is one run on the final trajectory. This saves a derivative and
  // a backward pass per solve (a third of the cost at one iteration).
  bool have_gains = false;
  for (int it = 0; it < iterations; ++it) {
    for (int i = 0; i < n; ++i) f.stepWithMemory(p_[i], w_[i], u_[i], &a_[i], &c_[i], &b_[i]);
    double expected = 0;
    if (!backward(p_ref, u_des, reg, &expected)) {
      reg = std::max(1e-6, reg * 10.0);
      continue;
    }
    have_gains = true;
    if (expected > -1e-14) break;  // converged: no descent left
    bool accepted = false;
    for (double step : {1.0, 0.5, 0.25, 0.1}) {
      const double c = rollout(f, p0, w0, p_ref, u_des, u_, step, p_try_, w_try_, u_try_);
      if (std::isfinite(c) && c < cost) {
        cost = c;
        p_.swap(p_try_);
        w_.swap(w_try_);
        u_.swap(u_try_);
        accepted = true;
        break;
      }
    }
    if (!accepted) reg = std::max(1e-6, reg * 10.0);
    else reg *= 0.1;
  }
  if (!have_gains) {
    for (int i = 0; i < n; ++i) f.stepWithMemory(p_[i], w_[i], u_[i], &a_[i], &c_[i], &b_[i]);
    double expected;
    if (!backward(p_ref, u_des, reg, &expected) && !backward(p_ref, u_des, std::max(reg, 1e-6), &expected)) return false;
  }
  cost_ = cost;
  return allFinite(u_) && allFinite(p_) && allFinite(kp_) && allFinite(kw_);
}

IlqgPressureController::IlqgPressureController(const ParametricModel& model, const IlqgParams& params,
                                               int solve_every)
    : model_(model), solver_(params), solve_every_(std::max(1, solve_every)) {
  // Every buffer at its final size now, so that update() never allocates.
  const auto n = static_cast<std::size_t>(solver_.params().horizon);
  p_ref_.assign(n + 1, 0.0);
  u_des_.assign(n + 1, 0.0);
  warm_.assign(n, 0.0);
  policy_.p.assign(n + 1, 0.0);
  policy_.w.assign(n + 1, 0.0);
  policy_.u.assign(n, 0.0);
  policy_.kp.assign(n, 0.0);
  policy_.kw.assign(n, 0.0);
}

void IlqgPressureController::reset() {
  policy_.valid = false;  // the buffers stay (no allocation when the cylinder is driven again)
  have_last_ = false;
  disturbance_ = 0.0;
}

void IlqgPressureController::updateDisturbance(double t, double p_meas, double w_last, const ParametricInputs& in) {
  // Offset-free MPC (disturbance model x_d' = x_d, estimated from the one-step prediction
  // error). Over [last_t, t] the valve held last tick's command (w then) for the dead time
  // and this tick's w_last (the command actually applied) after it. The model's prediction
  // from the last measurement, plus the current bias, is compared with the new measurement;
  // the bias moves by a fraction of the error rate. With the true bias D the estimate obeys
  // d <- d + g (D - d) + noise: a first-order filter of D with pole 1 - g.
  // last_p_ is the previous estimate (the measurement when measurement_gain = 1).
  const IlqgParams& prm = solver_.params();
  p_est_ = p_meas;
  if (have_last_ && std::isfinite(p_meas)) {
    const double dt = t - last_t_;
    if (dt > 0 && dt < 0.1) {
      const double pred = model_.stepDelayed(last_p_, last_w_, w_last, dt, last_in_) + disturbance_ * dt;
      const double e = p_meas - pred;
      if (prm.disturbance_gain > 0) {
        const double next = disturbance_ + prm.disturbance_gain * e / dt;
        if (std::isfinite(next)) disturbance_ = std::clamp(next, -prm.disturbance_limit, prm.disturbance_limit);
      }
      if (std::isfinite(pred)) {
        const double inside = prm.measurement_band > 0 ? std::clamp(e, -prm.measurement_band, prm.measurement_band) : e;
        p_est_ = pred + prm.measurement_gain * inside + (e - inside);
      }
    } else if (!(dt > 0)) {
      disturbance_ = 0.0;  // time went backwards: start over
    }
  }
  (void)in;
}

double IlqgPressureController::evaluate(double t, double p_meas, double w_last) const {
  if (!policy_.valid) return kNaN;
  const auto n = static_cast<int>(policy_.u.size());
  const int i = static_cast<int>(std::floor((t - policy_.t0) / policy_.dt + 1e-6));
  if (i < 0 || i >= n) return kNaN;
  const IlqgParams& prm = solver_.params();
  const double dx_p = p_meas - policy_.p[i], dx_w = w_last - policy_.w[i];
  const double u = policy_.u[i] + prm.feedback_fraction * (policy_.kp[i] * dx_p + policy_.kw[i] * dx_w);
  return std::isfinite(u) ? std::clamp(u, prm.u_min, prm.u_max) : kNaN;
}

double IlqgPressureController::update(double t, double p_meas, double w_last, const ParametricInputs& in,
                                      const double* p_ref, int n_ref, double dt_ref, ControlStats* stats,
                                      bool may_solve) {
  const IlqgParams& prm = solver_.params();
  const int n = prm.horizon;
  if (stats) *stats = ControlStats{};
  updateDisturbance(t, p_meas, w_last, in);
  // Scheduled once solve_every periods have passed since the plan (half a period early, for
  // the ticks' jitter), or when the clock went back; one that may not run now stays scheduled.
  const double since_plan = t - policy_.t0;
  const bool scheduled = since_plan < 0 || since_plan >= (solve_every_ - 0.5) * prm.dt;
  const bool due = (scheduled && may_solve) || !policy_.valid;
  if (due && n_ref > 0 && std::isfinite(p_meas) && std::isfinite(w_last)) {
    const auto start = std::chrono::steady_clock::now();
    resampleReference(p_ref, n_ref, dt_ref, 0.0, prm.dt, n + 1, p_ref_.data());
    // Warm start: previous controls shifted by the time elapsed since that solve.
    const bool warm = policy_.valid;
    if (warm) {
      const int shift = static_cast<int>(std::lround((t - policy_.t0) / prm.dt));
      for (int i = 0; i < n; ++i) warm_[i] = policy_.u[std::min(std::max(i + shift, 0), n - 1)];
    }
    if (prm.u_des_steady_state) {
      // Model steady-state inverse of the reference. Smooth in time, so solved every 10th
      // sample and interpolated.
      constexpr int kEvery = 10;
      for (int i = 0; i <= n; i += kEvery)
        u_des_[i] = model_.inverseSteadyState(p_ref_[i], in, prm.u_min, prm.u_max);
      const int last = (n / kEvery) * kEvery;
      if (last != n) u_des_[n] = model_.inverseSteadyState(p_ref_[n], in, prm.u_min, prm.u_max);
      for (int i = 0; i <= n; ++i) {
        if (i % kEvery != 0 && i != n) {
          const int a = (i / kEvery) * kEvery, b = std::min(a + kEvery, n);
          u_des_[i] = u_des_[a] + (u_des_[b] - u_des_[a]) * (i - a) / static_cast<double>(b - a);
        }
      }
    } else {
      // Proximal: stay near the previous plan (or the applied command before the first
      // solve). It cannot bias where the plan settles, only how far one solve moves it.
      for (int i = 0; i <= n; ++i) u_des_[i] = warm ? warm_[std::min(i, n - 1)] : w_last;
    }
    const ParametricDynamics dyn(model_, in, prm.dt, disturbance_);
    const bool ok = solver_.solve(dyn, p_est_, w_last, p_ref_.data(), u_des_.data(), warm_.data(), warm ? n : 0,
                                  prm.iterations);
    if (ok) {
      // Copies into buffers of the same size: no allocation.
      policy_.valid = true;
      policy_.t0 = t;
      policy_.dt = prm.dt;
      policy_.p = solver_.p();
      policy_.w = solver_.w();
      policy_.u = solver_.u();
      policy_.kp = solver_.gainP();
      policy_.kw = solver_.gainW();
    }
    if (stats) {
      stats->solved = ok;
      stats->rejected = !ok;
      stats->solve_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
  }
  if (std::isfinite(p_meas) && std::isfinite(w_last)) {
    have_last_ = true;
    last_t_ = t;
    last_p_ = p_est_;
    last_w_ = w_last;
    last_in_ = in;
  }
  return evaluate(t, p_est_, w_last);
}

bool setIlqgParam(IlqgParams& p, const std::string& name, double value) {
  const auto integer = [&](int& field) { field = static_cast<int>(std::lround(value)); };
  if (name == "horizon") integer(p.horizon);
  else if (name == "dt") p.dt = value;
  else if (name == "alpha_p") p.alpha_p = value;
  else if (name == "alpha_u") p.alpha_u = value;
  else if (name == "alpha_w") p.alpha_w = value;
  else if (name == "u_min") p.u_min = value;
  else if (name == "u_max") p.u_max = value;
  else if (name == "iterations") integer(p.iterations);
  else if (name == "feedback_fraction") p.feedback_fraction = value;
  else if (name == "jump_threshold") p.jump_threshold = value;
  else if (name == "jump_iterations") integer(p.jump_iterations);
  else if (name == "disturbance_gain") p.disturbance_gain = value;
  else if (name == "disturbance_limit") p.disturbance_limit = value;
  else if (name == "measurement_gain") p.measurement_gain = value;
  else if (name == "measurement_band") p.measurement_band = value;
  else return false;
  return true;
}

void PidfParams::validate() const {
  if (!(kp >= 0) || !(ki >= 0) || !(kd >= 0) || !std::isfinite(kp + ki + kd))
    throw std::invalid_argument("pidf: gains kp, ki, kd must be finite and >= 0");
  if (!(filter_hz > 0)) throw std::invalid_argument("pidf: filter_hz must be > 0");
  if (!(feedforward_advance >= 0 && feedforward_advance <= 0.1))
    throw std::invalid_argument("pidf: feedforward_advance must be in [0, 0.1] s");
  if (!(u_min < u_max) || u_min < -5 || u_max > 5) throw std::invalid_argument("pidf: need -5 <= u_min < u_max <= 5");
}

PidfController::PidfController(const ParametricModel& model, const PidfParams& params)
    : model_(model), params_(params) {
  params_.validate();
}

void PidfController::reset() {
  started_ = false;
  integral_ = last_error_ = derivative_ = 0;
}

double PidfController::update(double t, double p_meas, double /*w_last*/, const ParametricInputs& in,
                              const double* p_ref, int n_ref, double dt_ref, ControlStats* stats,
                              bool /*may_solve: nothing to solve*/) {
  if (stats) *stats = ControlStats{};
  if (n_ref < 1 || !std::isfinite(p_meas) || !std::isfinite(p_ref[0])) return kNaN;
  const double e = p_ref[0] - p_meas;  // Pa (the gains are per Pa)
  const double dt = started_ ? t - last_t_ : 0.0;
  if (started_ && dt > 0) {
    const double raw = (e - last_error_) / dt;
    const double blend = -std::expm1(-dt * 2.0 * M_PI * params_.filter_hz);
    derivative_ += blend * (raw - derivative_);
  }
  double ff = 0.0;
  if (params_.feedforward) {
    double ahead = p_ref[0];
    if (params_.feedforward_advance > 0 && n_ref > 1 && dt_ref > 0)
      resampleReference(p_ref, n_ref, dt_ref, params_.feedforward_advance, dt_ref, 1, &ahead);
    if (!std::isfinite(ahead)) return kNaN;
    ff = model_.inverseSteadyState(ahead, in, params_.u_min, params_.u_max);
  }
  const double unclamped = ff + params_.kp * e + params_.ki * integral_ + params_.kd * derivative_;
  // Integrate only while not pushing further into saturation (anti-windup).
  const bool saturated = (unclamped > params_.u_max && e > 0) || (unclamped < params_.u_min && e < 0);
  if (started_ && dt > 0 && !saturated) integral_ += e * dt;
  started_ = true;
  last_t_ = t;
  last_error_ = e;
  const double u = std::clamp(unclamped, params_.u_min, params_.u_max);
  return std::isfinite(u) ? u : kNaN;
}

void resampleReference(const double* in, int n_in, double dt_in, double offset, double dt_out, int n, double* out) {
  for (int k = 0; k < n; ++k) {
    const double x = (offset + k * dt_out) / dt_in;
    if (n_in == 1 || x >= n_in - 1) { out[k] = in[n_in - 1]; continue; }
    if (x <= 0) { out[k] = in[0]; continue; }
    const int i = static_cast<int>(x);
    const double f = x - i;
    out[k] = in[i] + f * (in[i + 1] - in[i]);
  }
}

}  // namespace adroit::pneumatics
