#include "adroit_mpc/sampling_planner.h"

#include <adroit_core/timing_stats.h>

namespace adroit_mpc {

void SamplingPlanner::initialize(const mjModel* m, const Task& task, const PlannerSettings& settings) {
  initializeSampling(m, task, settings);
  sigma_ = mean_;
  sigma_.setConstant(settings.noise_scale * (space_.upper() - space_.lower()));
  reset();
}

OptimizeReport SamplingPlanner::optimize() {
  adroit::Stopwatch total_clock;
  OptimizeReport report;
  beginOptimize();
  for (int it = 0; it < settings_.iterations; ++it) {
    adroit::Stopwatch clock;
    sampleAndRollout(sigma_);
    report.rollout += clock.elapsed();
    const int best = rankCandidates(1)[0];
    if (it == 0) report.cost_before = candidates_[0].total;
    report.cost_after = candidates_[best].total;
    report.iterations = it + 1;
    // Every candidate diverged, the nominal included.
    if (!std::isfinite(candidates_[best].total)) return diverged(report, total_clock.elapsed());
    if (best != 0) {
      report.improved = true;
      mean_.copyValuesFrom(candidate_splines_[best]);
    }
    keepPlan(candidates_[best]);
  }
  report.total = total_clock.elapsed();
  return report;
}

}  // namespace adroit_mpc
