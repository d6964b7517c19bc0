#include "adroit_mpc/catch_task.h"

#include <algorithm>
#include <stdexcept>

namespace adroit_mpc {

namespace {

struct ObjectScratch : TaskScratch {
  explicit ObjectScratch(const mjModel* m) : buf(m, std::max(6, m->nv)) {}
  ResidualBuffer buf;
};

ObjectScratch& scratchOf(TaskScratch& s, const std::string& task) {
  auto* scratch = dynamic_cast<ObjectScratch*>(&s);
  if (!scratch) throw std::invalid_argument("task " + task + ": scratch was not made by this task");
  return *scratch;
}

}  // namespace

ObjectTaskBase::ObjectTaskBase(const std::string& task, const TaskParams& p)
    : task_name_(task), weights_(task, p) {
  w_object_velocity_ = weights_.index("w_object_velocity");
  w_goal_position_ = weights_.index("w_goal_position");
  w_goal_orientation_ = weights_.index("w_goal_orientation");
  w_grasp_ = weights_.index("w_grasp");
  w_control_ = weights_.index("w_control");
  w_synergy_ = weights_.index("w_synergy");
  orientation_axes_ = paramVector3(task, p, "orientation_axes");
  if ((orientation_axes_.array() < 0).any())
    throw std::invalid_argument("task " + task + ": parameter 'orientation_axes' must be >= 0");
  workspace_.min = paramVector3(task, p, "workspace_min");
  workspace_.max = paramVector3(task, p, "workspace_max");
  if ((workspace_.min.array() >= workspace_.max.array()).any())
    throw std::invalid_argument("task " + task + ": parameter 'workspace_min' must be below 'workspace_max'");
  velocity_angular_scale_ = paramNumber(task, p, "velocity_angular_scale", 0, 10);
  position_smoothing_ = paramNumber(task, p, "position_smoothing", 1e-6, 10);
  grasp_smoothing_ = paramNumber(task, p, "grasp_smoothing", 1e-6, 10);
  terminal_scale_ = paramNumber(task, p, "terminal_scale", 0, 1e6);
  horizon_hint_ = paramNumber(task, p, "horizon", 1e-3, 10);
  planner_dt_hint_ = paramNumber(task, p, "planner_dt", 1e-4, 1);
  object_start_position_ = paramVector3(task, p, "object_start_position");
  object_start_orientation_ = paramQuaternion(task, p, "object_start_quat");
  paramNumber(task, p, "object_mass", 1e-6, 100);
  paramNumber(task, p, "object_radius", 1e-4, 1);
  object_body_name_ = paramString(task, p, "object_body");
  object_joint_name_ = paramString(task, p, "object_joint");
  grasp_site_name_ = paramString(task, p, "grasp_site");
  paramString(task, p, "scene");
  // The goal is checked like a live setGoal: a YAML goal outside the box is a bad parameter.
  goal_orientation_ = paramQuaternion(task, p, "goal_quat");
  const auto goal = paramVector(task, p, "goal_position", -1);
  if (goal.size() == 3) {
    goal_position_ = Eigen::Vector3d(goal[0], goal[1], goal[2]);
    std::string why;
    if (!checkGoal(goal_position_, goal_orientation_, workspace_, &goal_orientation_, &why))
      throw std::invalid_argument("task " + task + ": parameter 'goal_position': " + why);
  } else if (!goal.empty() || task == "catch") {
    throw std::invalid_argument("task " + task + ": parameter 'goal_position' needs 3 numbers (got " +
                                std::to_string(goal.size()) + ")");
  } else {
    goal_position_ = object_start_position_;  // relocate without a goal: its hold pose decides
  }
}

void ObjectTaskBase::copyBaseFrom(const ObjectTaskBase& other) {
  weights_.copyValuesFrom(other.weights_);
  goal_position_ = other.goal_position_;
  goal_orientation_ = other.goal_orientation_;
}

void ObjectTaskBase::bind(const mjModel* model, int synergy_dims) {
  const std::string where = "task " + task_name_ + ": ";
  try {
    object_point_ = BodyPoint::bodyFrame(model, object_body_name_);
    grasp_point_ = BodyPoint::site(model, grasp_site_name_);
    object_dofs_ = DofList::freeJoint(model, object_joint_name_, velocity_angular_scale_);
    control_effort_.bind(model, synergy_dims);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(where + e.what());
  }
  object_body_ = object_point_.body;
  nv_ = model->nv;
  nx_ = 2 * model->nv + model->na;
  nu_total_ = model->nu + synergy_dims;
  bound_ = true;
}

std::unique_ptr<TaskScratch> ObjectTaskBase::makeScratch(const mjModel* model) const {
  return std::make_unique<ObjectScratch>(model);
}

void ObjectTaskBase::checkSizes(const Eigen::VectorXd& u, const CostDerivatives* out) const {
  if (!bound_) throw std::logic_error("task " + task_name_ + ": cost evaluated before bind()");
  if (u.size() != nu_total_)
    throw std::invalid_argument("task " + task_name_ + ": control has " + std::to_string(u.size()) +
                                " entries, expected " + std::to_string(nu_total_));
  if (out && (out->lx.size() != nx_ || out->lu.size() != nu_total_))
    throw std::invalid_argument("task " + task_name_ + ": CostDerivatives sized " + std::to_string(out->lx.size()) +
                                " x " + std::to_string(out->lu.size()) + ", expected " + std::to_string(nx_) +
                                " x " + std::to_string(nu_total_));
}

double ObjectTaskBase::stateCost(const mjModel* m, const mjData* d, double scale, ResidualBuffer& buf,
                                 CostDerivatives* out) const {
  const bool derivatives = out != nullptr;
  double cost = 0;
  velocityResidual(m, d, object_dofs_, derivatives, buf);
  cost += addResidualCost(scale * weights_[w_object_velocity_], Norm::quadratic(), buf, out);
  if (goalTermsActive()) {
    pointResidual(m, d, object_point_, BodyPoint::world(goal_position_), derivatives, buf);
    cost += addResidualCost(scale * weights_[w_goal_position_], Norm::smoothAbs(position_smoothing_), buf, out);
    if (weights_[w_goal_orientation_] > 0) {
      orientationResidual(m, d, object_body_, goal_orientation_, orientation_axes_, derivatives, buf);
      cost += addResidualCost(scale * weights_[w_goal_orientation_], Norm::quadratic(), buf, out);
    }
  }
  if (graspHintActive()) {
    pointResidual(m, d, object_point_, grasp_point_, derivatives, buf);
    cost += addResidualCost(scale * weights_[w_grasp_], Norm::smoothAbs(grasp_smoothing_), buf, out);
  }
  cost += extraStateCost(m, d, scale, buf, out);
  return cost;
}

double ObjectTaskBase::runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double,
                                   TaskScratch& s) const {
  checkSizes(u, nullptr);
  return stateCost(m, d, 1.0, scratchOf(s, task_name_).buf, nullptr) +
         control_effort_.value(u, weights_[w_control_], weights_[w_synergy_]);
}

