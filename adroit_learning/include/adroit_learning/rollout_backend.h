// Where rollouts run (issue 13 item 4): in-process MuJoCo workers (adroit_learning/
// sim_rollouts.h) or the live driver over ROS (the trainer node). Both run the trainer's
// controller, or any Policy (TVLG, library, network), from a given initial state for T
// control steps, holding each valve command for one control step, and return the states the
// robot reported and the commands it was sent. One control loop (runControlLoop) serves
// every backend and every kind of action, so they all act identically.
#pragma once
#include <adroit_learning/dynamics_fit.h>
#include <adroit_learning/lg_controller.h>
#include <adroit_learning/policy.h>
#include <adroit_learning/trajectory_cost.h>

#include <Eigen/Dense>
#include <atomic>
#include <cmath>
#include <exception>
#include <functional>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace adroit {

struct RolloutRequest {
  Eigen::MatrixXd noise;               // nu x T, N(0, 1) per entry (smoothedNoise); unused by a Policy
  std::vector<double> joint_offset;    // added to the initial joint angles (rad); empty = none
  // The tube's initial yaw (degrees in [0, 180), tubeOrientationFromYaw) instead of the task's
  // initial_object_yaw, for this rollout only: evaluating a policy over many rod angles (11.5).
  std::optional<double> object_yaw_deg;
};

// Makes one Policy per rollout: a library remembers which local policy it chose, so
// rollouts that run at the same time never share one.
using PolicyFactory = std::function<std::unique_ptr<Policy>()>;

struct RolloutResult {
  Rollout sample;     // x: nx x (T + 1), u: nu x T (the commands sent, clamped to the valves' range)
  Eigen::MatrixXd touch;  // touch sensors x (T + 1) as observed (0 rows when the robot reports none)
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
  // The touch sensors Observation::touch reports, in its order (none by default): the
  // fingertips' (fingertipTouch), which a network policy reads (thesis 11.6).
  virtual std::vector<std::string> touchNames() const { return {}; }
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
  // Runs each request with a fresh policy from `make_policy` (its mean action; the request's
  // noise is unused) for `steps` control steps (0: the policy's horizon, or the task's for a
  // time-invariant policy). A policy that does not fit the robot, or is not defined for
  // `steps`, fails its rollouts with the reason. Results in request order.
  virtual std::vector<RolloutResult> runPolicy(const TrainingTask& /*task*/, const StateLayout& /*layout*/,
                                               const PolicyFactory& /*make_policy*/,
                                               const std::vector<RolloutRequest>& /*requests*/, int /*steps*/,
                                               const std::atomic<bool>& /*cancel*/) {
    throw std::logic_error("rollout backend '" + name() + "' cannot run a Policy");
  }
};

// The fingertip touch sensors among a robot's (names ending in "tip", in their order): what
// the thesis' network reads (11.6, "tactile sensors in the fingertips") and what the hardware's
// palm board reports (adroit_driver can_mapping.h: the same rule), so a network trained on the
// simulation runs on the robot. Their indices in `names`.
inline std::vector<int> fingertipTouch(const std::vector<std::string>& names) {
  std::vector<int> tips;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i].size() >= 3 && names[i].compare(names[i].size() - 3, 3, "tip") == 0) tips.push_back(static_cast<int>(i));
  return tips;
}

// "" when the request's object yaw override is absent or in [0, 180) degrees, else why not.
inline std::string objectYawProblem(const RolloutRequest& request) {
  if (!request.object_yaw_deg) return "";
  const double yaw = *request.object_yaw_deg;
  if (std::isfinite(yaw) && yaw >= 0 && yaw < 180) return "";
  std::ostringstream text;
  text << "object_yaw_deg must be in [0, 180) degrees, got " << yaw;
  return text.str();
}

