// The free object's state (Signals::object layout) as nav_msgs/Odometry and the tf world ->
// object: one conversion for the simulation driver and for the hardware emulator's stand-in
// for the motion-capture system. Allocates nothing (header, frames and stamp are the caller's).
#pragma once

#include <mujoco/mujoco.h>

#include <array>

#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Odometry.h>

namespace adroit::driver {

// o: position (3), quaternion w x y z (4), linear velocity in the world frame (3), angular
// velocity in the object frame (3), as MuJoCo's free joint gives them.
inline void fillObjectOdometry(const std::array<double, 13>& o, nav_msgs::Odometry* odom,
                               geometry_msgs::TransformStamped* tf) {
  auto& pose = odom->pose.pose;
  pose.position.x = o[0], pose.position.y = o[1], pose.position.z = o[2];
  pose.orientation.w = o[3], pose.orientation.x = o[4], pose.orientation.y = o[5], pose.orientation.z = o[6];
  // nav_msgs/Odometry: the twist in the child (object) frame.
  double rot[9], linear_body[3];
  mju_quat2Mat(rot, o.data() + 3);
  mju_rotVecMatT(linear_body, o.data() + 7, rot);
  auto& tw = odom->twist.twist;
  tw.linear.x = linear_body[0], tw.linear.y = linear_body[1], tw.linear.z = linear_body[2];
  tw.angular.x = o[10], tw.angular.y = o[11], tw.angular.z = o[12];
  tf->header = odom->header;
  tf->child_frame_id = odom->child_frame_id;
  tf->transform.translation.x = pose.position.x;
  tf->transform.translation.y = pose.position.y;
  tf->transform.translation.z = pose.position.z;
  tf->transform.rotation = pose.orientation;
}

}  // namespace adroit::driver
