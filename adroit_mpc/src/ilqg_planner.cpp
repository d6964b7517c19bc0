#include "adroit_mpc/ilqg_planner.h"

#include <adroit_core/timing_stats.h>

#include <stdexcept>

namespace adroit_mpc {

void IlqgPlanner::initialize(const mjModel* m, const Task& task, const PlannerSettings& settings) {
  knots_ = validatePlannerSettings(m, settings);
  model_ = m;
  settings_ = settings;
  task_ = task.clone();
  space_.initialize(m, settings.synergies, settings.tension_step_weight);
  const int nu = space_.size();
  nx_ = 2 * m->nv + m->na;
  task_->bind(m, nu - m->nu);
  pool_ = std::make_unique<adroit::ThreadPool>(settings.threads);
  const int workers = static_cast<int>(pool_->size());
  workspaces_.resize(workers);
  for (auto& w : workspaces_) w.initialize(m, *task_);
  cost_derivatives_.resize(workers);
  for (auto& c : cost_derivatives_) c.resize(nx_, nu);
  x_interp_.assign(workers, Eigen::VectorXd::Zero(m->nq + m->nv + m->na));
  u_interp_.assign(workers, Eigen::VectorXd::Zero(nu));
  feedback_.assign(workers, Eigen::VectorXd::Zero(nu));

  state_.qpos.assign(m->qpos0, m->qpos0 + m->nq);
  state_.qvel.assign(m->nv, 0.0);
  state_.act.assign(m->na, 0.0);
  initial_.resize(m->nq + m->nv + m->na);

  FdSettings fd;
  fd.epsilon = settings.fd_epsilon;
  fd.centered = settings.fd_centered;
  fd.skip = settings.derivative_skip;
  fd.warmstart_from_nominal = settings.fd_warmstart;
  fd.force_space_controls = settings.fd_force_space;
  fd.max_age = settings.derivative_max_age;
  fd.reuse_tolerance = settings.derivative_reuse_tolerance;
  fd_.initialize(m, knots_, workers, fd);
  B_act_.assign(knots_, Eigen::MatrixXd::Zero(nx_, m->nu));
  lq_.resize(nx_, nu, knots_);
  backward_ = std::make_unique<adroit::BackwardPass>(nx_, nu, knots_);
  gains_.resize(nx_, nu, knots_);

  nominal_.resize(m, knots_, nu);
  candidates_.resize(workers);
  for (auto& c : candidates_) c.resize(m, knots_, nu);
  candidate_alpha_.assign(workers, 0.0);
  previous_.resize(m, knots_, nu);
  previous_gains_.assign(knots_, Eigen::MatrixXd::Zero(nu, nx_));
  best_.resize(m, knots_, nu);
  best_gains_.assign(knots_, Eigen::MatrixXd::Zero(m->nu, nx_));
  writeTrajectory(best_, best_view_);
  have_best_ = false;
  reset();
}

void IlqgPlanner::setState(const PlannerState& s) {
  if (!model_) throw std::logic_error("IlqgPlanner::setState before initialize()");
  copyPlannerState(model_, s, state_);
}

void IlqgPlanner::setTask(const Task& task) { task_->copyParametersFrom(task); }

void IlqgPlanner::reset() {
  have_previous_ = false;
  fd_.forget();  // the safe warm start is another trajectory
  schedule_ = adroit::RegularizationSchedule{};
  schedule_.mu_min = settings_.mu_initial > 0 ? settings_.mu_initial : schedule_.mu_min;
  schedule_.mu = settings_.mu_initial;
}

void IlqgPlanner::warmStartRollout(OptimizeReport& report) {
  adroit::Stopwatch clock;
  const mjModel* m = model_;
  const double dt = m->opt.timestep;
  const int T = knots_;
  RolloutWorkspace& w = workspaces_[0];
  Eigen::VectorXd& x_nom = x_interp_[0];
  Eigen::VectorXd& fb = feedback_[0];
  auto law = [&](int t, const mjData* d, Eigen::VectorXd& u) {
    if (!have_previous_) {
      space_.safeControls(u);
      return;
    }
    // The previous plan at this knot's time: linear between its knots, held past its end.
    const double s = (d->time - previous_.times[0]) / dt;
    int i = 0;
    double a = 0;
    if (s >= T - 1) {
      i = T - 1;
    } else if (s > 0) {
      i = static_cast<int>(s);
      a = s - i;
    }
    const int j = std::min(i + 1, T - 1);
    x_nom = (1 - a) * previous_.states[i] + a * previous_.states[j];
    u = (1 - a) * previous_.controls[i] + a * previous_.controls[j];
    stateDifference(m, x_nom.data(), d->qpos, d->qvel, d->act, w.dx);
    fb.noalias() = previous_gains_[i] * w.dx;
    u += (1 - a) * fb;
    if (a > 0) {
      fb.noalias() = previous_gains_[j] * w.dx;
      u += a * fb;
    }
    (void)t;
  };
  // The cost derivatives of the nominal are taken here, where mj_forward has just run at
  // every knot (saves one mj_forward per knot against a separate pass).
  CostDerivatives& c = cost_derivatives_[0];
  double cost_time = 0;
  auto knot_cost = [&](int t, const mjData* d, const Eigen::VectorXd& u) {
    adroit::Stopwatch cost_clock;
    struct Accumulate {
      double& total;
      adroit::Stopwatch& clock;
      ~Accumulate() { total += clock.elapsed(); }
    } accumulate{cost_time, cost_clock};
    c.setZero();
    if (t == T) {
      const double cost = task_->terminalCostDerivatives(m, d, nominal_.times[t], *w.scratch, c);
      lq_.lx[t] = c.lx;
      lq_.lxx[t] = c.lxx;
      return cost;
    }
    const double cost = task_->runningCostDerivatives(m, d, u, nominal_.times[t], *w.scratch, c);
    lq_.lx[t] = c.lx;
    lq_.lxx[t] = c.lxx;
    lq_.lu[t] = c.lu;
    lq_.luu[t] = c.luu;
    lq_.lux[t] = c.lux;
    return cost;
  };
  rollout(m, space_, initial_, state_.time, law, knot_cost, w, nominal_);
  report.rollout += clock.elapsed() - cost_time;
  clock.restart();
  addStepDerivatives();
  report.cost += cost_time + clock.elapsed();
}

void IlqgPlanner::addStepDerivatives() {
  if (space_.stepWeight() == 0) return;
  for (int t = 0; t < knots_; ++t) space_.addStepDerivatives(nominal_, t, lq_.lu[t], lq_.luu[t]);
}

void IlqgPlanner::computeCostDerivatives() {
  const mjModel* m = model_;
  const int T = knots_;
  pool_->parallelForWorkers(T + 1, [&](std::size_t index, std::size_t w) {
    const int t = static_cast<int>(index);
    mjData* d = workspaces_[w].data.get();
    CostDerivatives& c = cost_derivatives_[w];
    c.setZero();
    setKnotState(m, d, nominal_.states[t], nominal_.ctrl[std::min(t, T - 1)], nominal_.times[t]);
    mj_forward(m, d);
    if (t < T) {
      task_->runningCostDerivatives(m, d, nominal_.controls[t], nominal_.times[t], *workspaces_[w].scratch, c);
      lq_.lu[t] = c.lu;
      lq_.luu[t] = c.luu;
      lq_.lux[t] = c.lux;
    } else {
      task_->terminalCostDerivatives(m, d, nominal_.times[t], *workspaces_[w].scratch, c);
    }
    lq_.lx[t] = c.lx;
    lq_.lxx[t] = c.lxx;
  });
  addStepDerivatives();
}

bool IlqgPlanner::lineSearch(const adroit::BackwardPassResult& pass, OptimizeReport& report) {
  const mjModel* m = model_;
  const int workers = static_cast<int>(candidates_.size());
  const double J0 = nominal_.total;
  double alpha = line_search.initial_step;
  for (int tried = 0; tried < line_search.max_steps; tried += workers) {
    const int batch = std::min(workers, line_search.max_steps - tried);
    for (int c = 0; c < batch; ++c, alpha *= line_search.step_factor) candidate_alpha_[c] = alpha;
    pool_->parallelForWorkers(batch, [&](std::size_t c, std::size_t w) {
      const double a = candidate_alpha_[c];
      RolloutWorkspace& ws = workspaces_[w];
      rollout(m, *task_, space_, initial_, state_.time,
              [&](int t, const mjData* d, Eigen::VectorXd& u) {
                stateDifference(m, nominal_.states[t].data(), d->qpos, d->qvel, d->act, ws.dx);
                u = nominal_.controls[t] + a * gains_.k[t];
                u.noalias() += gains_.K[t] * ws.dx;
              },
              ws, candidates_[c]);
    });
    // The cheapest candidate of the batch that passes the acceptance test.
    int best = -1;
    for (int c = 0; c < batch; ++c) {
      const double J = candidates_[c].total;
      if (!std::isfinite(J)) continue;
      const double a = candidate_alpha_[c];
      const double expected = -(a * pass.dV[0] + a * a * pass.dV[1]);
      const double ratio = expected > 0 ? (J0 - J) / expected : (J < J0 ? 1.0 : -1.0);
      if (ratio > line_search.min_reduction_ratio && (best < 0 || J < candidates_[best].total)) best = c;
    }
    if (best >= 0) {
      report.alpha = candidate_alpha_[best];
      std::swap(nominal_, candidates_[best]);  // equal sizes: storage swap, no allocation
      return true;
    }
  }
  return false;
}

void IlqgPlanner::publish() {
  best_ = nominal_;  // equal sizes: element-wise copies
  for (int t = 0; t < knots_; ++t) space_.chainGains(best_.controls[t], gains_.K[t], best_gains_[t]);
  writeTrajectory(best_, best_view_);
  have_best_ = true;
}

OptimizeReport IlqgPlanner::optimize() {
  if (!model_) throw std::logic_error("IlqgPlanner::optimize before initialize()");
  adroit::Stopwatch total_clock;
  OptimizeReport report;
  const mjModel* m = model_;
  mju_copy(initial_.data(), state_.qpos.data(), m->nq);
  mju_copy(initial_.data() + m->nq, state_.qvel.data(), m->nv);
  if (m->na) mju_copy(initial_.data() + m->nq + m->nv, state_.act.data(), m->na);
  if (have_previous_) space_.holdApplied(previous_, state_.time);
  else space_.forgetApplied();

  warmStartRollout(report);
  report.cost_before = report.cost_after = nominal_.total;
  if (!std::isfinite(nominal_.total)) {
    reset();
    report.diverged = true;
    report.total = total_clock.elapsed();
    return report;
  }

  for (int it = 0; it < settings_.iterations; ++it) {
    report.iterations = it + 1;
    adroit::Stopwatch clock;
    fd_.compute(*pool_, nominal_.states, nominal_.ctrl, nominal_.times, lq_.A, B_act_);
    report.derivative_knots += fd_.lastEvaluatedKnots();
    for (int t = 0; t < knots_; ++t) space_.chainRule(B_act_[t], nominal_.controls[t], lq_.B[t]);
    report.derivatives += clock.elapsed();

    if (it > 0) {  // the first iteration's were taken in the warm-start rollout
      clock.restart();
      computeCostDerivatives();
      report.cost += clock.elapsed();
    }

    clock.restart();
    adroit::BackwardPassResult pass;
    for (;;) {
      pass = backward_->run(lq_, nominal_.controls, space_.lower(), space_.upper(), schedule_.mu, gains_);
      if (pass.ok) break;
      schedule_.increase();
      if (schedule_.exhausted()) break;
    }
    report.backward += clock.elapsed();
    report.mu = schedule_.mu;
    if (!pass.ok) {
      // No positive-definite Q_uu even with large mu: keep the warm-start rollout, no feedback.
      for (auto& K : gains_.K) K.setZero();
      schedule_.mu = settings_.mu_initial;
      break;
    }

    clock.restart();
    const bool accepted = lineSearch(pass, report);
    report.line_search += clock.elapsed();
    if (accepted) {
      report.improved = true;
      schedule_.decrease();
    } else {
      schedule_.increase();
      if (schedule_.exhausted()) schedule_.mu = settings_.mu_initial;
      break;
    }
  }
  report.cost_after = nominal_.total;

  previous_ = nominal_;
  previous_gains_ = gains_.K;
  have_previous_ = true;
  publish();
  report.total = total_clock.elapsed();
  return report;
}

void IlqgPlanner::policy(PlanPolicy& out) const {
  if (!have_best_) throw std::logic_error("IlqgPlanner::policy: no plan yet (call optimize() first)");
  writePolicy(model_, best_, &best_gains_, out);
}

}  // namespace adroit_mpc
