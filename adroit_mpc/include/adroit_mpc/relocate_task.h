// Object relocation (thesis 6.5): the catch costs on the ball scene (arm + hand), with phases.
//   hold    - grasp the object and hold it at the hold pose until a goal is given;
//   goal    - move it to the user's goal (setGoal, checked against the workspace box);
//   release - the goal and grasp terms switch off; the hand leaves: the grasp site is pushed
//             beyond a clearance from the object and the joints are drawn to a rest keyframe.
// A goal given in the parameters (goal_position) skips the hold phase.
//
// Within hold and goal, a stage decided by observe() from the observed state (a 0.3 s horizon
// cannot discover a grasp from the object-to-goal cost alone: the hand pushes the ball away):
//   approach - the grasp site to a pre-grasp point above the object (pregrasp_offset), the
//              fingertips hovering open_margin outside its surface and below_depth below its
//              centre, the thumb opposing the fingers; no goal, no grasp hint (nothing pulls
//              the hand onto the object);
//   grasp    - the fingertips onto the surface (squeezing by `squeeze`) below its centre,
//              thumb opposing, the grasp hint (object to the grasp site); still no goal;
//   carry    - as grasp, plus the object-to-goal terms, and the grasp site led to the goal
//              plus its offset from the object when the object was taken (the hand leads).
// approach -> grasp when the grasp site is within pregrasp_tolerance of the pre-grasp point
// and the thumb and min_fingers fingers are within grasp_start_gap of the surface;
// -> carry when they are within hold_gap (from approach too: an object already in the hand);
// grasp / carry -> approach when the thumb or all but fewer than min_fingers fingers are
// further than lost_gap (the object is lost). Gaps are measured from each fingertip's pad
// (its site + fingertip_offset) to the object's surface (object_radius).
// Events: {"stage", "approach" | "grasp" | "carry"} on each change.
// Parameters and defaults: config/tasks/relocate.yaml (defaultTaskParams("relocate")).
#pragma once

#include <adroit_mpc/catch_task.h>

namespace adroit_mpc {

class RelocateTask : public ObjectTaskBase {
 public:
  enum class Phase { kHold, kGoal, kRelease };
  enum class Stage { kApproach, kGrasp, kCarry };

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
  Stage stage() const { return stage_; }
  static const char* stageName(Stage stage);

  // Gap [m] of each fingertip's pad to the object's surface at the state in `d` (kinematics
  // valid): thumb first, then the fingers of finger_sites. Negative: inside the surface.
  void fingertipGaps(const mjData* d, std::vector<double>* gaps) const;

 protected:
  bool goalTermsActive() const override { return phase_ != Phase::kRelease && stage_ == Stage::kCarry; }
  bool graspHintActive() const override { return phase_ != Phase::kRelease && stage_ != Stage::kApproach; }
  double extraStateCost(const mjModel* m, const mjData* d, double scale, ResidualBuffer& buf,
                        CostDerivatives* out) const override;

 private:
  Phase phase_ = Phase::kHold;
  Eigen::Vector3d hold_position_;
  Eigen::Quaterniond hold_orientation_;
  double release_clearance_, goal_tolerance_;
  int w_release_clearance_, w_release_posture_;
  std::string release_keyframe_;
  // Stages.
  Stage stage_ = Stage::kApproach;
  int w_pregrasp_, w_fingertip_, w_opposition_, w_carry_, w_below_;
  double below_depth_;
  Eigen::Vector3d carry_offset_ = Eigen::Vector3d::Zero();  // grasp site - object when taken
  Eigen::Vector3d pregrasp_offset_;
  double object_radius_, fingertip_offset_, fingertip_smoothing_, open_margin_, squeeze_;
  double pregrasp_tolerance_, grasp_start_gap_, hold_gap_, lost_gap_;
  int min_fingers_;
  std::string thumb_site_name_;
  std::vector<std::string> finger_site_names_;
  Stage reported_stage_ = Stage::kApproach;
  // observe() bookkeeping (node side)
  bool phase_reported_ = false;
  Phase reported_phase_ = Phase::kHold;
  bool goal_reached_reported_ = false;
  // Resolved by bind().
  JointList robot_joints_;
  std::vector<double> rest_targets_, unit_scales_;
  BodyPoint thumb_point_;
  std::vector<BodyPoint> finger_points_;
  std::vector<double> gaps_;  // observe() scratch
};

}  // namespace adroit_mpc
