#include "adroit_learning/pickup.h"

#include <cmath>
#include <stdexcept>

namespace adroit {

Eigen::Vector3d objectAxis(const Eigen::Quaterniond& q, const ObjectGeometry& geometry) {
  return (q.normalized() * geometry.axis_in_body.normalized()).normalized();
}

PickupVerdict pickupSuccess(const ObjectState& tube, const ObjectGeometry& geometry, const PickupThresholds& th) {
  if (!geometry.valid()) throw std::invalid_argument("pickupSuccess: the object's geometry is unknown");
  PickupVerdict v;
  const Eigen::Vector3d axis = objectAxis(tube.orientation, geometry);
  for (int end = 0; end < 2; ++end) {
    const double z = tube.position.z() + (end == 0 ? 1.0 : -1.0) * geometry.half_length * axis.z();
    v.end_clearance[end] = z - geometry.radius - geometry.table_top;
  }
  // |cos|: the axis anti-parallel to x is as aligned as parallel (symmetric tube).
  v.axis_angle = std::acos(std::min(1.0, std::abs(axis.x())));
  v.speed = tube.linear_velocity.norm();
  v.angular_speed = tube.angular_velocity.norm();
  if (!(std::isfinite(v.speed) && std::isfinite(v.angular_speed) && tube.position.allFinite()))
    v.failure = "non-finite object state";
  else if (v.speed > th.max_speed || v.angular_speed > th.max_angular_speed)
    v.failure = "not stationary";
  else if (std::min(v.end_clearance[0], v.end_clearance[1]) < th.min_end_clearance)
    v.failure = "an end is below the lift height";
  else if (v.axis_angle > th.max_axis_angle)
    v.failure = "not aligned with x";
  v.success = v.failure.empty();
  return v;
}

Eigen::Quaterniond tubeOrientationFromYaw(double yaw_degrees, const ObjectGeometry& geometry) {
  if (!std::isfinite(yaw_degrees) || yaw_degrees < 0 || yaw_degrees >= 180)
    throw std::invalid_argument("tube yaw must be in [0, 180) degrees, got " + std::to_string(yaw_degrees));
  // First the body's axis onto world x (identity for the scene's tube, whose axis is body x),
  // then the yaw about the vertical: the axis stays horizontal, so the tube lies flat.
  const Eigen::Quaterniond onto_x =
      Eigen::Quaterniond::FromTwoVectors(geometry.axis_in_body.normalized(), Eigen::Vector3d::UnitX());
  const Eigen::Quaterniond yaw(Eigen::AngleAxisd(yaw_degrees * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  return (yaw * onto_x).normalized();
}

double tubeYawDegrees(const Eigen::Quaterniond& q, const ObjectGeometry& geometry) {
  const Eigen::Vector3d axis = objectAxis(q, geometry);
  const double horizontal = std::hypot(axis.x(), axis.y());
  if (!(horizontal > 1e-9)) throw std::invalid_argument("the tube's axis is vertical or not finite: it has no yaw");
  // Either end of the symmetric tube gives the same yaw modulo 180.
  double yaw = std::atan2(axis.y(), axis.x()) * 180.0 / M_PI;
  if (yaw < 0) yaw += 180.0;
  if (yaw >= 180.0) yaw -= 180.0;  // also -1e-17 + 180, which rounds to 180
  return yaw;
}

}  // namespace adroit
