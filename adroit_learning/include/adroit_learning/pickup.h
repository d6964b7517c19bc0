// The pickup task of thesis 10.2 / 11.3 / 11.4: the success criterion of 11.4 and the tube's
// initial orientation, the one place every user (trainer, benchmarks, generalisation) takes
// them from. ROS-free and MuJoCo-free: the tube's geometry comes in as numbers that the sim
// layer reads from the model (adroit_learning/sim_rollouts.h: objectGeometry).
#pragma once
#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <string>

namespace adroit {

// A capsule (or cylinder) object: the half-length of its axis segment, its radius, the axis in
// the object body's frame, and the height of the table top it rests on (world z).
struct ObjectGeometry {
  double half_length = 0, radius = 0;
  Eigen::Vector3d axis_in_body = Eigen::Vector3d::UnitX();
  double table_top = 0;
  bool valid() const { return half_length > 0; }
};

// The object at the end of a rollout: position (world), orientation (body to world), linear
// velocity (world) and angular velocity (either frame: only its norm is used).
struct ObjectState {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d linear_velocity = Eigen::Vector3d::Zero(), angular_velocity = Eigen::Vector3d::Zero();
};

// Thresholds of the 11.4 criterion. The thesis names the conditions but gives no numbers
// ("above the ground by a certain height", "aligned with the x-axis"); these are ours:
struct PickupThresholds {
  // Lowest point of each end (end-cap centre z - radius) above the table top. 2 cm is far
  // beyond contact penetration and margins (< 1 mm) and the sensed pose's noise, so an end
  // resting on the table never passes, and far below what a tube held near the 12 cm height
  // target of 10.4 has (about 10 cm).
  double min_end_clearance = 0.02;  // m
  // Angle between the tube's axis and world x, either direction (the tube is symmetric end to
  // end: 11.3 spans all its initial orientations with 180 degrees). At 15 degrees the ends of
  // the 24 cm axis are 3 cm off the line across the palm, about one finger's width (22 mm
  // between the fingers), so the tube still lies across the palm in the grasp 11.4 asks for.
  double max_axis_angle = 0.2618;  // rad (15 degrees)
  // "Stationary": at rest in a grasp the tube moves only with the hand's small pressure
  // oscillations (mm/s). 5 cm/s moves it 2 mm in a 40 ms control step; a tube slipping out of
  // the fingers or rolling on the table exceeds it at once (1 m/s after a 5 cm fall).
  double max_speed = 0.05;          // m/s
  double max_angular_speed = 0.5;   // rad/s (about 30 degrees/s)
};

struct PickupVerdict {
  bool success = false;
  double end_clearance[2] = {0, 0};  // m, lowest point of each end above the table top
  double axis_angle = 0;             // rad in [0, pi/2]
  double speed = 0, angular_speed = 0;
  std::string failure;               // the first condition that failed ("" on success)
};

// Thesis 11.4: success iff the tube is stationary, both of its ends are above the height and
// its axis is aligned with world x. A lifted centre with one end on the table fails.
PickupVerdict pickupSuccess(const ObjectState& tube, const ObjectGeometry& geometry,
                            const PickupThresholds& thresholds = {});

// The tube's world axis (unit) in orientation q.
Eigen::Vector3d objectAxis(const Eigen::Quaterniond& q, const ObjectGeometry& geometry);

// The initial orientation of thesis 11.3: the tube lying on the table with its axis at `yaw`
// degrees from world +x towards +y, yaw in [0, 180) (the symmetric tube's distinct
// orientations). Throws std::invalid_argument outside that range or non-finite.
Eigen::Quaterniond tubeOrientationFromYaw(double yaw_degrees, const ObjectGeometry& geometry);

// The inverse on any orientation: the yaw (degrees in [0, 180)) of the horizontal projection of
// the tube's axis, as the nearest-neighbour library observes it (11.5). Throws
// std::invalid_argument when the axis is vertical (no yaw) or not finite.
double tubeYawDegrees(const Eigen::Quaterniond& q, const ObjectGeometry& geometry);

}  // namespace adroit
