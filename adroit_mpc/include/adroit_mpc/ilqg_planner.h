// iLQG behaviour MPC on the full planning model (thesis 5.5.2-5.5.4, 6.4.2). One optimise:
//   1. warm start: roll out the previous policy (nominal, gains) resampled at the new
//      state's knot times, with its feedback, from the new state (min-tension controls the
//      first time and after reset());
//   2. A_t, B_t by finite differences (FdDerivatives; derivative_skip), B mapped to the
//      planner controls [actuators | synergies] by the chain rule;
//   3. the task's Gauss-Newton cost derivatives at every knot, parallel over knots;
//   4. the box-constrained backward pass (ctrlrange, [-1, 1] for synergies) with the
//      Levenberg-Marquardt schedule (small mu: MPC must take large steps, thesis 6.4);
//   5. line search: the forward passes of several step sizes run in parallel, one per
//      worker, and the cheapest accepted one becomes the plan.
// A non-finite nominal cost resets the planner to the safe warm start and reports
// `diverged`; the last good plan stays the one handed out.
#pragma once

#include <adroit_core/line_search.h>
#include <adroit_core/lq_backward_pass.h>
#include <adroit_core/thread_pool.h>
#include <adroit_mpc/fd_derivatives.h>
#include <adroit_mpc/planner.h>

namespace adroit_mpc {

class IlqgPlanner : public Planner {
 public:
  std::string name() const override { return "ilqg"; }
  void initialize(const mjModel* model, const Task& task, const PlannerSettings& settings) override;
  void setState(const PlannerState& state) override;
  void setTask(const Task& task) override;
  OptimizeReport optimize() override;
  void policy(PlanPolicy& out) const override;
  const Trajectory& bestTrajectory() const override { return best_view_; }
  void reset() override;

  // Line-search constants (step sequence and acceptance), defaults of adroit::LineSearchSettings.
  adroit::LineSearchSettings line_search;
  const FdDerivatives& derivatives() const { return fd_; }

 private:
  void warmStartRollout(OptimizeReport& report);
  void computeCostDerivatives();
  // The tension step cost's derivatives (ControlSpace::addStepDerivatives) into lq_ per knot.
  void addStepDerivatives();
  bool lineSearch(const adroit::BackwardPassResult& pass, OptimizeReport& report);
  void publish();

  const mjModel* model_ = nullptr;
  std::unique_ptr<Task> task_;
  PlannerSettings settings_;
  int knots_ = 0, nx_ = 0;
  ControlSpace space_;
  std::unique_ptr<adroit::ThreadPool> pool_;
  std::vector<RolloutWorkspace> workspaces_;   // one per worker
  std::vector<CostDerivatives> cost_derivatives_;  // one per worker
  std::vector<Eigen::VectorXd> x_interp_, u_interp_, feedback_;  // per worker (warm start)
  PlannerState state_;
  Eigen::VectorXd initial_;

  FdDerivatives fd_;
  std::vector<Eigen::MatrixXd> B_act_;         // d x_{t+1} / d ctrl_t
  adroit::LqApproximation lq_;
  std::unique_ptr<adroit::BackwardPass> backward_;
  adroit::FeedbackGains gains_;
  adroit::RegularizationSchedule schedule_;

  KnotTrajectory nominal_;
  std::vector<KnotTrajectory> candidates_;     // one per worker (line search)
  std::vector<double> candidate_alpha_;
  bool have_previous_ = false;
  KnotTrajectory previous_;                    // the last plan, for the warm start
  std::vector<Eigen::MatrixXd> previous_gains_;  // planner controls x nx

  KnotTrajectory best_;                        // handed out
  std::vector<Eigen::MatrixXd> best_gains_;    // actuator controls x nx
  Trajectory best_view_;
  bool have_best_ = false;
};

}  // namespace adroit_mpc
