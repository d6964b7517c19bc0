// Template body of backtrackingLineSearch (included by line_search.h).
#pragma once

#include <cmath>
#include <stdexcept>

namespace adroit {

template <typename Rollout>
LineSearchResult backtrackingLineSearch(Rollout&& rollout, double current_cost, const double dV[2],
                                        const LineSearchSettings& settings) {
  if (!(settings.initial_step > 0) || !(settings.step_factor > 0 && settings.step_factor < 1) ||
      settings.max_steps < 1)
    throw std::invalid_argument(
        "LineSearchSettings: need initial_step > 0, step_factor in (0, 1) and max_steps >= 1");
  if (!std::isfinite(current_cost))
    throw std::invalid_argument("backtrackingLineSearch: the current cost is not finite");
  LineSearchResult result;
  double alpha = settings.initial_step;
  for (int i = 0; i < settings.max_steps; ++i, alpha *= settings.step_factor) {
    const double cost = rollout(alpha);
    result.tries = i + 1;
    result.cost = cost;
    if (!std::isfinite(cost)) continue;
    const double expected = -(alpha * dV[0] + alpha * alpha * dV[1]);
    const double actual = current_cost - cost;
    // No predicted reduction (at a stationary point up to rounding): any decrease is progress.
    const double ratio = expected > 0 ? actual / expected : (actual > 0 ? 1.0 : -1.0);
    result.reduction_ratio = ratio;
    if (ratio > settings.min_reduction_ratio) {
      result.accepted = true;
      result.alpha = alpha;
      return result;
    }
  }
  return result;
}

}  // namespace adroit
