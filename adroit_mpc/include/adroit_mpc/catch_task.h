// Dynamic manipulation (thesis 6.5): catch the bottle dropped onto the palm-up hand and hold it
// at a goal configuration. Running cost = object velocity + distance to the goal (position and
// orientation) + a small grasp-envelope hint (object to the hand's S_grasp site) + control
// effort (synergies slightly cheaper). Terminal cost = terminal_scale x the state terms.
// Parameters and defaults: config/tasks/catch.yaml (defaultTaskParams("catch")).
#pragma once

#include <adroit_mpc/cost_terms.h>
#include <adroit_mpc/task.h>
#include <adroit_mpc/task_params.h>

#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

namespace adroit_mpc {

// The object-manipulation costs that catch and relocate share.
class ObjectTaskBase : public Task {
 public:
  void bind(const mjModel* model, int synergy_dims) override;
  std::unique_ptr<TaskScratch> makeScratch(const mjModel* model) const override;

  double runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                     TaskScratch& s) const override;
  double terminalCost(const mjModel* m, const mjData* d, double t, TaskScratch& s) const override;
  double runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                                TaskScratch& s, CostDerivatives& out) const override;
  double terminalCostDerivatives(const mjModel* m, const mjData* d, double t, TaskScratch& s,
                                 CostDerivatives& out) const override;

  std::vector<std::string> weightNames() const override { return weights_.names(); }
  double weight(const std::string& name) const override { return weights_.get(name); }
  void setWeight(const std::string& name, double value) override { weights_.set(name, value); }

  // Distance [m] of the object (its body frame origin) to the current goal position.
  double error(const mjModel* m, const mjData* d) const override;

  const Eigen::Vector3d& goalPosition() const { return goal_position_; }
  const Eigen::Quaterniond& goalOrientation() const { return goal_orientation_; }
  const WorkspaceBox& workspace() const { return workspace_; }
  // Hints for the node / benchmarks (not used by the costs).
  double horizonHint() const { return horizon_hint_; }
  double plannerDtHint() const { return planner_dt_hint_; }
  const Eigen::Vector3d& objectStartPosition() const { return object_start_position_; }
  const Eigen::Quaterniond& objectStartOrientation() const { return object_start_orientation_; }

 protected:
  ObjectTaskBase(const std::string& task, const TaskParams& merged);
  // Copies the live state of the base part (weights, goal); allocates nothing.
  void copyBaseFrom(const ObjectTaskBase& other);

  // The object-to-goal terms are on (relocate: only once the object is held, and not after
  // the release).
  virtual bool goalTermsActive() const { return true; }
  // The grasp-hint term (object to the grasp site) is on (relocate: off while approaching and
  // after the release).
  virtual bool graspHintActive() const { return true; }
  // Extra state terms of a derived task (relocate's release), added with `scale`.
  virtual double extraStateCost(const mjModel* /*m*/, const mjData* /*d*/, double /*scale*/,
                                ResidualBuffer& /*buf*/, CostDerivatives* /*out*/) const {
    return 0;
  }
  double stateCost(const mjModel* m, const mjData* d, double scale, ResidualBuffer& buf, CostDerivatives* out) const;
  void checkSizes(const Eigen::VectorXd& u, const CostDerivatives* out) const;

  std::string task_name_;
  WeightTable weights_;
  int w_object_velocity_, w_goal_position_, w_goal_orientation_, w_grasp_, w_control_, w_synergy_;
  Eigen::Vector3d goal_position_;
  Eigen::Quaterniond goal_orientation_;
  Eigen::Vector3d orientation_axes_;
  WorkspaceBox workspace_;
  double velocity_angular_scale_, position_smoothing_, grasp_smoothing_, terminal_scale_;
  double horizon_hint_, planner_dt_hint_;
  Eigen::Vector3d object_start_position_;
  Eigen::Quaterniond object_start_orientation_;
  std::string object_body_name_, object_joint_name_, grasp_site_name_;

  // Resolved by bind().
  bool bound_ = false;
  int nv_ = 0, nx_ = 0, nu_total_ = 0;
  int object_body_ = -1;
  BodyPoint object_point_, grasp_point_;
  DofList object_dofs_;
  ControlEffort control_effort_;
};

class CatchTask : public ObjectTaskBase {
 public:
  // Throws std::invalid_argument naming a bad or unknown parameter.
  explicit CatchTask(const TaskParams& params = {});
  static TaskParams defaults();

  std::string name() const override { return "catch"; }
  std::unique_ptr<Task> clone() const override { return std::make_unique<CatchTask>(*this); }
  void copyParametersFrom(const Task& other) override;
  // A new goal for the held object (checked against the workspace box).
  bool setGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation, std::string* why) override;
};

}  // namespace adroit_mpc
