#include "adroit_mpc/spline_sampling.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace adroit_mpc {

// --------------------------------------------------------------------------- ControlSpline

void ControlSpline::resize(int points, int controls, int knots) {
  values.assign(points, Eigen::VectorXd::Zero(controls));
  knots_ = std::max(1, knots);
  t0 = 0;
}

const Eigen::VectorXd& ControlSpline::atKnot(int knot) const {
  return values[std::min(points() - 1, knot * points() / knots_)];
}

int ControlSpline::shiftTo(double time, double horizon) {
  const int n = points();
  const double spacing = horizon / n;
  const double shift = time - t0;
  // Old point index of new point j, limited to [-1, n] before the cast (a large time jump).
  const auto source = [&](int j) {
    const double k = std::floor((j * spacing + shift) / spacing + 1e-9);
    return static_cast<int>(std::min<double>(n, std::max(-1.0, k)));
  };
  // In place: forwards in time point j reads a later point, so ascending order reads each
  // source before it is overwritten; backwards in time, descending order does.
  if (shift >= 0) {
    for (int j = 0; j < n; ++j) values[j] = values[std::min(n - 1, source(j))];
  } else {
    for (int j = n - 1; j >= 0; --j) values[j] = values[std::max(0, source(j))];
  }
  t0 = time;
  int first_new = 0;
  while (first_new < n && source(first_new) <= n - 1) ++first_new;
  return first_new;
}

void ControlSpline::setConstant(const Eigen::VectorXd& value) {
  for (auto& v : values) v = value;
}

void ControlSpline::copyValuesFrom(const ControlSpline& other) {
  for (int j = 0; j < points(); ++j) values[j] = other.values[j];
}

// ------------------------------------------------------------------- SplineSamplingPlanner

void SplineSamplingPlanner::initializeSampling(const mjModel* m, const Task& task, const PlannerSettings& settings) {
  knots_ = validatePlannerSettings(m, settings);
  model_ = m;
  settings_ = settings;
  task_ = task.clone();
  space_.initialize(m, settings.synergies, settings.tension_step_weight);
  task_->bind(m, space_.size() - m->nu);
  pool_ = std::make_unique<adroit::ThreadPool>(settings.threads);
  workspaces_.resize(pool_->size());
  for (auto& w : workspaces_) w.initialize(m, *task_);

  const int n = space_.size();
  state_.qpos.assign(m->qpos0, m->qpos0 + m->nq);
  state_.qvel.assign(m->nv, 0.0);
  state_.act.assign(m->na, 0.0);
  state_.time = 0;
  initial_.resize(m->nq + m->nv + m->na);
  mean_.resize(settings.spline_points, n, knots_);
  candidate_splines_.assign(settings.samples, mean_);
  candidates_.resize(settings.samples);
  for (auto& c : candidates_) c.resize(m, knots_, n);
  noise_.clear();
  for (int i = 0; i < settings.samples; ++i) noise_.emplace_back(settings.seed + 7919 * static_cast<std::uint64_t>(i));
  order_.resize(settings.samples);
  best_.resize(m, knots_, n);
  writeTrajectory(best_, best_view_);
  have_best_ = false;
}

void SplineSamplingPlanner::setState(const PlannerState& s) {
  if (!model_) throw std::logic_error(name() + " planner: setState before initialize()");
  copyPlannerState(model_, s, state_);
}

void SplineSamplingPlanner::setTask(const Task& task) { task_->copyParametersFrom(task); }

void SplineSamplingPlanner::resetMean() {
  space_.safeControls(mean_.values.front());
  mean_.setConstant(mean_.values.front());
  mean_.t0 = state_.time;
}

int SplineSamplingPlanner::beginOptimize() {
  if (!model_) throw std::logic_error(name() + " planner: optimize before initialize()");
  const mjModel* m = model_;
  mju_copy(initial_.data(), state_.qpos.data(), m->nq);
  mju_copy(initial_.data() + m->nq, state_.qvel.data(), m->nv);
  if (m->na) mju_copy(initial_.data() + m->nq + m->nv, state_.act.data(), m->na);
  if (have_best_) space_.holdApplied(best_, state_.time);
  else space_.forgetApplied();
  return mean_.shiftTo(state_.time, settings_.horizon);
}

void SplineSamplingPlanner::rolloutSpline(const ControlSpline& spline, KnotTrajectory& out) {
  rollout(model_, *task_, space_, initial_, state_.time,
          [&](int t, const mjData*, Eigen::VectorXd& u) { u = spline.atKnot(t); }, workspaces_.front(), out);
}

void SplineSamplingPlanner::sampleAndRollout(const ControlSpline& sigma) {
  pool_->parallelForWorkers(candidates_.size(), [&](std::size_t i, std::size_t w) {
    ControlSpline& spline = candidate_splines_[i];
    spline.t0 = mean_.t0;
    for (int j = 0; j < spline.points(); ++j) {
      spline.values[j] = mean_.values[j];
      if (i == 0) continue;  // the mean itself competes
      for (int c = 0; c < spline.values[j].size(); ++c) spline.values[j][c] += sigma.values[j][c] * noise_[i]();
      space_.clamp(spline.values[j]);
    }
    rollout(model_, *task_, space_, initial_, state_.time,
            [&](int t, const mjData*, Eigen::VectorXd& u) { u = spline.atKnot(t); }, workspaces_[w], candidates_[i]);
  });
}

const int* SplineSamplingPlanner::rankCandidates(int n) {
  for (std::size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
  n = std::min(std::max(n, 1), static_cast<int>(order_.size()));
  std::partial_sort(order_.begin(), order_.begin() + n, order_.end(), [&](int a, int b) {
    const double ca = candidates_[a].total, cb = candidates_[b].total;
    return ca < cb || (ca == cb && a < b);
  });
  return order_.data();
}

void SplineSamplingPlanner::keepPlan(KnotTrajectory& plan) {
  std::swap(best_, plan);  // same sizes: storage swap, no allocation
  writeTrajectory(best_, best_view_);
  have_best_ = true;
}

OptimizeReport& SplineSamplingPlanner::diverged(OptimizeReport& report, double elapsed) {
  reset();
  report.diverged = true;
  report.total = elapsed;
  return report;
}

void SplineSamplingPlanner::policy(PlanPolicy& out) const {
  if (!have_best_) throw std::logic_error(name() + " planner: policy() before the first optimize()");
  writePolicy(model_, best_, nullptr, out);
}

}  // namespace adroit_mpc
