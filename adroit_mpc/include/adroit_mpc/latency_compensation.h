// Latency compensation: an optimisation that takes L seconds starts from the state measured
// at t0 but takes over at t0 + L, while the previous policy runs. Planning instead from the
// state that policy is predicted to reach at t0 + L (on the planning model) lines the new
// plan's first knot up with the moment it takes over, so no part of the plan is spent on a
// past the robot has already left (a standard remedy for computation delay in MPC; the thesis
// plans from the measured state).
#pragma once

#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/planner.h>

#include <mujoco/mujoco.h>

#include <array>
#include <cstddef>

namespace adroit_mpc {

class StatePredictor {
 public:
  // Allocates the prediction's mjData once (`model`: the planning model, outliving this).
  void initialize(const mjModel* model);
  // Advances `state` (time included) by the whole planning knots nearest `seconds`, but not
  // past the policy's last knot, the policy acting with its feedback scaled as on the robot.
  // Returns the seconds advanced: 0 (state untouched) for less than half a knot, no policy or
  // a prediction that left the finite numbers.
  // Allocates nothing.
  double predict(const PlanPolicy& policy, double feedback_scale, double seconds, PlannerState& state);

 private:
  const mjModel* model_ = nullptr;
  adroit::DataPtr data_;
};

// The latency to compensate: the median of the last optimisations' wall times (robust to the
// one slow solve a busy machine gives now and then). 0 until one is recorded.
class LatencyEstimate {
 public:
  void record(double seconds);
  double expected() const;

 private:
  static constexpr std::size_t kWindow = 9;
  std::array<double, kWindow> recent_{};
  std::size_t count_ = 0;
};

}  // namespace adroit_mpc
