// rviz markers of the simulated robot: tendon paths coloured by tension, a bar per
// cylinder for its gauge pressure, touch contacts and the free object.
#include <cmath>

#include "robot_driver.h"

namespace adroit::driver {

namespace {
// 0 -> blue, 1 -> red, through green.
std_msgs::ColorRGBA heat(double x, float alpha = 1.0f) {
  x = std::min(1.0, std::max(0.0, x));
  std_msgs::ColorRGBA c;
  c.r = static_cast<float>(std::min(1.0, 2.0 * x));
  c.g = static_cast<float>(1.0 - std::abs(2.0 * x - 1.0));
  c.b = static_cast<float>(std::min(1.0, 2.0 * (1.0 - x)));
  c.a = alpha;
  return c;
}

geometry_msgs::Point point(const double* p) {
  geometry_msgs::Point out;
  out.x = p[0], out.y = p[1], out.z = p[2];
  return out;
}

void setPose(visualization_msgs::Marker& marker, const double* pos, const double* xmat) {
  double quat[4];
  mju_mat2Quat(quat, xmat);
  marker.pose.position = point(pos);
  marker.pose.orientation.w = quat[0], marker.pose.orientation.x = quat[1];
  marker.pose.orientation.y = quat[2], marker.pose.orientation.z = quat[3];
}
}  // namespace

// Simulation thread, robot_mutex_ held: copies what the markers need into the preallocated
// snapshot (mj_copyData into an existing mjData allocates nothing). try_lock: when the
// publisher is still building from the last snapshot, this one is skipped.
void RobotDriver::takeMarkerSnapshot() {
  std::unique_lock<std::mutex> lock(marker_mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  mj_copyData(marker_data_.get(), robot_->model(), robot_->data());
  marker_truth_ = robot_->truth();
  marker_stamp_ = stamp();
  marker_fresh_ = true;
}

// Publisher thread: builds the markers from the snapshot and sends them.
void RobotDriver::publishMarkers() {
  std::lock_guard<std::mutex> lock(marker_mutex_);
  if (!marker_fresh_) return;
  marker_fresh_ = false;
  const mjModel* m = robot_->model();
  const mjData* d = marker_data_.get();
  const Signals& truth = marker_truth_;
  const auto& cylinders = robot_->cylinders();
  const double supply = robot_->supplyPressure(), atm = robot_->atmosphericPressure();
  marker_msg_.markers.clear();
  visualization_msgs::Marker base;
  base.header.frame_id = "world";
  base.header.stamp = marker_stamp_;
  base.action = visualization_msgs::Marker::ADD;
  base.pose.orientation.w = 1;
  base.frame_locked = false;

  for (std::size_t i = 0; i < cylinders.size(); ++i) {
    // Tendon path through its routing sites, coloured by tension / max tension.
    visualization_msgs::Marker line = base;
    line.ns = "tendon_tension";
    line.id = static_cast<int>(i);
    line.type = visualization_msgs::Marker::LINE_STRIP;
    line.scale.x = 0.0015;
    line.color = heat(truth.tension[i] / cylinders[i].max_tension);
    const int t = cylinders[i].tendon;
    for (int k = 0; k < d->ten_wrapnum[t]; ++k) {
      const int w = d->ten_wrapadr[t] + k;
      if (d->wrap_obj[w] == -2) continue;  // pulley marker, not a point
      line.points.push_back(point(d->wrap_xpos + 3 * w));
    }
    if (line.points.size() >= 2) marker_msg_.markers.push_back(line);

    // Pressure panel behind the table: one bar per cylinder, height = gauge pressure.
    visualization_msgs::Marker bar = base;
    bar.ns = "cylinder_pressure";
    bar.id = static_cast<int>(i);
    bar.type = visualization_msgs::Marker::CUBE;
    const double fraction = std::max(0.0, (truth.pressure[i] - atm) / (supply - atm));
    const double height = 0.002 + 0.25 * fraction;
    bar.scale.x = 0.012, bar.scale.y = 0.012, bar.scale.z = height;
    bar.pose.position.x = -0.42 + 0.0175 * static_cast<double>(i);
    bar.pose.position.y = 0.3;
    bar.pose.position.z = height / 2;
    bar.color = heat(fraction);
    marker_msg_.markers.push_back(bar);
  }
  visualization_msgs::Marker label = base;
  label.ns = "cylinder_pressure_label";
  label.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
  label.pose.position.x = 0, label.pose.position.y = 0.3, label.pose.position.z = 0.32;
  label.scale.z = 0.035;
  label.color = heat(0.5);
  label.color.r = label.color.g = label.color.b = 1.0f;
  label.text = "cylinder pressures (gauge, 0 .. supply)";
  marker_msg_.markers.push_back(label);

  // Touch zones in contact: a sphere at the sensor site, larger with more force.
  const auto& touch_names = robot_->touchNames();
  for (std::size_t k = 0; k < touch_names.size(); ++k) {
    const int sensor = mj_name2id(m, mjOBJ_SENSOR, touch_names[k].c_str());
    const int site = m->sensor_objid[sensor];
    visualization_msgs::Marker dot = base;
    dot.ns = "touch";
    dot.id = static_cast<int>(k);
    dot.type = visualization_msgs::Marker::SPHERE;
    const double force = truth.touch[k];
    if (force > 0.01) {
      const double size = 0.008 + 0.004 * std::min(5.0, force);
      dot.scale.x = dot.scale.y = dot.scale.z = size;
      dot.pose.position = point(d->site_xpos + 3 * site);
      dot.color = heat(std::min(1.0, force / 5.0), 0.9f);
    } else {
      dot.action = visualization_msgs::Marker::DELETE;  // not a transparent sphere: rviz warns on alpha 0
    }
    marker_msg_.markers.push_back(dot);
  }

  // The free object (not in the URDF): its geoms.
  if (robot_->hasObject()) {
    const int body = robot_->objectBody();
    for (int g = m->body_geomadr[body]; g < m->body_geomadr[body] + m->body_geomnum[body]; ++g) {
      visualization_msgs::Marker shape = base;
      shape.ns = "object";
      shape.id = g;
      const double* size = m->geom_size + 3 * g;
      switch (m->geom_type[g]) {
        case mjGEOM_SPHERE:
          shape.type = visualization_msgs::Marker::SPHERE;
          shape.scale.x = shape.scale.y = shape.scale.z = 2 * size[0];
          break;
        case mjGEOM_CAPSULE:  // drawn as its cylinder
        case mjGEOM_CYLINDER:
          shape.type = visualization_msgs::Marker::CYLINDER;
          shape.scale.x = shape.scale.y = 2 * size[0];
          shape.scale.z = 2 * size[1] + (m->geom_type[g] == mjGEOM_CAPSULE ? 2 * size[0] : 0);
          break;
        case mjGEOM_BOX:
          shape.type = visualization_msgs::Marker::CUBE;
          shape.scale.x = 2 * size[0], shape.scale.y = 2 * size[1], shape.scale.z = 2 * size[2];
          break;
        default: continue;
      }
      setPose(shape, d->geom_xpos + 3 * g, d->geom_xmat + 9 * g);
      const float* rgba = m->geom_rgba + 4 * g;
      shape.color.r = rgba[0], shape.color.g = rgba[1], shape.color.b = rgba[2], shape.color.a = rgba[3];
      marker_msg_.markers.push_back(shape);
    }
  }
  marker_pub_.publish(marker_msg_);
}

}  // namespace adroit::driver
