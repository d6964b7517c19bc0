// A demonstration replayed open loop as a policy (thesis 11.4, fig. 11.2a: "following the
// demonstrated behaviors directly"): a TVLG controller with K_t = 0 and k_t = the
// demonstration's valve commands u_t of the task's action cylinders, so any program that runs
// policies (the pickup evaluation, execute_policy) replays a demonstration like a trained
// controller. ROS-free.
#pragma once
#include <adroit_learning/demonstration.h>
#include <adroit_learning/policy_file.h>
#include <adroit_learning/trajectory_cost.h>
#include <adroit_learning/training_task.h>

namespace adroit {

// The replay's exploration covariance (V^2): a policy file needs a positive definite C_t;
// executing a policy never explores, so it only keeps the file valid.
constexpr double kDemonstrationReplayVariance = 1e-6;

// The policy that sends the demonstration's commands u_0 .. u_{T-1} (demonstrationActions) for
// the task's horizon T, whatever the state: K_t = 0, k_t = u_t, C_t = 1e-6 I. Its metadata
// (task, scene, control step, joints, cylinders, actions, state layout, locked command) is the
// task's on `layout`; iteration 0, cost_mean NaN (never run). Throws DemonstrationError with
// demonstrationMismatch's line when the demonstration cannot be replayed for this task on this
// robot (another task or scene, force commands, another control step, too short, other joints
// or cylinders).
PolicyFile demonstrationReplayPolicy(const Demonstration& demo, const TrainingTask& task, const StateLayout& layout);

}  // namespace adroit
