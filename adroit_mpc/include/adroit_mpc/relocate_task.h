// Object relocation (thesis 6.5): the catch costs on the ball scene (arm + hand), with phases.
//   hold    - grasp the object and hold it at the hold pose until a goal is given;
//   goal    - move it to the user's goal (setGoal, checked against the workspace box);
//   release - the goal and grasp terms switch off; the hand leaves: the grasp site is pushed
//             beyond a clearance from the object and the joints are drawn to a rest keyframe.
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
  // per goal when the object is within goal_tolerance of it.
  std::vector<TaskEvent> observe(const mjModel* m, const mjData* d, double t) override;

  Phase phase() const { return phase_; }
  static const char* phaseName(Phase phase);

 protected:
  bool graspTermsActive() const override { return phase_ != Phase::kRelease; }
  double extraStateCost(const mjModel* m, const mjData* d, double scale, ResidualBuffer& buf,
                        CostDerivatives* out) const override;

 private:
  Phase phase_ = Phase::kHold;
  Eigen::Vector3d hold_position_;
  Eigen::Quaterniond hold_orientation_;
  double release_clearance_, goal_tolerance_;
  int w_release_clearance_, w_release_posture_;
  std::string release_keyframe_;
  // observe() bookkeeping (node side)
  bool phase_reported_ = false;
  Phase reported_phase_ = Phase::kHold;
  bool goal_reached_reported_ = false;
  // Resolved by bind().
  JointList robot_joints_;
  std::vector<double> rest_targets_, unit_scales_;
};

}  // namespace adroit_mpc
