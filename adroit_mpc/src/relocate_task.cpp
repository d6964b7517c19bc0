#include "adroit_mpc/relocate_task.h"

#include <stdexcept>

namespace adroit_mpc {

TaskParams RelocateTask::defaults() {
  TaskParams p;
  p.strings = {{"scene", "ball"}, {"object_body", "object"}, {"object_joint", "object_root"},
               {"grasp_site", "S_grasp"}, {"release_keyframe", "rest"}};
  p.numbers = {{"w_object_velocity", 0.5}, {"w_goal_position", 10.0},   {"w_goal_orientation", 0.0},
               {"w_grasp", 1.0},           {"w_control", 0.1},         {"w_synergy", 0.08},
               {"w_release_clearance", 20.0}, {"w_release_posture", 0.5},
               {"terminal_scale", 10.0},   {"velocity_angular_scale", 0.035},
               {"position_smoothing", 0.02}, {"grasp_smoothing", 0.02},
               {"release_clearance", 0.12}, {"goal_tolerance", 0.02},
               {"horizon", 0.3},           {"planner_dt", 0.01},
               {"object_mass", 0.18},      {"object_radius", 0.035}};
  p.vectors = {{"goal_position", {}},
               {"goal_quat", {1, 0, 0, 0}},
               {"hold_position", {0.0, -0.25, 0.15}},
               {"hold_quat", {1, 0, 0, 0}},
               {"orientation_axes", {1, 1, 1}},
               {"workspace_min", {-0.35, -0.55, 0.035}},
               {"workspace_max", {0.35, -0.15, 0.4}},
               {"object_start_position", {0.0, -0.15, 0.035}},
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
  w_release_clearance_ = weights_.index("w_release_clearance");
  w_release_posture_ = weights_.index("w_release_posture");
  release_clearance_ = paramNumber(task, p, "release_clearance", 0, 2);
  goal_tolerance_ = paramNumber(task, p, "goal_tolerance", 0, 1);
  release_keyframe_ = paramString(task, p, "release_keyframe");
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
  rest_targets_.resize(robot_joints_.size());
  unit_scales_.assign(robot_joints_.size(), 1.0);
  for (int i = 0; i < robot_joints_.size(); ++i)
    rest_targets_[i] = model->key_qpos[key * model->nq + robot_joints_.qpos_adr[i]];
}

void RelocateTask::copyParametersFrom(const Task& other) {
  const auto* source = dynamic_cast<const RelocateTask*>(&other);
  if (!source) throw std::invalid_argument("task relocate: cannot copy the parameters of task " + other.name());
  copyBaseFrom(*source);
  phase_ = source->phase_;
}

bool RelocateTask::setGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation,
                           std::string* why) {
  Eigen::Quaterniond unit;
  if (!checkGoal(position, orientation, workspace_, &unit, why)) return false;
  goal_position_ = position;
  goal_orientation_ = unit;
  phase_ = Phase::kGoal;  // also after a release: grasp again and bring it there
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
  if (phase_ != Phase::kRelease) return 0;
  const bool derivatives = out != nullptr;
  double cost = 0;
  clearanceResidual(m, d, grasp_point_, object_point_, release_clearance_, derivatives, buf);
  cost += addResidualCost(scale * weights_[w_release_clearance_], Norm::quadratic(), buf, out);
  jointResidual(m, d, robot_joints_, rest_targets_.data(), unit_scales_.data(), derivatives, buf);
  cost += addResidualCost(scale * weights_[w_release_posture_], Norm::quadratic(), buf, out);
  return cost;
}

}  // namespace adroit_mpc
