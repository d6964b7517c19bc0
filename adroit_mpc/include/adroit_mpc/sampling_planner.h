// Predictive sampling (as in MuJoCo MPC): the plan is a zero-order-hold control spline of
// spline_points knots over the horizon; every optimise shifts it to the state's time, rolls
// out the nominal and samples - 1 noisy copies (Gaussian noise scaled by each control's
// range) in parallel, and keeps the cheapest, the nominal included, so the cost of the plan
// never rises for the same state and task. Its policy has no feedback (K = 0).
#pragma once

#include <adroit_core/normal_noise.h>
#include <adroit_core/thread_pool.h>
#include <adroit_mpc/planner.h>

namespace adroit_mpc {

class SamplingPlanner : public Planner {
 public:
  std::string name() const override { return "sampling"; }
  void initialize(const mjModel* model, const Task& task, const PlannerSettings& settings) override;
  void setState(const PlannerState& state) override;
  void setTask(const Task& task) override;
  OptimizeReport optimize() override;
  void policy(PlanPolicy& out) const override;
  const Trajectory& bestTrajectory() const override { return best_view_; }
  void reset() override;

 private:
  // Control of knot t from spline `values` (knots spaced horizon / points from t0).
  int splineIndex(int knot) const;

  const mjModel* model_ = nullptr;
  std::unique_ptr<Task> task_;
  PlannerSettings settings_;
  int knots_ = 0;
  ControlSpace space_;
  std::unique_ptr<adroit::ThreadPool> pool_;
  std::vector<RolloutWorkspace> workspaces_;  // one per worker
  PlannerState state_;
  Eigen::VectorXd initial_;                   // [qpos qvel act] of state_

  double spline_t0_ = 0;
  bool have_plan_ = false;
  std::vector<Eigen::VectorXd> nominal_;              // spline_points values
  std::vector<std::vector<Eigen::VectorXd>> candidate_splines_;  // samples x points
  std::vector<KnotTrajectory> candidates_;            // samples rollouts
  std::vector<adroit::NormalNoise> noise_;            // one stream per candidate
  Eigen::VectorXd noise_sigma_;                       // per control

  KnotTrajectory best_;
  Trajectory best_view_;
  bool have_best_ = false;
};

}  // namespace adroit_mpc
