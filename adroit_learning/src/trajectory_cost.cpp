#include "adroit_learning/trajectory_cost.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace adroit {

namespace {

constexpr double kAtmosphere = 101325.0;
constexpr double kPressureScale = 1e5;  // Pa per state unit
constexpr double kMaxVolts = 5.0;

int indexOf(const std::vector<std::string>& names, const std::string& name) {
  const auto it = std::find(names.begin(), names.end(), name);
  return it == names.end() ? -1 : static_cast<int>(it - names.begin());
}

}  // namespace

StateLayout::StateLayout(const TrainingTask& task, const std::vector<std::string>& joints,
                         const std::vector<std::string>& cylinders, bool scene_has_object)
    : joint_names(joints), cylinder_names(cylinders), locked_command(task.locked_command), object_(task.uses_object()) {
  if (object_ && !scene_has_object)
    throw TaskError("task '" + task.name + "': object cost terms, but scene '" + task.scene + "' has no free object");
  for (const auto& [name, value] : task.target_joints)
    if (indexOf(joints, name) < 0) throw TaskError("task '" + task.name + "': target_joints: unknown joint '" + name + "'");
  for (const auto& [name, value] : task.initial_joints)
    if (indexOf(joints, name) < 0) throw TaskError("task '" + task.name + "': initial_joints: unknown joint '" + name + "'");
  for (const auto& name : task.locked_cylinders)
    if (indexOf(cylinders, name) < 0)
      throw TaskError("task '" + task.name + "': locked_cylinders: unknown cylinder '" + name + "'");
  for (int c = 0; c < static_cast<int>(cylinders.size()); ++c)
    if (std::find(task.locked_cylinders.begin(), task.locked_cylinders.end(), cylinders[c]) == task.locked_cylinders.end())
      action_cylinders.push_back(c);
  nx_ = 2 * this->joints() + (object_ ? 12 : 0) + static_cast<int>(cylinders.size());
}

Eigen::Vector3d rotationVector(const double q[4]) {
  // Shortest rotation: w >= 0, then angle = 2 atan2(|v|, w) in [0, pi].
  const double sign = q[0] < 0 ? -1.0 : 1.0;
  const Eigen::Vector3d v(sign * q[1], sign * q[2], sign * q[3]);
  const double s = v.norm();
  if (s < 1e-12) return 2.0 * v;  // small angle: angle * axis ~ 2 v
  return v * (2.0 * std::atan2(s, sign * q[0]) / s);
}

void StateLayout::state(const Observation& obs, Eigen::Ref<Eigen::VectorXd> x) const {
  const int nj = joints(), nc = static_cast<int>(cylinder_names.size());
  if (static_cast<int>(obs.joint_position.size()) != nj || static_cast<int>(obs.joint_velocity.size()) != nj ||
      static_cast<int>(obs.pressure.size()) != nc || x.size() != nx_)
    throw std::invalid_argument("observation has " + std::to_string(obs.joint_position.size()) + " joints and " +
                                std::to_string(obs.pressure.size()) + " cylinders, the layout " +
                                std::to_string(nj) + " and " + std::to_string(nc));
  for (int j = 0; j < nj; ++j) {
    x[q() + j] = obs.joint_position[j];
    x[qdot() + j] = obs.joint_velocity[j];
  }
  if (object_) {
    for (int i = 0; i < 3; ++i) x[objectPosition() + i] = obs.object[i];
    x.segment<3>(objectRotation()) = rotationVector(&obs.object[3]);
    for (int i = 0; i < 6; ++i) x[qdot() + nj + i] = obs.object[7 + i];
  }
  for (int c = 0; c < nc; ++c) x[pressures() + c] = (obs.pressure[c] - kAtmosphere) / kPressureScale;
}

void StateLayout::command(const Eigen::Ref<const Eigen::VectorXd>& u, std::vector<double>& volts) const {
  volts.assign(cylinder_names.size(), locked_command);
  for (int i = 0; i < nu(); ++i) {
    const double v = std::isfinite(u[i]) ? u[i] : 0.0;  // a non-finite gain product never reaches a valve
    volts[action_cylinders[i]] = std::clamp(v, -kMaxVolts, kMaxVolts);
  }
}

