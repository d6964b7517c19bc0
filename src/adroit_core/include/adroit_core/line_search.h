// Backtracking line search on the forward pass of iLQG/iLQR: tries step sizes alpha in
// decreasing order and accepts the first whose actual cost reduction is a sufficient
// fraction of the reduction the backward pass predicted (Tassa, Erez & Todorov 2012).
#pragma once

#include <functional>

namespace adroit {

struct LineSearchSettings {
  double initial_step = 1.0;
  double step_factor = 0.5;          // alpha_{k+1} = factor * alpha_k
  int max_steps = 10;
  double min_reduction_ratio = 0.1;  // accept when (J_old - J_new) / -(a dV0 + a^2 dV1) > this
};

struct LineSearchResult {
  bool accepted = false;
  double alpha = 0;     // accepted step (0 when none)
  double cost = 0;      // cost of the accepted candidate (or of the last tried when none)
  int tries = 0;
  double reduction_ratio = 0;
};

// rollout(alpha) runs the forward pass with step alpha, keeps its result as the candidate,
// and returns its total cost (non-finite costs are rejected). dV as in BackwardPassResult.
// Templated on the callable so no std::function is built per iteration.
template <typename Rollout>
LineSearchResult backtrackingLineSearch(Rollout&& rollout, double current_cost, const double dV[2],
                                        const LineSearchSettings& settings = {});

}  // namespace adroit

#include <adroit_core/line_search_impl.h>
