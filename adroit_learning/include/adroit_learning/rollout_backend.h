// Where the trainer's rollouts run (issue 13 item 4): in-process MuJoCo workers
// (adroit_learning/sim_rollouts.h) or the live driver over ROS (the trainer node). Both run a
// controller from a given initial state for T control steps, holding each valve command for
// one control step, and return the states the robot reported and the commands it was sent.
#pragma once
#include <adroit_learning/dynamics_fit.h>
#include <adroit_learning/lg_controller.h>
#include <adroit_learning/trajectory_cost.h>

#include <Eigen/Dense>
#include <atomic>
#include <string>
#include <vector>

namespace adroit {

struct RolloutRequest {
  Eigen::MatrixXd noise;               // nu x T, N(0, 1) per entry (smoothedNoise)
  std::vector<double> joint_offset;    // added to the initial joint angles (rad); empty = none
};

struct RolloutResult {
  Rollout sample;     // x: nx x (T + 1), u: nu x T (the commands sent, clamped to the valves' range)
  bool ok = false;
  std::string error;  // why not: non-finite state, the driver's safe state, cancelled, ...
};

class RolloutBackend {
 public:
  virtual ~RolloutBackend() = default;
  virtual std::string name() const = 0;
  // The robot's 1-DOF joints, cylinders, and whether the scene has a free object.
  virtual std::vector<std::string> jointNames() const = 0;
  virtual std::vector<std::string> cylinderNames() const = 0;
  virtual bool hasObject() const = 0;
  // Range (rad) of each joint of jointNames(): initial-state noise is a fraction of it.
  virtual std::vector<double> jointRanges() const = 0;
  // The free object's geometry read from the scene (pickup criterion); invalid without one.
  virtual ObjectGeometry objectGeometry() const { return {}; }
  // The task's initial state as the robot reports it right after a reset (no offsets): the
  // trainer's targets for joints the task does not name come from it.
  virtual Eigen::VectorXd initialState(const TrainingTask& task, const StateLayout& layout) = 0;
  // Runs each request with the controller (mean K x + k, plus L_t noise_t); results in request
  // order. `cancel`, when set, ends the remaining rollouts with ok = false.
  virtual std::vector<RolloutResult> run(const TrainingTask& task, const StateLayout& layout,
                                         const LgController& controller, const std::vector<RolloutRequest>& requests,
                                         const std::atomic<bool>& cancel) = 0;
};

// One rollout's control loop, shared by every backend so they act identically: at each
// control step observe -> x_t, u_t = controller(t, x_t, noise_t) -> send; then advance.
// `observe(obs)` returns false with `error` set when the robot cannot go on (safe state,
// non-finite sensors); `send(volts)` and `advance()` do the same for commanding and stepping.
template <class Observe, class Send, class Advance>
RolloutResult runControlLoop(const StateLayout& layout, const LgController& controller, const Eigen::MatrixXd& noise,
                             const std::atomic<bool>& cancel, Observe&& observe, Send&& send, Advance&& advance) {
  const int T = controller.horizon();
  RolloutResult result;
  result.sample.x.resize(layout.nx(), T + 1);
  result.sample.u.resize(layout.nu(), T);
  Observation obs;
  std::vector<double> volts;
  Eigen::VectorXd u(layout.nu());
  for (int t = 0; t <= T; ++t) {
    if (cancel.load()) {
      result.error = "cancelled";
      return result;
    }
    if (!observe(obs, result.error)) return result;
    layout.state(obs, result.sample.x.col(t));
    if (!result.sample.x.col(t).allFinite()) {
      result.error = "non-finite state at step " + std::to_string(t);
      return result;
    }
    if (t == T) break;
    controller.action(t, result.sample.x.col(t), noise.col(t), u);
    if (!u.allFinite()) {
      result.error = "non-finite action at step " + std::to_string(t);
      return result;
    }
    layout.command(u, volts);
    for (int i = 0; i < layout.nu(); ++i) result.sample.u(i, t) = volts[layout.action_cylinders[i]];
    if (!send(volts, result.error) || !advance(result.error)) return result;
  }
  result.ok = true;
  return result;
}

}  // namespace adroit
