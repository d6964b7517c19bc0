#include "adroit_mpc/sampling_planner.h"

#include <adroit_core/timing_stats.h>

#include <stdexcept>

namespace adroit_mpc {

void SamplingPlanner::initialize(const mjModel* m, const Task& task, const PlannerSettings& settings) {
  knots_ = validatePlannerSettings(m, settings);
  model_ = m;
  settings_ = settings;
  task_ = task.clone();
  space_.initialize(m, settings.synergies);
  task_->bind(m, space_.size() - m->nu);
  pool_ = std::make_unique<adroit::ThreadPool>(settings.threads);
  workspaces_.resize(pool_->size());
  for (auto& w : workspaces_) w.initialize(m, *task_);

  const int n = space_.size();
  state_.qpos.assign(m->qpos0, m->qpos0 + m->nq);
  state_.qvel.assign(m->nv, 0.0);
  state_.act.assign(m->na, 0.0);
  initial_.resize(m->nq + m->nv + m->na);
  nominal_.assign(settings.spline_points, Eigen::VectorXd::Zero(n));
  candidate_splines_.assign(settings.samples, nominal_);
  candidates_.resize(settings.samples);
  for (auto& c : candidates_) c.resize(m, knots_, n);
  noise_.clear();
  for (int i = 0; i < settings.samples; ++i) noise_.emplace_back(0x5eed + 7919 * i);
  noise_sigma_ = settings.noise_scale * (space_.upper() - space_.lower());
  best_.resize(m, knots_, n);
  writeTrajectory(best_, best_view_);
  reset();
}

void SamplingPlanner::setState(const PlannerState& s) {
  if (!model_) throw std::logic_error("SamplingPlanner::setState before initialize()");
  copyPlannerState(model_, s, state_);
}

void SamplingPlanner::setTask(const Task& task) { task_->copyParametersFrom(task); }

void SamplingPlanner::reset() {
  for (auto& v : nominal_) space_.safeControls(v);
  spline_t0_ = state_.time;
  have_plan_ = true;
}

int SamplingPlanner::splineIndex(int knot) const {
  const int points = settings_.spline_points;
  return std::min(points - 1, knot * points / knots_);
}

OptimizeReport SamplingPlanner::optimize() {
  if (!model_) throw std::logic_error("SamplingPlanner::optimize before initialize()");
  adroit::Stopwatch total_clock;
  OptimizeReport report;
  const mjModel* m = model_;
  mju_copy(initial_.data(), state_.qpos.data(), m->nq);
  mju_copy(initial_.data() + m->nq, state_.qvel.data(), m->nv);
  if (m->na) mju_copy(initial_.data() + m->nq + m->nv, state_.act.data(), m->na);

  // Warm start: the spline point j of the new plan holds what the old plan held at its time.
  const int points = settings_.spline_points;
  const double spacing = settings_.horizon / points;
  const double shift = state_.time - spline_t0_;
  auto& shifted = candidate_splines_[0];
  for (int j = 0; j < points; ++j) {
    const int old = std::min(points - 1, std::max(0, static_cast<int>(std::floor((j * spacing + shift) / spacing + 1e-9))));
    shifted[j] = nominal_[old];
  }
  for (int j = 0; j < points; ++j) nominal_[j] = shifted[j];
  spline_t0_ = state_.time;

  for (int it = 0; it < settings_.iterations; ++it) {
    adroit::Stopwatch clock;
    pool_->parallelForWorkers(candidates_.size(), [&](std::size_t i, std::size_t w) {
      auto& spline = candidate_splines_[i];
      for (int j = 0; j < points; ++j) {
        spline[j] = nominal_[j];
        if (i == 0) continue;  // the nominal itself competes
        for (int c = 0; c < spline[j].size(); ++c) spline[j][c] += noise_sigma_[c] * noise_[i]();
        space_.clamp(spline[j]);
      }
      rollout(m, *task_, space_, initial_, state_.time,
              [&](int t, const mjData*, Eigen::VectorXd& u) { u = spline[splineIndex(t)]; }, workspaces_[w],
              candidates_[i]);
    });
    report.rollout += clock.elapsed();
    std::size_t best = 0;
    for (std::size_t i = 1; i < candidates_.size(); ++i)
      if (candidates_[i].total < candidates_[best].total) best = i;
    if (it == 0) report.cost_before = candidates_[0].total;
    report.cost_after = candidates_[best].total;
    report.iterations = it + 1;
    if (!std::isfinite(candidates_[best].total)) {
      // Every candidate diverged (the nominal included): back to the safe warm start and
      // keep handing out the last good plan.
      reset();
      report.diverged = true;
      report.total = total_clock.elapsed();
      return report;
    }
    if (best != 0) {
      report.improved = true;
      for (int j = 0; j < points; ++j) nominal_[j] = candidate_splines_[best][j];
    }
    std::swap(best_, candidates_[best]);  // same sizes: storage swap, no allocation
  }
  writeTrajectory(best_, best_view_);
  have_best_ = true;
  report.total = total_clock.elapsed();
  return report;
}

void SamplingPlanner::policy(PlanPolicy& out) const {
  if (!have_best_) throw std::logic_error("SamplingPlanner::policy: no plan yet (call optimize() first)");
  writePolicy(model_, best_, nullptr, out);
}

}  // namespace adroit_mpc
