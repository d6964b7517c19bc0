// Cross-entropy method (CEM) on the control spline (structure after MuJoCo MPC's "cross
// entropy" planner). The sampling distribution is a Gaussian per spline value: mean = the
// plan's spline, standard deviation per control and point (in units of the control's range).
// One iteration:
//   1. samples - 1 candidates around the mean (N(0, (std · range)^2) per value, clamped to the
//      control box) and the mean itself, rolled out in parallel;
//   2. the cem_elites cheapest: their mean and standard deviation (clamped to
//      [cem_std_min, cem_std_initial]) become the new distribution;
//   3. the elite mean is rolled out; it becomes the plan if it costs no more than the cheapest
//      candidate, else that candidate does (the mean then moves to it).
// So the plan is always the cheapest trajectory the iteration saw, and as the previous mean
// is a candidate, its cost never rises for the same state and task. The elite mean is tried
// as the plan because averaging cancels much of the noise that each sample carries in its
// 45 x spline_points values. The policy has no feedback (K = 0), as in predictive sampling.
// The std of a point that the shift brings in past the old plan's end restarts at
// cem_std_initial (nothing was learnt there).
#pragma once

#include <adroit_mpc/spline_sampling.h>

namespace adroit_mpc {

class CemPlanner : public SplineSamplingPlanner {
 public:
  std::string name() const override { return "cem"; }
  void initialize(const mjModel* model, const Task& task, const PlannerSettings& settings) override;
  OptimizeReport optimize() override;
  void reset() override;

  // The sampling standard deviation per spline value, in units of each control's range.
  const ControlSpline& standardDeviation() const { return std_; }

 private:
  // One CEM iteration; false when every candidate diverged.
  bool iterate(OptimizeReport& report);

  Eigen::VectorXd range_;    // upper - lower per control
  ControlSpline std_;        // per value, fraction of range, in [std_min, std_initial]
  ControlSpline sigma_;      // std_ x range_: the noise of the next sampling
  ControlSpline elite_mean_;
  KnotTrajectory elite_rollout_;
};

// The elite statistics of one CEM iteration: `mean` = the average of the splines
// `elites[0..n)`, `std` = their standard deviation (population form, 1/n) divided by each
// control's `range`, clamped to [std_min, std_max]. A control with zero range gets std_min.
// Allocates nothing.
void eliteStatistics(const std::vector<ControlSpline>& splines, const int* elites, int n, const Eigen::VectorXd& range,
                     double std_min, double std_max, ControlSpline& mean, ControlSpline& std);

}  // namespace adroit_mpc
