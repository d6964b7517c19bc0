// What the sampling planners (predictive sampling, cross entropy) share, after MuJoCo MPC:
// the plan is a zero-order-hold control spline; every optimise re-times it to the state's
// time, rolls out the spline itself and noisy copies of it in parallel, and hands out a plan
// without feedback (K = 0). The planners differ only in how they pick the next spline.
#pragma once

#include <adroit_core/normal_noise.h>
#include <adroit_core/thread_pool.h>
#include <adroit_mpc/planner.h>

#include <cstdint>

namespace adroit_mpc {

// `points` control values spaced horizon / points apart from t0, each held until the next.
class ControlSpline {
 public:
  void resize(int points, int controls, int knots);  // allocates
  int points() const { return static_cast<int>(values.size()); }
  // The value planner knot `knot` holds (the horizon has `knots` knots).
  const Eigen::VectorXd& atKnot(int knot) const;
  // Re-times the spline to start at `time`: point j takes the value the spline held at
  // time + j spacing (the last value past its end). Returns the first point whose time lies
  // past the old spline's end (points() when none does). Allocates nothing.
  int shiftTo(double time, double horizon);
  void setConstant(const Eigen::VectorXd& value);
  void copyValuesFrom(const ControlSpline& other);  // same sizes; no allocation

  std::vector<Eigen::VectorXd> values;
  double t0 = 0;

 private:
  int knots_ = 1;
};

// The lifecycle both sampling planners run: state, task, the population of candidate splines
// and their parallel rollouts, divergence, and the handed-out plan. Candidate i draws its
// noise from its own stream (seed + 7919 i), so a plan depends on the seed, not on which
// worker rolled out what.
class SplineSamplingPlanner : public Planner {
 public:
  void setState(const PlannerState& state) override;
  void setTask(const Task& task) override;
  void policy(PlanPolicy& out) const override;
  const Trajectory& bestTrajectory() const override { return best_view_; }

  const ControlSpline& mean() const { return mean_; }  // the spline of the current plan

 protected:
  // Allocates what both planners use (settings.samples candidates).
  void initializeSampling(const mjModel* model, const Task& task, const PlannerSettings& settings);
  // initial_ from the state; the mean spline re-timed to the state's time (shiftTo's result).
  int beginOptimize();
  // Candidate 0 is the mean itself (so the plan's cost cannot rise for the same state and
  // task); candidate i > 0 is the mean plus N(0, sigma^2) per spline value, clamped to the
  // control box. All rolled out in parallel.
  void sampleAndRollout(const ControlSpline& sigma);
  // One spline rolled out on the calling thread (with worker 0's workspace: call it between
  // parallel batches).
  void rolloutSpline(const ControlSpline& spline, KnotTrajectory& out);
  // The n cheapest candidates, cheapest first (ties: lower index); allocates nothing.
  const int* rankCandidates(int n);
  // `plan` becomes the handed-out plan (storage swap, then published).
  void keepPlan(KnotTrajectory& plan);
  // The safe warm start: the mean at the minimum-tension controls from the state's time.
  void resetMean();
  // Every candidate diverged: back to the safe warm start, the last good plan kept.
  OptimizeReport& diverged(OptimizeReport& report, double elapsed);

  const mjModel* model_ = nullptr;
  std::unique_ptr<Task> task_;
  PlannerSettings settings_;
  int knots_ = 0;
  ControlSpace space_;
  std::unique_ptr<adroit::ThreadPool> pool_;
  std::vector<RolloutWorkspace> workspaces_;  // one per worker
  PlannerState state_;
  Eigen::VectorXd initial_;                   // [qpos qvel act] of state_

  ControlSpline mean_;                          // the spline of the plan handed out
  std::vector<ControlSpline> candidate_splines_;
  std::vector<KnotTrajectory> candidates_;      // their rollouts
  std::vector<adroit::NormalNoise> noise_;      // one stream per candidate
  std::vector<int> order_;                      // candidates by cost (rankCandidates)

  KnotTrajectory best_;
  Trajectory best_view_;
  bool have_best_ = false;
};

}  // namespace adroit_mpc