std::string StateLayout::describe() const {
  std::string s = "q:" + std::to_string(joints());
  if (object_) s += " object_position:3 object_rotation_vector:3";
  s += " qdot:" + std::to_string(joints());
  if (object_) s += " object_linear_velocity_world:3 object_angular_velocity_body:3";
  s += " pressure_bar_gauge:" + std::to_string(cylinder_names.size());
  return s;
}

TrajectoryCost::TrajectoryCost(const TrainingTask& task, const StateLayout& layout, const Eigen::VectorXd& x_initial,
                               const ObjectGeometry& geometry)
    : task_(task), geometry_(geometry), horizon_(task.horizon), nu_(layout.nu()),
      object_position_(layout.objectPosition()), object_rotation_(layout.objectRotation()),
      object_velocity_(layout.hasObject() ? layout.qdot() + layout.joints() : -1) {
  if (x_initial.size() != layout.nx()) throw std::invalid_argument("initial state size differs from the layout");
  if (task.pickupSuccessCriterion() && !geometry.valid())
    throw TaskError("task '" + task.name + "': the pickup criterion needs the object's geometry from the scene");
  // ||q - q*||^2 over every joint: unlisted joints are held at their initial angle.
  target_q_ = x_initial.segment(layout.q(), layout.joints());
  for (const auto& [name, value] : task.target_joints) {
    const int j = indexOf(layout.joint_names, name);
    target_q_[j] = value;
    target_joint_index_.push_back(layout.q() + j);
  }
  addJointTerm(layout);
  if (layout.hasObject()) addObjectTerms(layout, x_initial);
}

void TrajectoryCost::addJointTerm(const StateLayout& layout) {
  const int nx = layout.nx(), nj = layout.joints(), T = horizon_;
  StateResidualTerm joints{"joints", Eigen::MatrixXd::Zero(nj, nx), {}, task_.joint_weight,
                           task_.final_scale * task_.final_joint_weight};
  joints.A.block(0, layout.q(), nj, nj).setIdentity();
  if (task_.joint_reference.empty()) {
    joints.b.assign(T + 1, target_q_);
  } else {  // q_hat_t of a demonstration (thesis 10.4 shaping term)
    if (static_cast<int>(task_.joint_reference.size()) != T + 1)
      throw TaskError("task '" + task_.name + "': joint_reference has " + std::to_string(task_.joint_reference.size()) +
                      " steps, the horizon needs " + std::to_string(T + 1));
    for (const auto& q : task_.joint_reference) {
      if (static_cast<int>(q.size()) != nj || !Eigen::Map<const Eigen::VectorXd>(q.data(), nj).allFinite())
        throw TaskError("task '" + task_.name + "': joint_reference needs " + std::to_string(nj) +
                        " finite joint angles per step");
      joints.b.push_back(Eigen::Map<const Eigen::VectorXd>(q.data(), nj));
    }
  }
  terms_.push_back(std::move(joints));
}

void TrajectoryCost::addObjectTerms(const StateLayout& layout, const Eigen::VectorXd& x_initial) {
  const int nx = layout.nx(), T = horizon_;
  StateResidualTerm position{"object_position", Eigen::MatrixXd::Zero(3, nx), {}, task_.object_position_weight,
                             task_.final_scale * task_.object_position_weight};
  position.A.block(0, layout.objectPosition(), 3, 3).setIdentity();
  const Eigen::Vector3d p_target = task_.object_position_target.empty()
                                       ? Eigen::Vector3d(x_initial.segment<3>(layout.objectPosition()))
                                       : Eigen::Vector3d(task_.object_position_target.data());
  position.b.assign(T + 1, p_target);
  terms_.push_back(std::move(position));
  angle_row_ = Eigen::RowVectorXd::Zero(nx);
  for (int i = 0; i < 3; ++i) angle_row_[layout.objectRotation() + i] = task_.rotation_axis[i];
  StateResidualTerm rotation{"object_rotation", angle_row_, {}, task_.object_rotation_weight,
                             task_.final_scale * task_.object_rotation_weight};
  for (int t = 0; t <= T; ++t) rotation.b.push_back(Eigen::VectorXd::Constant(1, task_.rotation_target.at(t, T)));
  terms_.push_back(std::move(rotation));
  // Thesis 10.4: w_z (z_obj - z*)^2, "the final cost is the same as the running cost".
  if (task_.object_height_weight == 0) return;
  StateResidualTerm height{"object_height", Eigen::MatrixXd::Zero(1, nx), {}, task_.object_height_weight,
                           task_.final_scale * task_.object_height_weight};
  height.A(0, layout.objectPosition() + 2) = 1.0;
  height.b.assign(T + 1, Eigen::VectorXd::Constant(1, task_.object_height_target));
  terms_.push_back(std::move(height));
}