// One rollout's policy from `make_policy`, checked against `robot` and `layout`, and the steps
// it runs (`steps`, resolved as RolloutBackend::runPolicy says). nullptr with `error` set when
// the factory fails or gives none, the policy does not fit, or is not defined that long.
inline std::unique_ptr<Policy> policyForRollout(const PolicyFactory& make_policy, const RolloutBackend& robot,
                                                const StateLayout& layout, const TrainingTask& task, int& steps,
                                                std::string& error) {
  std::unique_ptr<Policy> policy;
  try {
    policy = make_policy();
  } catch (const std::exception& e) {
    error = std::string("policy not made: ") + e.what();
    return nullptr;
  }
  if (!policy) {
    error = "policy not made: the factory gave none";
    return nullptr;
  }
  error = policy->mismatch(robot.jointNames(), robot.cylinderNames(), robot.touchNames(), layout);
  if (!error.empty()) return nullptr;
  const int horizon = policy->horizon();
  if (steps <= 0) steps = horizon > 0 ? horizon : task.horizon;
  if (steps <= 0 || (horizon > 0 && steps > horizon)) {
    error = "the " + policy->kind() + " policy is defined for " + std::to_string(horizon) + " steps, asked for " +
            std::to_string(steps);
    return nullptr;
  }
  return policy;
}

// The trainer's action: the controller's mean plus its exploration noise, u = K x + k + L noise_t.
inline auto controllerAction(const LgController& controller, const Eigen::MatrixXd& noise) {
  return [&controller, &noise](int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>&,
                               Eigen::Ref<Eigen::VectorXd> u, std::string&) {
    controller.action(t, x, noise.col(t), u);
    return true;
  };
}

// A policy's action: start(x_0) at t = 0, then its mean action. A policy that throws (a
// library facing a vertical tube, a network's failed inference) ends the rollout with its
// message rather than the process.
inline auto policyAction(Policy& policy) {
  return [&policy](int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
                   Eigen::Ref<Eigen::VectorXd> u, std::string& error) {
    try {
      if (t == 0) policy.start(x);
      policy.action(t, x, touch, u);
      return true;
    } catch (const std::exception& e) {
      error = policy.kind() + " policy failed at step " + std::to_string(t) + ": " + e.what();
      return false;
    }
  };
}

// One rollout's control loop, shared by every backend and every kind of action so they act
// identically: at each control step observe -> x_t, act(t, x_t, touch_t, u_t) -> send; then
// advance, for `steps` steps. `observe(obs, error)` returns false with `error` set when the
// robot cannot go on (safe state, non-finite sensors); `act`, `send(volts, error)` and
// `advance(error)` do the same for acting, commanding and stepping.
template <class Act, class Observe, class Send, class Advance>
RolloutResult runControlLoop(const StateLayout& layout, int steps, const std::atomic<bool>& cancel, Act&& act,
                             Observe&& observe, Send&& send, Advance&& advance) {
  const int T = steps;
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
    if (t == 0) result.touch.resize(static_cast<Eigen::Index>(obs.touch.size()), T + 1);
    if (static_cast<Eigen::Index>(obs.touch.size()) != result.touch.rows()) {
      result.error = "touch sensor count changed at step " + std::to_string(t);
      return result;
    }
    for (Eigen::Index i = 0; i < result.touch.rows(); ++i) result.touch(i, t) = obs.touch[i];
    if (!result.sample.x.col(t).allFinite()) {
      result.error = "non-finite state at step " + std::to_string(t);
      return result;
    }
    if (t == T) break;
    if (!act(t, result.sample.x.col(t), result.touch.col(t), u, result.error)) return result;
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

// The trainer's rollout: the controller over its horizon with the request's noise.
template <class Observe, class Send, class Advance>
RolloutResult runControlLoop(const StateLayout& layout, const LgController& controller, const Eigen::MatrixXd& noise,
                             const std::atomic<bool>& cancel, Observe&& observe, Send&& send, Advance&& advance) {
  return runControlLoop(layout, controller.horizon(), cancel, controllerAction(controller, noise),
                        std::forward<Observe>(observe), std::forward<Send>(send), std::forward<Advance>(advance));
}

}  // namespace adroit
