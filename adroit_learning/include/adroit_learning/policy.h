// Any policy the stack can run (thesis ch. 11): a time-varying linear-Gaussian controller
// (TVLG file), a library of them chosen by nearest neighbour on the object's initial
// orientation, or a time-invariant neural network. execute_policy and the evaluation program
// run every kind through this one interface and one control loop.
#pragma once
#include <adroit_learning/trajectory_cost.h>

#include <Eigen/Dense>
#include <string>
#include <vector>

namespace adroit {

class Policy {
 public:
  virtual ~Policy() = default;
  // "tvlg", "library" or "network".
  virtual std::string kind() const = 0;
  // Control steps the policy is defined for; 0 = time-invariant (runs as long as asked).
  virtual int horizon() const = 0;
  // Once per execution, with the first state x_0 (StateLayout of the task), before the first
  // action: a library picks its local policy here.
  virtual void start(const Eigen::Ref<const Eigen::VectorXd>& x0) = 0;
  // The mean action u (valve commands of the action cylinders, size nu) at step t from the
  // state x and the touch sensors (N, the robot's order). Allocates nothing per call where the
  // kind allows it (TVLG); a network's inference is timed by its caller.
  virtual void action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
                      Eigen::Ref<Eigen::VectorXd> u) = 0;
  // "" when the policy fits the robot it is about to run on, else one line naming the
  // mismatch (joints, cylinders, touch sensors, state layout).
  virtual std::string mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                               const std::vector<std::string>& touch, const StateLayout& layout) const = 0;
};

}  // namespace adroit
