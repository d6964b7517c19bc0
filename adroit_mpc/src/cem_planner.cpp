#include "adroit_mpc/cem_planner.h"

#include <adroit_core/timing_stats.h>

#include <algorithm>
#include <cmath>

namespace adroit_mpc {

void eliteStatistics(const std::vector<ControlSpline>& splines, const int* elites, int n, const Eigen::VectorXd& range,
                     double std_min, double std_max, ControlSpline& mean, ControlSpline& std) {
  for (int j = 0; j < mean.points(); ++j) {
    Eigen::VectorXd& mu = mean.values[j];
    Eigen::VectorXd& sd = std.values[j];
    mu.setZero();
    for (int e = 0; e < n; ++e) mu += splines[elites[e]].values[j];
    mu /= n;
    sd.setZero();
    for (int e = 0; e < n; ++e) sd += (splines[elites[e]].values[j] - mu).cwiseAbs2();
    for (int c = 0; c < sd.size(); ++c) {
      const double spread = range[c] > 0 ? std::sqrt(sd[c] / n) / range[c] : 0.0;
      sd[c] = std::min(std_max, std::max(std_min, spread));
    }
  }
}

void CemPlanner::initialize(const mjModel* m, const Task& task, const PlannerSettings& settings) {
  initializeSampling(m, task, settings);
  range_ = space_.upper() - space_.lower();
  std_ = mean_;
  sigma_ = mean_;
  elite_mean_ = mean_;
  elite_rollout_.resize(m, knots_, space_.size());
  reset();
}

void CemPlanner::reset() {
  resetMean();
  for (auto& v : std_.values) v.setConstant(settings_.cem_std_initial);  // no temporary: optimize() may reset
  std_.t0 = mean_.t0;
}

OptimizeReport CemPlanner::optimize() {
  adroit::Stopwatch total_clock;
  OptimizeReport report;
  const int first_new = beginOptimize();
  std_.shiftTo(mean_.t0, settings_.horizon);  // the distribution moves with its mean
  for (int j = first_new; j < std_.points(); ++j) std_.values[j].setConstant(settings_.cem_std_initial);
  for (int it = 0; it < settings_.iterations; ++it) {
    if (!iterate(report)) return diverged(report, total_clock.elapsed());
  }
  report.total = total_clock.elapsed();
  return report;
}

bool CemPlanner::iterate(OptimizeReport& report) {
  adroit::Stopwatch clock;
  for (int j = 0; j < sigma_.points(); ++j) sigma_.values[j] = std_.values[j].cwiseProduct(range_);
  sampleAndRollout(sigma_);
  ++report.iterations;
  const double previous = candidates_[0].total;  // the previous mean's cost
  if (report.iterations == 1) report.cost_before = previous;
  const int* order = rankCandidates(settings_.cem_elites);
  const KnotTrajectory& cheapest = candidates_[order[0]];
  if (!std::isfinite(cheapest.total)) {
    report.rollout += clock.elapsed();
    report.cost_after = cheapest.total;
    return false;
  }
  // Diverged candidates are no elites: the cheapest `elites` with a finite cost.
  int elites = 1;
  while (elites < settings_.cem_elites && std::isfinite(candidates_[order[elites]].total)) ++elites;
  eliteStatistics(candidate_splines_, order, elites, range_, settings_.cem_std_min, settings_.cem_std_initial,
                  elite_mean_, std_);
  rolloutSpline(elite_mean_, elite_rollout_);
  report.rollout += clock.elapsed();
  if (elite_rollout_.total <= cheapest.total) {
    mean_.copyValuesFrom(elite_mean_);
    keepPlan(elite_rollout_);
  } else {
    mean_.copyValuesFrom(candidate_splines_[order[0]]);
    keepPlan(candidates_[order[0]]);
  }
  report.cost_after = best_.total;
  report.improved = report.improved || best_.total < previous;
  return true;
}

}  // namespace adroit_mpc
