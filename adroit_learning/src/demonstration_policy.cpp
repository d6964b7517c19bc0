#include "adroit_learning/demonstration_policy.h"

#include <limits>

namespace adroit {

PolicyFile demonstrationReplayPolicy(const Demonstration& demo, const TrainingTask& task, const StateLayout& layout) {
  const std::string problem = demonstrationMismatch(demo, task, layout);
  if (!problem.empty()) throw DemonstrationError(problem);
  const int T = task.horizon;
  const Eigen::MatrixXd u = demonstrationActions(demo, layout, T);
  PolicyFile p;
  p.task = task.name;
  p.scene = task.scene;
  p.state_layout = layout.describe();
  p.control_dt = task.control_dt;
  p.iteration = 0;
  p.cost_mean = std::numeric_limits<double>::quiet_NaN();
  p.joints = layout.joint_names;
  p.cylinders = layout.cylinder_names;
  for (int c : layout.action_cylinders) p.actions.push_back(layout.cylinder_names[c]);
  p.locked_command = layout.locked_command;
  p.controller = LgController(layout.nx(), layout.nu(), T);  // K = 0
  const Eigen::MatrixXd C = Eigen::MatrixXd::Identity(layout.nu(), layout.nu()) * kDemonstrationReplayVariance;
  for (int t = 0; t < T; ++t) {
    p.controller.k[t] = u.col(t);
    p.controller.setCovariance(t, C);
  }
  return p;
}

}  // namespace adroit
