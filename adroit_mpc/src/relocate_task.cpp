#include "adroit_mpc/relocate_task.h"

#include <stdexcept>

namespace adroit_mpc {

TaskParams RelocateTask::defaults() {
  TaskParams p;
  p.strings = {{"scene", "ball"}, {"object_body", "object"}, {"object_joint", "object_root"},
               {"grasp_site", "S_grasp"}, {"release_keyframe", "rest"}, {"arm_joint_prefix", "ARJ"},
               {"wrist_joint_prefix", "WRJ"}};
  p.numbers = {{"w_object_velocity", 0.5}, {"w_goal_position", 20.0}, {"w_goal_orientation", 0.0},
               {"w_grasp", 12.0},           {"w_control", 0.1},       {"w_synergy", 0.08},
               {"w_release_posture", 0.5}, {"w_arm_posture", 5.0}, {"w_wrist_posture", 5.0},
               {"terminal_scale", 10.0},   {"velocity_angular_scale", 0.035},
               {"position_smoothing", 0.02}, {"grasp_smoothing", 0.02}, {"goal_tolerance", 0.02},
               {"reach_radius", 0.25},
               {"horizon", 0.3},           {"planner_dt", 0.02},
               {"object_mass", 0.18},      {"object_radius", 0.035}};
  p.vectors = {{"goal_position", {}},
               {"goal_quat", {1, 0, 0, 0}},
               {"hold_position", {0.007, -0.14, 0.415}},
               {"hold_quat", {1, 0, 0, 0}},
               {"orientation_axes", {1, 1, 1}},
               {"workspace_min", {-0.2, -0.35, 0.2}},
               {"workspace_max", {0.2, 0.0, 0.5}},
               {"object_start_position", {0.007, -0.14, 0.48}},
               {"object_start_quat", {1, 0, 0, 0}}};
  return p;
}

namespace {
TaskParams mergedRelocate(const TaskParams& params) {
  return mergeTaskParams("relocate", RelocateTask::defaults(), params);
}
}  // namespace

RelocateTask::RelocateTask(const TaskParams& params) : ObjectTaskBase("relocate", mergedRelocate(params)) {
  const TaskParams p = mergedRelocate(params);
  const std::string task = "relocate";
  w_release_posture_ = weights_.index("w_release_posture");
  w_arm_posture_ = weights_.index("w_arm_posture");
  w_wrist_posture_ = weights_.index("w_wrist_posture");
  goal_tolerance_ = paramNumber(task, p, "goal_tolerance", 0, 1);
  reach_radius_ = paramNumber(task, p, "reach_radius", 0.01, 10);
  release_keyframe_ = paramString(task, p, "release_keyframe");
  arm_joint_prefix_ = paramString(task, p, "arm_joint_prefix");
  wrist_joint_prefix_ = paramString(task, p, "wrist_joint_prefix");
  hold_position_ = paramVector3(task, p, "hold_position");
  std::string why;
  if (!checkGoal(hold_position_, paramQuaternion(task, p, "hold_quat"), workspace_, &hold_orientation_, &why))
    throw std::invalid_argument("task relocate: parameter 'hold_position': " + why);
  if (paramVector(task, p, "goal_position", -1).empty()) {
    phase_ = Phase::kHold;
    goal_position_ = hold_position_;
    goal_orientation_ = hold_orientation_;
  } else {
    phase_ = Phase::kGoal;  // the base checked the goal against the workspace
  }
}

void RelocateTask::bind(const mjModel* model, int synergy_dims) {
  ObjectTaskBase::bind(model, synergy_dims);
  const int key = mj_name2id(model, mjOBJ_KEY, release_keyframe_.c_str());
  if (key < 0)
    throw std::invalid_argument("task relocate: the model has no keyframe '" + release_keyframe_ +
                                "' (parameter release_keyframe)");
  robot_joints_ = JointList::where(model, [](const std::string&) { return true; });
  const auto starting = [model](const std::string& prefix) {
    return JointList::where(model, [&prefix](const std::string& name) { return name.rfind(prefix, 0) == 0; });
  };
  arm_joints_ = starting(arm_joint_prefix_);
  wrist_joints_ = starting(wrist_joint_prefix_);
  const auto targets = [&](const JointList& joints) {
    std::vector<double> q(joints.size());
    for (int i = 0; i < joints.size(); ++i) q[i] = model->key_qpos[key * model->nq + joints.qpos_adr[i]];
    return q;
  };
  rest_targets_ = targets(robot_joints_);
  arm_targets_ = targets(arm_joints_);
  wrist_targets_ = targets(wrist_joints_);
  unit_scales_.assign(robot_joints_.size(), 1.0);
}

void RelocateTask::copyParametersFrom(const Task& other) {
  const auto* source = dynamic_cast<const RelocateTask*>(&other);
  if (!source) throw std::invalid_argument("task relocate: cannot copy the parameters of task " + other.name());
  copyBaseFrom(*source);
  phase_ = source->phase_;
  in_reach_ = source->in_reach_;
}

bool RelocateTask::setGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation,
                           std::string* why) {
  Eigen::Quaterniond unit;
  if (!checkGoal(position, orientation, workspace_, &unit, why)) return false;
  goal_position_ = position;
  goal_orientation_ = unit;
  phase_ = Phase::kGoal;  // also after a release: hold it again and bring it there
  goal_reached_reported_ = false;
  return true;
}

bool RelocateTask::release(std::string* why) {
  if (phase_ == Phase::kRelease) {
    *why = "task relocate: the object is already released";
    return false;
  }
  phase_ = Phase::kRelease;
  return true;
}

const char* RelocateTask::phaseName(Phase phase) {
  switch (phase) {
    case Phase::kHold: return "hold";
    case Phase::kGoal: return "goal";
    case Phase::kRelease: return "release";
  }
  return "?";
}

std::vector<TaskEvent> RelocateTask::observe(const mjModel* m, const mjData* d, double) {
  std::vector<TaskEvent> events;
  if (!phase_reported_ || reported_phase_ != phase_) {
    events.push_back({"phase", phaseName(phase_)});
    phase_reported_ = true;
    reported_phase_ = phase_;
  }
  const bool in_reach = (object_point_.position(d) - grasp_point_.position(d)).norm() <= reach_radius_;
  if (in_reach != in_reach_) {
    in_reach_ = in_reach;
    events.push_back({"object", in_reach ? "in reach" : "out of reach"});
  }
  if (phase_ == Phase::kGoal && !goal_reached_reported_) {
    const double distance = error(m, d);
    if (distance <= goal_tolerance_) {
      events.push_back({"goal_reached", std::to_string(distance)});
      goal_reached_reported_ = true;
    }
  }
  return events;
}

double RelocateTask::extraStateCost(const mjModel* m, const mjData* d, double scale, ResidualBuffer& buf,
                                    CostDerivatives* out) const {
  // A quadratic pull of some joints towards their release-keyframe angles (none at weight 0).
  const auto posture = [&](const JointList& joints, const std::vector<double>& targets, double weight) {
    if (joints.size() == 0 || !(weight > 0)) return 0.0;
    jointResidual(m, d, joints, targets.data(), unit_scales_.data(), out != nullptr, buf);
    return addResidualCost(scale * weight, Norm::quadratic(), buf, out);
  };
  double cost = posture(arm_joints_, arm_targets_, weights_[w_arm_posture_]) +
                posture(wrist_joints_, wrist_targets_, weights_[w_wrist_posture_]);
  if (phase_ == Phase::kRelease) cost += posture(robot_joints_, rest_targets_, weights_[w_release_posture_]);
  return cost;
}

}  // namespace adroit_mpc
