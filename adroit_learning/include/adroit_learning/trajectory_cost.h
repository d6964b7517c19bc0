// The trainer's state and cost (thesis 8.4): how a robot observation becomes the state vector
// x, how u maps onto valve commands, and the costs of 8.4.1 / 8.4.2 built from one reusable
// term, a weighted squared linear residual of the state.
#pragma once
#include <adroit_learning/dynamics_fit.h>
#include <adroit_learning/kl_update.h>
#include <adroit_learning/pickup.h>
#include <adroit_learning/training_task.h>

#include <Eigen/Dense>
#include <array>
#include <string>
#include <vector>

namespace adroit {

// What the robot reports at one instant, in the driver's conventions (adroit_driver's
// Signals; the ROS trainer fills it from joint_states, actuator_states and object odometry).
struct Observation {
  std::vector<double> joint_position, joint_velocity;  // the robot's 1-DOF joints
  std::vector<double> pressure;                        // Pa absolute, per cylinder
  // Fingertip touch sensors (N, RolloutBackend::touchNames order; empty when the backend has
  // none). Not part of the TVLG state x: network policies read it (thesis 11.6).
  std::vector<double> touch;
  // Free object: position, quaternion w x y z, linear velocity (world), angular velocity
  // (object frame). Ignored when the layout has no object.
  std::array<double, 13> object{};
};

// x = [q (joints) | object position (3) | object rotation vector (3) | qdot (joints) |
//      object linear velocity (3) | object angular velocity (3) | pressures (cylinders)],
// the object blocks only when the task uses the object; pressures as (p - p_atm) / 1e5 (bar
// gauge), so every block is of order one for the dynamics fit. u = valve commands (V) of the
// cylinders not locked by the task.
class StateLayout {
 public:
  StateLayout() = default;
  // Throws TaskError naming a target joint or locked cylinder the robot does not have, or an
  // object task on a scene without an object.
  StateLayout(const TrainingTask& task, const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
              bool scene_has_object);
  int nx() const { return nx_; }
  int nu() const { return static_cast<int>(action_cylinders.size()); }
  int joints() const { return static_cast<int>(joint_names.size()); }
  bool hasObject() const { return object_; }
  // First index of each block (-1 when absent).
  int q() const { return 0; }
  int objectPosition() const { return object_ ? joints() : -1; }
  int objectRotation() const { return object_ ? joints() + 3 : -1; }
  int qdot() const { return joints() + (object_ ? 6 : 0); }
  int pressures() const { return nx_ - static_cast<int>(cylinder_names.size()); }
  // Fills x (size nx). Observations with other sizes throw std::invalid_argument.
  void state(const Observation& obs, Eigen::Ref<Eigen::VectorXd> x) const;
  // Valve command per cylinder (size = cylinders) from u, locked ones at the locked command,
  // clamped to [-5, 5] V.
  void command(const Eigen::Ref<const Eigen::VectorXd>& u, std::vector<double>& volts) const;
  // One line naming the blocks and sizes (written into policy files).
  std::string describe() const;

  std::vector<std::string> joint_names, cylinder_names;
  std::vector<int> action_cylinders;  // cylinder index of each entry of u
  double locked_command = 0;

 private:
  int nx_ = 0;
  bool object_ = false;
};

// Rotation vector (axis * angle, |angle| <= pi) of a unit quaternion w x y z.
Eigen::Vector3d rotationVector(const double quat_wxyz[4]);

// One cost term: w ||A x - b_t||^2 with running weight w (t < T) and final weight w_T.
struct StateResidualTerm {
  std::string name;
  Eigen::MatrixXd A;                 // m x nx
  std::vector<Eigen::VectorXd> b;    // T + 1 targets
  double running_weight = 0, final_weight = 0;
};

// Per-rollout outcome of the task's success criteria at T.
struct TaskOutcome {
  double cost = 0;
  double joint_rms = 0;      // over the target joints
  double angle_error = 0;    // |object angle - target(T)|, 0 without an object
  double object_height = 0;  // object z at T
  bool dropped = false;
  bool success = false;
  std::string failure;       // pickup criterion: the condition that failed ("" otherwise)
};

class TrajectoryCost {
 public:
  // x_initial: the task's initial state, which gives the targets of unlisted joints and the
  // object's target position. geometry: the object's (RolloutBackend::objectGeometry), needed
  // by the pickup success criterion (a TaskError without it).
  TrajectoryCost(const TrainingTask& task, const StateLayout& layout, const Eigen::VectorXd& x_initial,
                 const ObjectGeometry& geometry = {});
  int horizon() const { return horizon_; }
  const std::vector<StateResidualTerm>& terms() const { return terms_; }
  // sum_t l_t(x_t, u_t) + l_T(x_T) of one rollout.
  double rolloutCost(const Rollout& rollout) const;
  TaskOutcome outcome(const Rollout& rollout) const;
  // The object's angle about the task's rotation axis in state x (0 without an object).
  double objectAngle(const Eigen::Ref<const Eigen::VectorXd>& x) const {
    return angle_row_.size() > 0 ? angle_row_.dot(x) : 0.0;
  }
  // Second-order expansion in absolute coordinates, averaged over the samples' points. Every
  // term is quadratic in (x, u), so the expansion is exact and the same at every sample; the
  // samples only fix where a non-quadratic term would be expanded.
  void expand(const std::vector<Rollout>& samples, QuadraticCost& out) const;
  // The object's pose and velocity in state x (a layout with the object).
  ObjectState objectState(const Eigen::Ref<const Eigen::VectorXd>& x) const;

 private:
  void addJointTerm(const StateLayout& layout);
  void addObjectTerms(const StateLayout& layout, const Eigen::VectorXd& x_initial);
  TrainingTask task_;
  ObjectGeometry geometry_;
  int horizon_, nu_, object_position_ = -1, object_rotation_ = -1, object_velocity_ = -1;
  std::vector<StateResidualTerm> terms_;
  std::vector<int> target_joint_index_;  // entries of x whose error success_joint_rms measures
  Eigen::VectorXd target_q_;
  Eigen::RowVectorXd angle_row_;         // angle = angle_row_ x (empty without an object)
};

}  // namespace adroit
