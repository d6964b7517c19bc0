// Object relocation (thesis 6.5). Relocation "starts as a dynamic stabilization sequence, but
// with a pre-specified intermediate goal configuration, called the hold configuration": the ball
// is dropped into the palm-up hand on the arm (scene ball) and caught with the catch costs, whose
// goal is the hold position until the user gives one. Phases:
//   hold    - the object to hold_position until a goal is given;
//   goal    - the object to the user's goal (setGoal, checked against the workspace box);
//   release - the goal and grasp terms switch off and the joints are drawn to release_keyframe:
//             the fingers open and leave the object on the palm.
// In every phase a small posture term draws the arm joints (arm_joint_prefix) to the
// release keyframe: an object position leaves the arm redundant, and without it the arm drifts
// through its null space until the hand loses the object. A second one draws the wrist joints
// (wrist_joint_prefix) there: the palm stays level, so the goal is reached with the arm.
// An object further than reach_radius from the grasp site (dropped to the floor, or not yet
// placed) switches the goal and grasp terms off until it is back within reach: the hand waits
// at rest instead of straining after it.
// A goal given in the parameters (goal_position) skips the hold phase.
// Parameters and defaults: config/tasks/relocate.yaml (defaultTaskParams("relocate")).
#pragma once

#include <adroit_mpc/catch_task.h>

namespace adroit_mpc {

class RelocateTask : public ObjectTaskBase {
 public:
  enum class Phase { kHold, kGoal, kRelease };

  explicit RelocateTask(const TaskParams& params = {});
  static TaskParams defaults();

  std::string name() const override { return "relocate"; }
  std::unique_ptr<Task> clone() const override { return std::make_unique<RelocateTask>(*this); }
  void copyParametersFrom(const Task& other) override;
  void bind(const mjModel* model, int synergy_dims) override;

  bool setGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation, std::string* why) override;
  bool release(std::string* why) override;
  // Events: {"phase", "hold" | "goal" | "release"} on each change, {"goal_reached", "<m>"} once
  // per goal when the object is within goal_tolerance of it, {"object", "out of reach" |
  // "in reach"} when it leaves or comes back within reach_radius.
  std::vector<TaskEvent> observe(const mjModel* m, const mjData* d, double t) override;

  Phase phase() const { return phase_; }
  bool objectInReach() const { return in_reach_; }
  static const char* phaseName(Phase phase);
  const Eigen::Vector3d& holdPosition() const { return hold_position_; }

 protected:
  bool goalTermsActive() const override { return phase_ != Phase::kRelease && in_reach_; }
  bool graspHintActive() const override { return phase_ != Phase::kRelease && in_reach_; }
  double extraStateCost(const mjModel* m, const mjData* d, double scale, ResidualBuffer& buf,
                        CostDerivatives* out) const override;

 private:
  Phase phase_ = Phase::kHold;
  Eigen::Vector3d hold_position_;
  Eigen::Quaterniond hold_orientation_;
  double goal_tolerance_, reach_radius_;
  bool in_reach_ = true;
  int w_release_posture_, w_arm_posture_, w_wrist_posture_;
  std::string release_keyframe_, arm_joint_prefix_, wrist_joint_prefix_;
  // observe() bookkeeping (node side)
  bool phase_reported_ = false;
  Phase reported_phase_ = Phase::kHold;
  bool goal_reached_reported_ = false;
  // Resolved by bind(): all robot joints (release posture), the arm's and the wrist's (postures).
  JointList robot_joints_, arm_joints_, wrist_joints_;
  std::vector<double> rest_targets_, arm_targets_, wrist_targets_, unit_scales_;
};

}  // namespace adroit_mpc
