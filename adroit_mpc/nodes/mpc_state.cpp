// State input (state queue): the driver's joint states and object odometry -> the planning
// model's qpos / qvel, so the same node runs on the simulator and on estimated hardware state.
// Messages are validated first; a bad one is rejected as a whole, counted and logged (throttled).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "mpc_ros.h"

namespace adroit::mpc_node {

namespace {

bool allFinite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

long long steadyNs() { return std::chrono::steady_clock::now().time_since_epoch().count(); }

}  // namespace

bool MpcNode::rebuildJointMap(const std::vector<std::string>& names) {
  joint_map_names_ = names;
  joint_map_qpos_.assign(names.size(), -1);
  joint_map_dof_.assign(names.size(), -1);
  std::vector<char> covered(model_->njnt, 0);
  for (std::size_t i = 0; i < names.size(); ++i) {
    const auto j = tables_->joints.find(names[i]);
    if (!j) continue;  // a joint the planning model does not have: ignored
    const int type = model_->jnt_type[*j];
    if (type != mjJNT_HINGE && type != mjJNT_SLIDE) continue;
    joint_map_qpos_[i] = model_->jnt_qposadr[*j];
    joint_map_dof_[i] = model_->jnt_dofadr[*j];
    covered[*j] = 1;
  }
  for (int j : hinge_joints_) {
    if (!covered[j]) {
      last_rejection_ = "joint state lacks joint '" + tables_->joints.name(j) + "' of the planning model";
      return false;
    }
  }
  return true;
}

void MpcNode::onJointState(const sensor_msgs::JointState::ConstPtr& msg) {
  const sensor_msgs::JointState& m = *msg;
  if (m.position.size() != m.name.size() || m.velocity.size() != m.name.size()) {
    rejections_.count(kJointLength);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: rejected joint state: %zu names, %zu positions, %zu velocities",
                       m.name.size(), m.position.size(), m.velocity.size());
    return;
  }
  if (!allFinite(m.position) || !allFinite(m.velocity)) {
    rejections_.count(kJointNonFinite);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: rejected joint state: NaN or Inf in position or velocity");
    return;
  }
  std::lock_guard<PiMutex> lock(state_mutex_);
  if (m.name != joint_map_names_) joint_map_ok_ = rebuildJointMap(m.name);  // allocates only on a new layout
  if (!joint_map_ok_) {
    rejections_.count(kJointMissing);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: rejected joint state: %s", last_rejection_.c_str());
    return;
  }
  for (std::size_t i = 0; i < m.name.size(); ++i) {
    if (joint_map_qpos_[i] < 0) continue;
    incoming_.qpos[joint_map_qpos_[i]] = m.position[i];
    incoming_.qvel[joint_map_dof_[i]] = m.velocity[i];
  }
  const ros::Time stamp = m.header.stamp.isZero() ? ros::Time::now() : m.header.stamp;
  if (!time_origin_set_) {
    time_origin_ = stamp;
    time_origin_set_ = true;
  }
  incoming_.time = nodeTime(stamp);
  ++incoming_.serial;
  joints_seen_ = true;
  joint_states_accepted_.fetch_add(1, std::memory_order_relaxed);
  state_wall_ns_.store(steadyNs(), std::memory_order_relaxed);
}

void MpcNode::onOdometry(const nav_msgs::Odometry::ConstPtr& msg) {
  if (object_qpos_ < 0) return;  // the scene has no free object
  const nav_msgs::Odometry& m = *msg;
  if (!m.header.frame_id.empty() && m.header.frame_id != "world") {
    rejections_.count(kOdomFrame);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: rejected object odometry: frame '%s', expected 'world'",
                       m.header.frame_id.c_str());
    return;
  }
  const auto& p = m.pose.pose.position;
  const auto& q = m.pose.pose.orientation;
  const auto& v = m.twist.twist.linear;
  const auto& w = m.twist.twist.angular;
  const double values[] = {p.x, p.y, p.z, q.w, q.x, q.y, q.z, v.x, v.y, v.z, w.x, w.y, w.z};
  if (!std::all_of(std::begin(values), std::end(values), [](double x) { return std::isfinite(x); })) {
    rejections_.count(kOdomNonFinite);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: rejected object odometry: NaN or Inf");
    return;
  }
  const double norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  if (std::abs(norm - 1.0) > 1e-2) {
    rejections_.count(kOdomQuaternion);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: rejected object odometry: quaternion norm %g, expected 1", norm);
    return;
  }
  // MuJoCo's free joint: position, quaternion (w x y z); linear velocity in the world frame,
  // angular velocity in the body frame. nav_msgs/Odometry (and the driver) give both in the
  // child (object) frame, so the linear part is rotated into the world.
  double quat[4] = {q.w / norm, q.x / norm, q.y / norm, q.z / norm};
  double rot[9], linear_world[3];
  const double linear_body[3] = {v.x, v.y, v.z};
  mju_quat2Mat(rot, quat);
  mju_rotVecMat(linear_world, linear_body, rot);
  std::lock_guard<PiMutex> lock(state_mutex_);
  double* qpos = incoming_.qpos.data() + object_qpos_;
  double* qvel = incoming_.qvel.data() + object_dof_;
  qpos[0] = p.x, qpos[1] = p.y, qpos[2] = p.z;
  std::copy(quat, quat + 4, qpos + 3);
  std::copy(linear_world, linear_world + 3, qvel);
  qvel[3] = w.x, qvel[4] = w.y, qvel[5] = w.z;
  if (time_origin_set_ && !m.header.stamp.isZero()) incoming_.object_time = nodeTime(m.header.stamp);
  object_seen_ = true;
  odom_accepted_.fetch_add(1, std::memory_order_relaxed);
}

bool MpcNode::latestState(StateSnapshot& out) {
  std::lock_guard<PiMutex> lock(state_mutex_);
  if (!joints_seen_ || (object_qpos_ >= 0 && !object_seen_)) return false;
  out.time = incoming_.time;
  out.object_time = incoming_.object_time;
  out.serial = incoming_.serial;
  std::copy(incoming_.qpos.begin(), incoming_.qpos.end(), out.qpos.begin());
  std::copy(incoming_.qvel.begin(), incoming_.qvel.end(), out.qvel.begin());
  std::copy(incoming_.act.begin(), incoming_.act.end(), out.act.begin());
  return true;
}

double MpcNode::stateAgeWall() const {
  const long long ns = state_wall_ns_.load(std::memory_order_relaxed);
  if (ns == 0) return std::numeric_limits<double>::infinity();
  return (steadyNs() - ns) * 1e-9;
}

}  // namespace adroit::mpc_node
