// Commands (default queue): set_task, release, goal (topic and interactive marker), type
// sequence, dynamic_reconfigure. Each bad request is refused with the task's one-line reason.
#include <cmath>

#include "mpc_ros.h"

namespace adroit::mpc_node {

namespace {

// A SetTask goal left at its default (all zero) means "no goal given".
bool isGiven(const geometry_msgs::Pose& p) {
  const auto& q = p.orientation;
  return p.position.x != 0 || p.position.y != 0 || p.position.z != 0 || q.w != 0 || q.x != 0 || q.y != 0 || q.z != 0;
}

// A goal pose from a message: NaN / Inf refused; a zero quaternion means "any orientation"
// (identity), others are normalised.
bool toGoal(const geometry_msgs::Pose& p, Eigen::Vector3d* position, Eigen::Quaterniond* orientation,
            std::string* why) {
  const auto& q = p.orientation;
  const double v[] = {p.position.x, p.position.y, p.position.z, q.w, q.x, q.y, q.z};
  for (double x : v) {
    if (!std::isfinite(x)) {
      *why = "goal pose has NaN or Inf";
      return false;
    }
  }
  *position = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  const double norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  *orientation = norm < 1e-9 ? Eigen::Quaterniond::Identity() : Eigen::Quaterniond(q.w, q.x, q.y, q.z).normalized();
  return true;
}

bool applyGoalTo(adroit_mpc::Task& task, const geometry_msgs::Pose& pose, std::string* why) {
  Eigen::Vector3d position;
  Eigen::Quaterniond orientation;
  return toGoal(pose, &position, &orientation, why) && task.setGoal(position, orientation, why);
}

}  // namespace

std::unique_ptr<adroit_mpc::Task> MpcNode::buildTask(const std::string& name, std::string* why) const {
  const auto params = params_.tasks.find(name);
  if (params == params_.tasks.end()) {
    *why = "unknown task '" + name + "' (known: catch, relocate, type)";
    return nullptr;
  }
  try {
    std::unique_ptr<adroit_mpc::Task> task = adroit_mpc::makeTask(name, params->second);
    task->bind(model_.get(), synergy_dims_);
    return task;
  } catch (const std::exception& e) {
    *why = "task '" + name + "' on scene " + params_.scene + ": " + e.what();
    return nullptr;
  }
}

bool MpcNode::onSetTask(adroit_msgs::SetTask::Request& req, adroit_msgs::SetTask::Response& res) {
  std::string why;
  std::unique_ptr<adroit_mpc::Task> fresh;
  if (req.task != task_name_) {
    fresh = buildTask(req.task, &why);
    if (!fresh) {
      rejections_.count(kTaskName);
      res.success = false;
      res.message = why;
      ROS_ERROR("adroit_mpc: set_task refused: %s", why.c_str());
      return true;
    }
  }
  {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    adroit_mpc::Task& target = fresh ? *fresh : runner_->task();
    // Goal and keys are checked on the target before anything changes.
    if (isGiven(req.goal) && !applyGoalTo(target, req.goal, &why)) {
      rejections_.count(kGoal);
      res.success = false;
      res.message = "goal refused: " + why;
      return true;
    }
    if (!req.keys.empty() && !target.setSequence(req.keys, &why)) {
      rejections_.count(kTaskCommand);
      res.success = false;
      res.message = "keys refused: " + why;
      return true;
    }
    if (fresh) {
      runner_->replaceTask(std::move(fresh));  // the planner is re-initialised at its next plan
      task_name_ = req.task;
    }
    if (isGiven(req.goal)) goal_ = req.goal;
  }
  syncReconfigure();
  res.success = true;
  res.message = "task " + req.task + (isGiven(req.goal) ? ", goal set" : "") + (req.keys.empty() ? "" : ", keys set");
  ROS_INFO("adroit_mpc: %s", res.message.c_str());
  return true;
}

bool MpcNode::onRelease(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  std::string why;
  std::lock_guard<std::mutex> lock(runner_->taskMutex());
  res.success = runner_->task().release(&why);
  res.message = res.success ? "released" : why;
  if (!res.success) rejections_.count(kTaskCommand);
  return true;
}

bool MpcNode::applyGoal(const geometry_msgs::Pose& pose, const std::string& frame, std::string* why) {
  if (!frame.empty() && frame != "world") {
    *why = "goal frame '" + frame + "', expected 'world'";
  } else {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    if (applyGoalTo(runner_->task(), pose, why)) {
      goal_ = pose;
      return true;
    }
  }
  rejections_.count(kGoal);
  return false;
}

void MpcNode::onGoal(const geometry_msgs::PoseStamped::ConstPtr& msg) {
  std::string why;
  if (!applyGoal(msg->pose, msg->header.frame_id, &why)) {
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: goal rejected: %s", why.c_str());
    return;
  }
  if (goal_server_) {
    goal_server_->setPose("goal", msg->pose);
    goal_server_->applyChanges();
  }
}

void MpcNode::onType(const std_msgs::String::ConstPtr& msg) {
  std::string why;
  std::lock_guard<std::mutex> lock(runner_->taskMutex());
  if (!runner_->task().setSequence(msg->data, &why)) {
    rejections_.count(kTaskCommand);
    ROS_ERROR_THROTTLE(1.0, "adroit_mpc: key sequence rejected: %s", why.c_str());
    return;
  }
  ROS_INFO("adroit_mpc: typing '%s'", msg->data.c_str());  // a user (and a failed run's log) sees it arrive
}

void MpcNode::setupGoalMarker() {
  // Start where the task's goal is: its YAML goal position, else the scene's target site.
  geometry_msgs::Pose pose;
  pose.orientation.w = 1;
  const adroit_mpc::TaskParams& tp = params_.tasks.at(params_.task);
  bool known = false;
  for (const char* key : {"goal_position", "goal"}) {
    const auto v = tp.vectors.find(key);
    if (v != tp.vectors.end() && v->second.size() >= 3) {
      pose.position.x = v->second[0], pose.position.y = v->second[1], pose.position.z = v->second[2];
      known = true;
      break;
    }
  }
  if (!known) {
    const auto site = tables_->sites.find("S_target");
    if (!site) return;  // no goal pose in this scene (typing): no marker
    mjData* d = marker_data_.get();
    mj_resetData(model_.get(), d);
    mj_kinematics(model_.get(), d);
    pose.position.x = d->site_xpos[3 * *site], pose.position.y = d->site_xpos[3 * *site + 1];
    pose.position.z = d->site_xpos[3 * *site + 2];
  }
  goal_ = pose;

  goal_server_ = std::make_unique<interactive_markers::InteractiveMarkerServer>("/adroit/mpc/goal_marker");
  visualization_msgs::InteractiveMarker marker;
  marker.header.frame_id = "world";
  marker.name = "goal";
  marker.description = "MPC goal";
  marker.scale = 0.12;
  marker.pose = pose;
  visualization_msgs::InteractiveMarkerControl body;
  body.always_visible = true;
  body.interaction_mode = visualization_msgs::InteractiveMarkerControl::MOVE_ROTATE_3D;
  visualization_msgs::Marker sphere;
  sphere.type = visualization_msgs::Marker::SPHERE;
  sphere.scale.x = sphere.scale.y = sphere.scale.z = 0.04;
  sphere.color.r = 0.1, sphere.color.g = 0.9, sphere.color.b = 0.2, sphere.color.a = 0.6;
  body.markers.push_back(sphere);
  marker.controls.push_back(body);
  // Six axis handles: move and rotate about x, y, z.
  const double axes[3][4] = {{1, 1, 0, 0}, {1, 0, 1, 0}, {1, 0, 0, 1}};  // quaternions w x y z
  const char* names[3] = {"x", "z", "y"};
  for (int a = 0; a < 3; ++a) {
    visualization_msgs::InteractiveMarkerControl c;
    c.orientation.w = axes[a][0], c.orientation.x = axes[a][1], c.orientation.y = axes[a][2];
    c.orientation.z = axes[a][3];
    c.name = std::string("move_") + names[a];
    c.interaction_mode = visualization_msgs::InteractiveMarkerControl::MOVE_AXIS;
    marker.controls.push_back(c);
    c.name = std::string("rotate_") + names[a];
    c.interaction_mode = visualization_msgs::InteractiveMarkerControl::ROTATE_AXIS;
    marker.controls.push_back(c);
  }
  goal_server_->insert(marker, [this](const visualization_msgs::InteractiveMarkerFeedbackConstPtr& f) { onGoalMarker(f); });
  goal_server_->applyChanges();
}

void MpcNode::onGoalMarker(const visualization_msgs::InteractiveMarkerFeedbackConstPtr& feedback) {
  if (feedback->event_type != visualization_msgs::InteractiveMarkerFeedback::MOUSE_UP) return;
  std::string why;
  if (applyGoal(feedback->pose, feedback->header.frame_id, &why)) return;
  ROS_ERROR("adroit_mpc: goal rejected: %s", why.c_str());
  geometry_msgs::Pose back;
  {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    if (!goal_) return;
    back = *goal_;
  }
  goal_server_->setPose("goal", back);  // the marker returns to the goal in force
  goal_server_->applyChanges();
}

void MpcNode::onReconfigure(Config& config, uint32_t) {
  reconfigure_config_ = config;
  if (!reconfigure_ready_) return;  // the server's first call: syncReconfigure sets the values
  dynamic_reconfigure::Config values;
  config.__toMessage__(values);
  std::lock_guard<std::mutex> lock(runner_->taskMutex());
  adroit_mpc::Task& task = runner_->task();
  const std::vector<std::string> weights = task.weightNames();
  for (const auto& p : values.doubles) {
    if (p.name == "horizon") {
      if (std::abs(p.value - runner_->horizon()) > 1e-12) {
        if (p.value < 2 * params_.settings.dt) {
          ROS_ERROR("adroit_mpc: reconfigure: horizon %g s is shorter than two knots", p.value);
          continue;
        }
        runner_->setHorizon(p.value);  // the planner is re-initialised at its next plan
      }
      continue;
    }
    if (std::find(weights.begin(), weights.end(), p.name) == weights.end()) continue;  // another task's weight
    if (task.weight(p.name) == p.value) continue;
    try {
      task.setWeight(p.name, p.value);
      ROS_INFO("adroit_mpc: %s = %g", p.name.c_str(), p.value);
    } catch (const std::exception& e) {
      ROS_ERROR("adroit_mpc: reconfigure: %s", e.what());
    }
  }
}

void MpcNode::syncReconfigure() {
  if (!reconfigure_) return;
  boost::recursive_mutex::scoped_lock server_lock(reconfigure_mutex_);
  Config config = reconfigure_config_;
  dynamic_reconfigure::Config values;
  config.__toMessage__(values);
  {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    for (auto& p : values.doubles) {
      if (p.name == "horizon") {
        p.value = runner_->horizon();
        continue;
      }
      const std::vector<std::string> weights = runner_->task().weightNames();
      if (std::find(weights.begin(), weights.end(), p.name) != weights.end()) p.value = runner_->task().weight(p.name);
    }
  }
  config.__fromMessage__(values);
  reconfigure_config_ = config;
  reconfigure_->updateConfig(config);
}

}  // namespace adroit::mpc_node