double ObjectTaskBase::terminalCost(const mjModel* m, const mjData* d, double, TaskScratch& s) const {
  if (!bound_) throw std::logic_error("task " + task_name_ + ": cost evaluated before bind()");
  return stateCost(m, d, terminal_scale_, scratchOf(s, task_name_).buf, nullptr);
}

double ObjectTaskBase::runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double,
                                              TaskScratch& s, CostDerivatives& out) const {
  checkSizes(u, &out);
  out.setZero();
  return stateCost(m, d, 1.0, scratchOf(s, task_name_).buf, &out) +
         control_effort_.addDerivatives(u, weights_[w_control_], weights_[w_synergy_], out);
}

double ObjectTaskBase::terminalCostDerivatives(const mjModel* m, const mjData* d, double, TaskScratch& s,
                                               CostDerivatives& out) const {
  if (!bound_) throw std::logic_error("task " + task_name_ + ": cost evaluated before bind()");
  if (out.lx.size() != nx_)
    throw std::invalid_argument("task " + task_name_ + ": CostDerivatives has " + std::to_string(out.lx.size()) +
                                " state entries, expected " + std::to_string(nx_));
  out.setZero();
  return stateCost(m, d, terminal_scale_, scratchOf(s, task_name_).buf, &out);
}

double ObjectTaskBase::error(const mjModel*, const mjData* d) const {
  if (!bound_) throw std::logic_error("task " + task_name_ + ": error() before bind()");
  return (object_point_.position(d) - goal_position_).norm();
}

// ---------------------------------------------------------------------------------- catch

TaskParams CatchTask::defaults() {
  TaskParams p;
  p.strings = {{"scene", "bottle"}, {"object_body", "object"}, {"object_joint", "object_root"},
               {"grasp_site", "S_grasp"}};
  p.numbers = {{"w_object_velocity", 0.5}, {"w_goal_position", 10.0}, {"w_goal_orientation", 1.0},
               {"w_grasp", 1.0},           {"w_control", 0.1},       {"w_synergy", 0.08},
               {"terminal_scale", 10.0},   {"velocity_angular_scale", 0.03},
               {"position_smoothing", 0.02}, {"grasp_smoothing", 0.02},
               {"horizon", 0.3},           {"planner_dt", 0.02},
               {"object_mass", 0.25},      {"object_radius", 0.03}};
  p.vectors = {{"goal_position", {0.007, -0.19, 0.26}},
               {"goal_quat", {1, 0, 0, 0}},
               {"orientation_axes", {0, 1, 1}},
               {"workspace_min", {-0.15, -0.35, 0.2}},
               {"workspace_max", {0.15, -0.05, 0.4}},
               {"object_start_position", {0.007, -0.19, 0.31}},
               {"object_start_quat", {1, 0, 0, 0}}};
  return p;
}

CatchTask::CatchTask(const TaskParams& params)
    : ObjectTaskBase("catch", mergeTaskParams("catch", defaults(), params)) {}

void CatchTask::copyParametersFrom(const Task& other) {
  const auto* source = dynamic_cast<const CatchTask*>(&other);
  if (!source) throw std::invalid_argument("task catch: cannot copy the parameters of task " + other.name());
  copyBaseFrom(*source);
}

bool CatchTask::setGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation, std::string* why) {
  Eigen::Quaterniond unit;
  if (!checkGoal(position, orientation, workspace_, &unit, why)) return false;
  goal_position_ = position;
  goal_orientation_ = unit;
  return true;
}

}  // namespace adroit_mpc
