// Predictive sampling (as in MuJoCo MPC): the plan is a zero-order-hold control spline of
// spline_points knots over the horizon; every optimise shifts it to the state's time, rolls
// out the nominal and samples - 1 noisy copies (Gaussian noise scaled by each control's
// range) in parallel, and keeps the cheapest, the nominal included, so the cost of the plan
// never rises for the same state and task. Its policy has no feedback (K = 0).
#pragma once

#include <adroit_mpc/spline_sampling.h>

namespace adroit_mpc {

class SamplingPlanner : public SplineSamplingPlanner {
 public:
  std::string name() const override { return "sampling"; }
  void initialize(const mjModel* model, const Task& task, const PlannerSettings& settings) override;
  OptimizeReport optimize() override;
  void reset() override { resetMean(); }

 private:
  ControlSpline sigma_;  // noise_scale x each control's range, at every point
};

}  // namespace adroit_mpc
