#include "adroit_mpc/planner.h"

#include "adroit_mpc/cem_planner.h"
#include "adroit_mpc/ilqg_planner.h"
#include "adroit_mpc/sampling_planner.h"

#include <algorithm>
#include <stdexcept>

namespace adroit_mpc {

// ---------------------------------------------------------------------------- PlanPolicy

void PlanPolicy::bind(const mjModel* m) {
  model_ = m;
  x_nominal_.resize(m->nq + m->nv + m->na);
  dx_.resize(2 * m->nv + m->na);
  u_.resize(m->nu);
}

void PlanPolicy::deviation(double t, const double* qpos, const double* qvel, const double* act) const {
  if (!model_) throw std::logic_error("PlanPolicy: bind() the planning model first");
  if (policy.knots() == 0) throw std::logic_error("PlanPolicy: the policy is empty (no plan yet)");
  policy.nominalState(t, x_nominal_);
  stateDifference(model_, x_nominal_.data(), qpos, qvel, act, dx_);
}

void PlanPolicy::clampInto(double* ctrl) const {
  for (int i = 0; i < model_->nu; ++i) {
    double u = u_[i];
    if (model_->actuator_ctrllimited[i])
      u = std::min(std::max(u, model_->actuator_ctrlrange[2 * i]), model_->actuator_ctrlrange[2 * i + 1]);
    ctrl[i] = u;
  }
}

void PlanPolicy::action(double t, const double* qpos, const double* qvel, const double* act, double* ctrl,
                        double feedback_scale) const {
  deviation(t, qpos, qvel, act);
  policy.action(t, dx_, u_, feedback_scale);
  clampInto(ctrl);
}

int PlanPolicy::reference(double t, const double* qpos, const double* qvel, const double* act, int max_samples,
                          double* out, double feedback_scale) const {
  deviation(t, qpos, qvel, act);
  const double last = policy.t0 + (policy.knots() - 1) * policy.dt;
  int samples = 0;
  for (; samples < max_samples; ++samples) {
    const double ts = t + samples * policy.dt;
    if (samples > 0 && ts > last + 1e-9) break;
    policy.action(ts, dx_, u_, feedback_scale);
    clampInto(out + static_cast<std::size_t>(samples) * model_->nu);
  }
  return samples;
}

// ------------------------------------------------------------------------- shared pieces

int validatePlannerSettings(const mjModel* m, const PlannerSettings& s) {
  auto bad = [](const std::string& what) { throw std::invalid_argument("planner settings: " + what); };
  if (!m) bad("no model");
  if (!(s.dt > 0)) bad("dt must be positive, got " + std::to_string(s.dt));
  if (std::fabs(m->opt.timestep - s.dt) > 1e-9 * s.dt)
    bad("dt " + std::to_string(s.dt) + " differs from the planning model's timestep " +
        std::to_string(m->opt.timestep) + " (applyPlanningSettings sets it)");
  if (!(s.horizon > 0)) bad("horizon must be positive, got " + std::to_string(s.horizon));
  const int knots = static_cast<int>(std::lround(s.horizon / s.dt));
  if (knots < 2) bad("horizon / dt gives " + std::to_string(knots) + " knots, need at least 2");
  if (s.threads < 0) bad("threads must be >= 0");
  if (s.iterations < 1) bad("iterations must be >= 1");
  if (!(s.fd_epsilon > 0)) bad("fd_epsilon must be positive");
  if (s.derivative_skip < 1) bad("derivative_skip must be >= 1");
  if (!(s.derivative_max_age >= 0) || !std::isfinite(s.derivative_max_age))
    bad("derivative_max_age must be >= 0 s (0: no reuse) and finite, got " + std::to_string(s.derivative_max_age));
  if (!(s.derivative_reuse_tolerance > 0) || !std::isfinite(s.derivative_reuse_tolerance))
    bad("derivative_reuse_tolerance must be positive and finite, got " + std::to_string(s.derivative_reuse_tolerance));
  if (!(s.mu_initial >= 0)) bad("mu_initial must be >= 0");
  if (!(s.feedback_scale >= 0 && s.feedback_scale <= 1)) bad("feedback_scale must be in [0, 1]");
  if (s.samples < 1) bad("samples must be >= 1");
  if (!(s.noise_scale >= 0)) bad("noise_scale must be >= 0");
  if (s.spline_points < 1) bad("spline_points must be >= 1");
  if (s.cem_elites < 1 || s.cem_elites > s.samples)
    bad("cem_elites must be in [1, samples = " + std::to_string(s.samples) + "], got " + std::to_string(s.cem_elites));
  if (!(s.cem_std_initial > 0) || !std::isfinite(s.cem_std_initial))
    bad("cem_std_initial must be positive and finite, got " + std::to_string(s.cem_std_initial));
  if (!(s.tension_step_weight >= 0) || !std::isfinite(s.tension_step_weight))
    bad("tension_step_weight must be >= 0 and finite, got " + std::to_string(s.tension_step_weight));
  if (!(s.cem_std_min > 0) || !(s.cem_std_min <= s.cem_std_initial))
    bad("cem_std_min must be positive and <= cem_std_initial (" + std::to_string(s.cem_std_initial) + "), got " +
        std::to_string(s.cem_std_min));
  return knots;
}

void copyPlannerState(const mjModel* m, const PlannerState& in, PlannerState& out) {
  if (static_cast<int>(in.qpos.size()) != m->nq || static_cast<int>(in.qvel.size()) != m->nv ||
      static_cast<int>(in.act.size()) != m->na)
    throw std::invalid_argument("planner state: sizes qpos " + std::to_string(in.qpos.size()) + " qvel " +
                                std::to_string(in.qvel.size()) + " act " + std::to_string(in.act.size()) +
                                " do not match the model (" + std::to_string(m->nq) + ", " +
                                std::to_string(m->nv) + ", " + std::to_string(m->na) + ")");
  out.time = in.time;
  std::copy(in.qpos.begin(), in.qpos.end(), out.qpos.begin());
  std::copy(in.qvel.begin(), in.qvel.end(), out.qvel.begin());
  std::copy(in.act.begin(), in.act.end(), out.act.begin());
}

void ControlSpace::initialize(const mjModel* m, bool synergies, double step_weight) {
  if (!(step_weight >= 0) || !std::isfinite(step_weight))
    throw std::invalid_argument("planner: tension_step_weight must be >= 0 and finite, got " + std::to_string(step_weight));
  nu_ = m->nu;
  has_synergies_ = synergies;
  const int n = nu_ + (synergies ? Synergies::kCount : 0);
  lower_.resize(n);
  upper_.resize(n);
  for (int i = 0; i < nu_; ++i) {
    if (!m->actuator_ctrllimited[i])
      throw std::invalid_argument("planner: actuator " + std::to_string(i) +
                                  " has no ctrlrange (the planners need bounded controls)");
    lower_[i] = m->actuator_ctrlrange[2 * i];
    upper_[i] = m->actuator_ctrlrange[2 * i + 1];
  }
  if (synergies) {
    synergies_ = Synergies(m);
    lower_.tail(Synergies::kCount).setConstant(-1);
    upper_.tail(Synergies::kCount).setConstant(1);
  }
  ctrl_.resize(nu_);
  mask_.resize(nu_);
  step_weight_ = step_weight;
  step_scale_.resize(nu_);
  for (int i = 0; i < nu_; ++i) {
    const double range = upper_[i] - lower_[i];
    step_scale_[i] = range > 0 ? step_weight / (range * range) : 0.0;
  }
  applied_ = lower_.head(nu_);
  has_applied_ = false;
  step_gradient_.resize(nu_);
  step_curvature_.resize(nu_);
  scaled_map_.resize(nu_, synergies ? Synergies::kCount : 0);
}

void ControlSpace::toCtrl(const Eigen::VectorXd& u, double* ctrl) const {
  if (has_synergies_) {
    synergies_.apply(u.data(), ctrl);
  } else {
    for (int i = 0; i < nu_; ++i) ctrl[i] = std::min(std::max(u[i], lower_[i]), upper_[i]);
  }
}

void ControlSpace::chainRule(const Eigen::MatrixXd& B_act, const Eigen::VectorXd& u, Eigen::MatrixXd& B) const {
  if (!has_synergies_) {
    B = B_act;
    return;
  }
  synergies_.apply(u.data(), ctrl_.data(), mask_.data());
  B.leftCols(nu_) = B_act * mask_.asDiagonal();
  B.rightCols(Synergies::kCount).noalias() = B.leftCols(nu_) * synergies_.map();
}

void ControlSpace::chainGains(const Eigen::VectorXd& u, const Eigen::MatrixXd& K, Eigen::MatrixXd& K_ctrl) const {
  if (!has_synergies_) {
    K_ctrl = K;
    return;
  }
  synergies_.apply(u.data(), ctrl_.data(), mask_.data());
  K_ctrl = K.topRows(nu_);
  K_ctrl.noalias() += synergies_.map() * K.bottomRows(Synergies::kCount);
  K_ctrl = mask_.asDiagonal() * K_ctrl;
}

void ControlSpace::safeControls(Eigen::VectorXd& u) const {
  u.head(nu_) = lower_.head(nu_);
  if (has_synergies_) u.tail(Synergies::kCount).setZero();
}

void ControlSpace::holdApplied(const KnotTrajectory& plan, double time) {
  const int T = static_cast<int>(plan.ctrl.size());
  if (T == 0) {
    has_applied_ = false;
    return;
  }
  const double dt = T > 1 ? plan.times[1] - plan.times[0] : 1.0;
  const double s = std::clamp((time - plan.times[0]) / dt, 0.0, static_cast<double>(T - 1));
  const int i = std::min(static_cast<int>(s), T - 1);
  const int j = std::min(i + 1, T - 1);
  const double a = s - i;
  applied_ = (1 - a) * plan.ctrl[i] + a * plan.ctrl[j];
  has_applied_ = true;
}

double ControlSpace::stepCost(const KnotTrajectory& plan, int t) const {
  if (step_weight_ == 0 || (t == 0 && !has_applied_)) return 0.0;
  const Eigen::VectorXd& before = t > 0 ? plan.ctrl[t - 1] : applied_;
  double sum = 0;
  for (int i = 0; i < nu_; ++i) {
    const double step = plan.ctrl[t][i] - before[i];
    sum += step_scale_[i] * step * step;
  }
  return 0.5 * sum;
}

void ControlSpace::addStepDerivatives(const KnotTrajectory& plan, int t, Eigen::VectorXd& lu,
                                      Eigen::MatrixXd& luu) const {
  if (step_weight_ == 0) return;
  const int T = static_cast<int>(plan.ctrl.size());
  step_gradient_.setZero();
  step_curvature_.setZero();
  if (t > 0 || has_applied_) {  // this knot's own step
    const Eigen::VectorXd& before = t > 0 ? plan.ctrl[t - 1] : applied_;
    step_gradient_.array() += step_scale_.array() * (plan.ctrl[t] - before).array();
    step_curvature_ += step_scale_;
  }
  if (t + 1 < T) {  // the next knot's step starts here
    step_gradient_.array() -= step_scale_.array() * (plan.ctrl[t + 1] - plan.ctrl[t]).array();
    step_curvature_ += step_scale_;
  }
  // d ctrl / d u = diag(mask) [I | S]: a control clamped at its range does not move.
  if (has_synergies_) synergies_.apply(plan.controls[t].data(), ctrl_.data(), mask_.data());
  else mask_.setOnes();
  step_gradient_.array() *= mask_.array();
  step_curvature_.array() *= mask_.array();  // mask is 0 or 1: mask^2 = mask
  lu.head(nu_) += step_gradient_;
  luu.topLeftCorner(nu_, nu_).diagonal() += step_curvature_;
  if (!has_synergies_) return;
  const Eigen::MatrixXd& S = synergies_.map();
  lu.tail(Synergies::kCount).noalias() += S.transpose() * step_gradient_;
  scaled_map_.noalias() = step_curvature_.asDiagonal() * S;
  luu.topRightCorner(nu_, Synergies::kCount) += scaled_map_;
  luu.bottomLeftCorner(Synergies::kCount, nu_) += scaled_map_.transpose();
  luu.bottomRightCorner(Synergies::kCount, Synergies::kCount).noalias() += S.transpose() * scaled_map_;
}

void KnotTrajectory::resize(const mjModel* m, int knots, int controls_size) {
  const int n_state = m->nq + m->nv + m->na;
  times.assign(knots + 1, 0.0);
  states.assign(knots + 1, Eigen::VectorXd::Zero(n_state));
  controls.assign(knots, Eigen::VectorXd::Zero(controls_size));
  ctrl.assign(knots, Eigen::VectorXd::Zero(m->nu));
  costs.assign(knots + 1, 0.0);
  total = 0;
}

void RolloutWorkspace::initialize(const mjModel* m, const Task& task) {
  data = adroit::makeData(m);
  scratch = task.makeScratch(m);
  dx.resize(2 * m->nv + m->na);
}

void writePolicy(const mjModel* m, const KnotTrajectory& plan, const std::vector<Eigen::MatrixXd>* gains,
                 PlanPolicy& out) {
  const int T = static_cast<int>(plan.ctrl.size());
  const int nx = 2 * m->nv + m->na;
  adroit::TvlgPolicy& p = out.policy;
  if (p.knots() != T || p.x.front().size() != plan.states.front().size() || p.K.front().cols() != nx ||
      p.u.front().size() != m->nu) {
    p = adroit::TvlgPolicy(m->nq + m->nv + m->na, nx, m->nu, T);
    p.u_min.resize(m->nu);
    p.u_max.resize(m->nu);
    for (int i = 0; i < m->nu; ++i) {
      p.u_min[i] = m->actuator_ctrllimited[i] ? m->actuator_ctrlrange[2 * i] : -mjMAXVAL;
      p.u_max[i] = m->actuator_ctrllimited[i] ? m->actuator_ctrlrange[2 * i + 1] : mjMAXVAL;
    }
    out.bind(m);
  }
  p.t0 = plan.times.front();
  p.dt = m->opt.timestep;
  for (int t = 0; t < T; ++t) {
    p.x[t] = plan.states[t];
    p.u[t] = plan.ctrl[t];
    if (gains) p.K[t] = (*gains)[t];
    else p.K[t].setZero();
  }
  out.cost = plan.total;
}

void writeTrajectory(const KnotTrajectory& plan, Trajectory& out) {
  if (out.states.size() != plan.states.size() || out.controls.size() != plan.controls.size() ||
      (!out.controls.empty() && out.controls.front().size() != plan.controls.front().size())) {
    out.times = plan.times;
    out.states = plan.states;
    out.ctrl = plan.ctrl;
    out.controls = plan.controls;
  }
  std::copy(plan.times.begin(), plan.times.end(), out.times.begin());
  for (std::size_t t = 0; t < plan.states.size(); ++t) out.states[t] = plan.states[t];
  for (std::size_t t = 0; t < plan.ctrl.size(); ++t) {
    out.ctrl[t] = plan.ctrl[t];
    out.controls[t] = plan.controls[t];
  }
  out.cost = plan.total;
}

void readState(const mjModel* m, const mjData* d, Eigen::VectorXd& state) {
  mju_copy(state.data(), d->qpos, m->nq);
  mju_copy(state.data() + m->nq, d->qvel, m->nv);
  if (m->na) mju_copy(state.data() + m->nq + m->nv, d->act, m->na);
}

void stateDifference(const mjModel* m, const double* nominal, const double* qpos, const double* qvel,
                     const double* act, Eigen::VectorXd& dx) {
  // qvel = (qpos2 - qpos1) / dt with dt = 1: the tangent of the nominal -> measured rotation.
  mj_differentiatePos(m, dx.data(), 1.0, nominal, qpos);
  const double* v_nominal = nominal + m->nq;
  for (int i = 0; i < m->nv; ++i) dx[m->nv + i] = qvel[i] - v_nominal[i];
  for (int i = 0; i < m->na; ++i) dx[2 * m->nv + i] = act[i] - v_nominal[m->nv + i];
}

void integrateAfterForward(const mjModel* m, mjData* d) {
  switch (m->opt.integrator) {
    case mjINT_EULER:
      mj_Euler(m, d);
      break;
    case mjINT_RK4:
      mj_RungeKutta(m, d, 4);
      break;
    default:  // implicit: 2.2.2 exposes no separate update, so step again (forward repeats)
      mj_step(m, d);
      break;
  }
}

std::unique_ptr<Planner> makePlanner(const std::string& name) {
  if (name == "ilqg") return std::make_unique<IlqgPlanner>();
  if (name == "sampling") return std::make_unique<SamplingPlanner>();
  if (name == "cem") return std::make_unique<CemPlanner>();
  throw std::invalid_argument("unknown planner '" + name + "' (known: ilqg, sampling, cem)");
}

}  // namespace adroit_mpc