ObjectState TrajectoryCost::objectState(const Eigen::Ref<const Eigen::VectorXd>& x) const {
  if (object_position_ < 0) throw std::logic_error("objectState: the layout has no object");
  ObjectState s;
  s.position = x.segment<3>(object_position_);
  const Eigen::Vector3d rv = x.segment<3>(object_rotation_);
  const double angle = rv.norm();
  s.orientation = angle < 1e-12 ? Eigen::Quaterniond::Identity()
                                : Eigen::Quaterniond(Eigen::AngleAxisd(angle, rv / angle));
  s.linear_velocity = x.segment<3>(object_velocity_);
  s.angular_velocity = x.segment<3>(object_velocity_ + 3);
  return s;
}

double TrajectoryCost::rolloutCost(const Rollout& r) const {
  double cost = 0;
  for (int t = 0; t <= horizon_; ++t) {
    for (const auto& term : terms_) {
      const double w = t < horizon_ ? term.running_weight : term.final_weight;
      if (w != 0) cost += w * (term.A * r.x.col(t) - term.b[t]).squaredNorm();
    }
    if (t < horizon_) cost += task_.action_weight * r.u.col(t).squaredNorm();
  }
  return cost;
}

TaskOutcome TrajectoryCost::outcome(const Rollout& r) const {
  TaskOutcome o;
  o.cost = rolloutCost(r);
  const Eigen::VectorXd xT = r.x.col(horizon_);
  double sq = 0;
  for (int i : target_joint_index_) sq += std::pow(xT[i] - target_q_[i], 2);  // the q block starts at 0
  o.joint_rms = target_joint_index_.empty() ? 0.0 : std::sqrt(sq / target_joint_index_.size());
  bool ok = o.joint_rms <= task_.success_joint_rms || target_joint_index_.empty();
  if (task_.pickupSuccessCriterion()) {  // thesis 11.4 alone decides
    const PickupVerdict v = pickupSuccess(objectState(xT), geometry_);
    o.angle_error = v.axis_angle;
    o.object_height = xT[object_position_ + 2];
    o.dropped = o.object_height < task_.drop_height;
    o.failure = v.failure;
    o.success = v.success;
    return o;
  }
  if (angle_row_.size() > 0) {
    o.angle_error = std::abs(objectAngle(xT) - task_.rotation_target.at(horizon_, horizon_));
    o.object_height = xT[object_position_ + 2];
    o.dropped = o.object_height < task_.drop_height;
    ok = ok && o.angle_error <= task_.success_angle && !o.dropped;
  }
  o.success = ok;
  return o;
}

void TrajectoryCost::expand(const std::vector<Rollout>& samples, QuadraticCost& out) const {
  if (samples.empty()) throw std::invalid_argument("cost expansion needs at least one sample");
  const int nx = static_cast<int>(samples.front().x.rows());
  out.resize(nx, nu_, horizon_);
  for (int t = 0; t <= horizon_; ++t) {
    for (const auto& term : terms_) {
      const double w = t < horizon_ ? term.running_weight : term.final_weight;
      if (w == 0) continue;
      // w ||A x - b||^2 = 0.5 x'(2w A'A)x - 2w b'A x + const.
      out.cxx[t].noalias() += 2.0 * w * term.A.transpose() * term.A;
      out.cx[t].noalias() -= 2.0 * w * term.A.transpose() * term.b[t];
    }
    if (t < horizon_) out.cuu[t].diagonal().array() += 2.0 * task_.action_weight;
  }
}

}  // namespace adroit
