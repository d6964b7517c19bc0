#include "adroit_mpc/relocate_task.h"

#include <cmath>
#include <stdexcept>

namespace adroit_mpc {

TaskParams RelocateTask::defaults() {
  TaskParams p;
  p.strings = {{"scene", "ball"}, {"object_body", "object"}, {"object_joint", "object_root"},
               {"grasp_site", "S_grasp"}, {"release_keyframe", "rest"},
               {"thumb_site", "S_thtip"}, {"finger_sites", "S_fftip S_mftip S_rftip S_lftip"}};
  p.numbers = {{"w_object_velocity", 0.5}, {"w_goal_position", 10.0},   {"w_goal_orientation", 0.0},
               {"w_grasp", 1.0},           {"w_control", 0.1},         {"w_synergy", 0.08},
               {"w_release_clearance", 20.0}, {"w_release_posture", 0.5},
               {"w_pregrasp", 10.0},       {"w_fingertip", 5.0},       {"w_opposition", 5.0},
               {"w_carry", 30.0},          {"w_below", 5.0},           {"below_depth", 0.01},
               {"terminal_scale", 10.0},   {"velocity_angular_scale", 0.035},
               {"position_smoothing", 0.02}, {"grasp_smoothing", 0.02},
               {"release_clearance", 0.12}, {"goal_tolerance", 0.02},
               {"fingertip_offset", 0.008}, {"fingertip_smoothing", 0.01},
               {"open_margin", 0.03},      {"squeeze", 0.01},
               {"pregrasp_tolerance", 0.04}, {"grasp_start_gap", 0.045},
               {"hold_gap", 0.015},        {"lost_gap", 0.05},         {"min_fingers", 2},
               {"horizon", 0.3},           {"planner_dt", 0.01},
               {"object_mass", 0.18},      {"object_radius", 0.035}};
  p.vectors = {{"goal_position", {}},
               {"pregrasp_offset", {0.0, 0.0, 0.05}},
               {"goal_quat", {1, 0, 0, 0}},
               {"hold_position", {0.0, -0.25, 0.15}},
               {"hold_quat", {1, 0, 0, 0}},
               {"orientation_axes", {1, 1, 1}},
               {"workspace_min", {-0.35, -0.55, 0.035}},
               {"workspace_max", {0.35, -0.15, 0.4}},
               {"object_start_position", {0.0, -0.21, 0.035}},
               {"object_start_quat", {1, 0, 0, 0}}};
  return p;
}

namespace {
TaskParams mergedRelocate(const TaskParams& params) {
  return mergeTaskParams("relocate", RelocateTask::defaults(), params);
}

std::vector<std::string> splitNames(const std::string& s) {
  std::vector<std::string> names;
  std::string name;
  for (const char c : s + " ") {
    if (c == ' ' || c == ',') {
      if (!name.empty()) names.push_back(name);
      name.clear();
    } else {
      name += c;
    }
  }
  return names;
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
  w_pregrasp_ = weights_.index("w_pregrasp");
  w_fingertip_ = weights_.index("w_fingertip");
  w_opposition_ = weights_.index("w_opposition");
  w_carry_ = weights_.index("w_carry");
  w_below_ = weights_.index("w_below");
  below_depth_ = paramNumber(task, p, "below_depth", -1, 1);
  pregrasp_offset_ = paramVector3(task, p, "pregrasp_offset");
  object_radius_ = paramNumber(task, p, "object_radius", 1e-4, 1);
  fingertip_offset_ = paramNumber(task, p, "fingertip_offset", 0, 0.1);
  fingertip_smoothing_ = paramNumber(task, p, "fingertip_smoothing", 1e-6, 1);
  open_margin_ = paramNumber(task, p, "open_margin", 0, 0.5);
  squeeze_ = paramNumber(task, p, "squeeze", 0, object_radius_);
  pregrasp_tolerance_ = paramNumber(task, p, "pregrasp_tolerance", 0, 1);
  hold_gap_ = paramNumber(task, p, "hold_gap", 0, 0.5);
  grasp_start_gap_ = paramNumber(task, p, "grasp_start_gap", hold_gap_, 0.5);
  lost_gap_ = paramNumber(task, p, "lost_gap", grasp_start_gap_, 1);
  thumb_site_name_ = paramString(task, p, "thumb_site");
  finger_site_names_ = splitNames(paramString(task, p, "finger_sites"));
  if (finger_site_names_.empty())
    throw std::invalid_argument("task relocate: parameter 'finger_sites' names no site");
  const double min_fingers = paramNumber(task, p, "min_fingers", 1, finger_site_names_.size());
  if (min_fingers != std::floor(min_fingers))
    throw std::invalid_argument("task relocate: parameter 'min_fingers' must be a whole number");
  min_fingers_ = static_cast<int>(min_fingers);
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
  try {
    thumb_point_ = BodyPoint::site(model, thumb_site_name_);
    finger_points_.clear();
    for (const auto& name : finger_site_names_) finger_points_.push_back(BodyPoint::site(model, name));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("task relocate: ") + e.what() + " (parameters thumb_site, finger_sites)");
  }
  gaps_.assign(1 + finger_points_.size(), 0.0);
}

void RelocateTask::copyParametersFrom(const Task& other) {
  const auto* source = dynamic_cast<const RelocateTask*>(&other);
  if (!source) throw std::invalid_argument("task relocate: cannot copy the parameters of task " + other.name());
  copyBaseFrom(*source);
  phase_ = source->phase_;
  stage_ = source->stage_;
  carry_offset_ = source->carry_offset_;
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

const char* RelocateTask::stageName(Stage stage) {
  switch (stage) {
    case Stage::kApproach: return "approach";
    case Stage::kGrasp: return "grasp";
    case Stage::kCarry: return "carry";
  }
  return "?";
}

void RelocateTask::fingertipGaps(const mjData* d, std::vector<double>* gaps) const {
  if (!bound_) throw std::logic_error("task relocate: fingertipGaps() before bind()");
  gaps->resize(1 + finger_points_.size());
  const Eigen::Vector3d centre = object_point_.position(d);
  const double surface = object_radius_ + fingertip_offset_;
  (*gaps)[0] = (thumb_point_.position(d) - centre).norm() - surface;
  for (std::size_t i = 0; i < finger_points_.size(); ++i)
    (*gaps)[1 + i] = (finger_points_[i].position(d) - centre).norm() - surface;
}

std::vector<TaskEvent> RelocateTask::observe(const mjModel* m, const mjData* d, double) {
  std::vector<TaskEvent> events;
  if (!phase_reported_ || reported_phase_ != phase_) {
    events.push_back({"phase", phaseName(phase_)});
    phase_reported_ = true;
    reported_phase_ = phase_;
  }
  if (phase_ != Phase::kRelease) {
    // The thumb and at least min_fingers fingers within `gap` of the surface.
    fingertipGaps(d, &gaps_);
    const auto within = [&](double gap) {
      if (gaps_[0] > gap) return false;
      int fingers = 0;
      for (std::size_t i = 1; i < gaps_.size(); ++i) fingers += gaps_[i] <= gap;
      return fingers >= min_fingers_;
    };
    const Eigen::Vector3d pregrasp = object_point_.position(d) + pregrasp_offset_;
    const bool over = (grasp_point_.position(d) - pregrasp).norm() <= pregrasp_tolerance_;
    if (within(hold_gap_)) {
      // The hand's place on the object as it is taken: carry moves the hand there about the goal.
      if (stage_ != Stage::kCarry) carry_offset_ = grasp_point_.position(d) - object_point_.position(d);
      stage_ = Stage::kCarry;
    } else if (stage_ == Stage::kApproach && over && within(grasp_start_gap_)) stage_ = Stage::kGrasp;
    else if (stage_ != Stage::kApproach && !within(lost_gap_)) stage_ = Stage::kApproach;
    if (stage_ != reported_stage_) {
      events.push_back({"stage", stageName(stage_)});
      reported_stage_ = stage_;
    }
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
  const bool derivatives = out != nullptr;
  double cost = 0;
  if (phase_ != Phase::kRelease) {
    const Norm tip_norm = Norm::smoothAbs(fingertip_smoothing_);
    const bool approach = stage_ == Stage::kApproach;
    if (approach) {
      // grasp site - (object + offset): the offset is in the world frame (a ball rolls).
      pointResidual(m, d, grasp_point_, object_point_, derivatives, buf);
      buf.r.head<3>() -= pregrasp_offset_;
      cost += addResidualCost(scale * weights_[w_pregrasp_], Norm::smoothAbs(grasp_smoothing_), buf, out);
    }
    if (stage_ == Stage::kCarry) {
      // The hand leads: grasp site to the goal + its offset on the object when it was taken.
      pointResidual(m, d, grasp_point_, BodyPoint::world(goal_position_ + carry_offset_), derivatives, buf);
      cost += addResidualCost(scale * weights_[w_carry_], Norm::smoothAbs(position_smoothing_), buf, out);
    }
    // Fingertips (their pads) onto the surface, or hovering open_margin outside it.
    const double radius = object_radius_ + fingertip_offset_ + (approach ? open_margin_ : -squeeze_);
    sphereSurfaceResidual(m, d, thumb_point_, object_point_, radius, derivatives, buf);
    cost += addResidualCost(scale * weights_[w_fingertip_], tip_norm, buf, out);
    for (const auto& finger : finger_points_) {
      sphereSurfaceResidual(m, d, finger, object_point_, radius, derivatives, buf);
      cost += addResidualCost(scale * weights_[w_fingertip_], tip_norm, buf, out);
    }
    // Fingertips below the object's centre (below its equator for a ball): a cage that holds.
    aboveResidual(m, d, thumb_point_, object_point_, -below_depth_, derivatives, buf);
    cost += addResidualCost(scale * weights_[w_below_], tip_norm, buf, out);
    for (const auto& finger : finger_points_) {
      aboveResidual(m, d, finger, object_point_, -below_depth_, derivatives, buf);
      cost += addResidualCost(scale * weights_[w_below_], tip_norm, buf, out);
    }
    // Opposition: the thumb a diameter of that sphere away from each finger (opposite sides).
    for (const auto& finger : finger_points_) {
      clearanceResidual(m, d, thumb_point_, finger, 2 * radius, derivatives, buf);
      cost += addResidualCost(scale * weights_[w_opposition_], tip_norm, buf, out);
    }
    return cost;
  }
  clearanceResidual(m, d, grasp_point_, object_point_, release_clearance_, derivatives, buf);
  cost += addResidualCost(scale * weights_[w_release_clearance_], Norm::quadratic(), buf, out);
  jointResidual(m, d, robot_joints_, rest_targets_.data(), unit_scales_.data(), derivatives, buf);
  cost += addResidualCost(scale * weights_[w_release_posture_], Norm::quadratic(), buf, out);
  return cost;
}

}  // namespace adroit_mpc
