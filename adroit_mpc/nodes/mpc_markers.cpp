// rviz markers of the plan (default queue, a few Hz, only while someone listens) and the
// node's diagnostics (1 Hz: iteration time split as thesis table 6.2, cost, mu, policy age).
#include <diagnostic_msgs/DiagnosticArray.h>

#include <algorithm>
#include <cmath>

#include "adroit_mpc/synergies.h"
#include "mpc_ros.h"

namespace adroit::mpc_node {

namespace {

visualization_msgs::Marker makeMarker(const std::string& ns, int id, int type, const ros::Time& stamp) {
  visualization_msgs::Marker m;
  m.header.frame_id = "world";
  m.header.stamp = stamp;
  m.ns = ns;
  m.id = id;
  m.type = type;
  m.action = visualization_msgs::Marker::ADD;
  m.pose.orientation.w = 1;
  m.lifetime = ros::Duration(1.0);
  return m;
}

geometry_msgs::Point point(const double* p) {
  geometry_msgs::Point q;
  q.x = p[0], q.y = p[1], q.z = p[2];
  return q;
}

// Fingertip colours FF MF RF LF TH.
const float kTipColours[5][3] = {{0.9f, 0.2f, 0.2f}, {0.9f, 0.6f, 0.1f}, {0.3f, 0.8f, 0.2f}, {0.2f, 0.5f, 0.9f},
                                 {0.7f, 0.3f, 0.9f}};

}  // namespace

void MpcNode::takeMarkerSnapshot() {
  std::unique_lock<std::mutex> lock(marker_mutex_, std::try_to_lock);  // the planner never waits
  if (!lock.owns_lock()) return;
  marker_plan_ = runner_->planner().bestTrajectory();  // same sizes after the first copy: no allocation
  marker_fresh_ = true;
}

void MpcNode::onMarkerTimer(const ros::WallTimerEvent&) {
  markers_wanted_ = marker_pub_.getNumSubscribers() > 0;
  if (!markers_wanted_) return;
  const mjModel* m = model_.get();
  mjData* d = marker_data_.get();
  const ros::Time stamp = ros::Time::now();
  marker_msg_.markers.clear();
  {
    std::lock_guard<std::mutex> lock(marker_mutex_);
    if (!marker_fresh_) return;
    marker_fresh_ = false;
    const adroit_mpc::Trajectory& plan = marker_plan_;
    std::vector<visualization_msgs::Marker> tips;
    for (std::size_t i = 0; i < tip_sites_.size(); ++i) {
      auto line = makeMarker("fingertip_plan", static_cast<int>(i), visualization_msgs::Marker::LINE_STRIP, stamp);
      line.scale.x = 0.003;
      const float* c = kTipColours[std::min<std::size_t>(i, 4)];
      line.color.r = c[0], line.color.g = c[1], line.color.b = c[2], line.color.a = 0.9f;
      tips.push_back(line);
    }
    auto object = makeMarker("object_plan", 0, visualization_msgs::Marker::LINE_STRIP, stamp);
    object.scale.x = 0.004;
    object.color.r = 1, object.color.g = 1, object.color.b = 1, object.color.a = 0.8f;
    for (const Eigen::VectorXd& x : plan.states) {
      if (x.size() < m->nq) continue;
      mju_copy(d->qpos, x.data(), m->nq);
      mj_kinematics(m, d);
      for (std::size_t i = 0; i < tip_sites_.size(); ++i) tips[i].points.push_back(point(d->site_xpos + 3 * tip_sites_[i]));
      if (object_body_ >= 0) object.points.push_back(point(d->xpos + 3 * object_body_));
    }
    for (auto& t : tips) marker_msg_.markers.push_back(t);
    if (object_body_ >= 0) marker_msg_.markers.push_back(object);

    // Synergy activations at the plan's first knot, as bars beside the hand (thesis 6.4.5).
    if (!plan.controls.empty() && synergy_dims_ > 0 && plan.controls.front().size() >= m->nu + synergy_dims_) {
      const Eigen::VectorXd& u = plan.controls.front();
      for (int s = 0; s < synergy_dims_; ++s) {
        const double a = u[m->nu + s];
        auto bar = makeMarker("synergies", s, visualization_msgs::Marker::CUBE, stamp);
        const double height = std::max(0.002, 0.1 * std::min(1.0, std::abs(a)));
        bar.pose.position.x = 0.35;
        bar.pose.position.y = -0.1 + 0.04 * s;
        bar.pose.position.z = (a >= 0 ? 1 : -1) * height / 2;
        bar.scale.x = bar.scale.y = 0.025;
        bar.scale.z = height;
        bar.color.r = a >= 0 ? 0.2f : 0.9f, bar.color.g = 0.5f, bar.color.b = a >= 0 ? 0.9f : 0.2f;
        bar.color.a = 0.9f;
        marker_msg_.markers.push_back(bar);
        auto label = makeMarker("synergy_labels", s, visualization_msgs::Marker::TEXT_VIEW_FACING, stamp);
        label.pose.position = bar.pose.position;
        label.pose.position.z = -0.02;
        label.scale.z = 0.015;
        label.color.r = label.color.g = label.color.b = label.color.a = 1;
        char text[64];
        std::snprintf(text, sizeof text, "%s %.2f", adroit_mpc::Synergies::names()[s].c_str(), a);
        label.text = text;
        marker_msg_.markers.push_back(label);
      }
    }
  }
  std::optional<geometry_msgs::Pose> goal;
  {
    std::lock_guard<std::mutex> lock(runner_->taskMutex());
    goal = goal_;
  }
  if (goal) {
    auto sphere = makeMarker("goal", 0, visualization_msgs::Marker::SPHERE, stamp);
    sphere.pose = *goal;
    sphere.scale.x = sphere.scale.y = sphere.scale.z = 0.03;
    sphere.color.g = 1, sphere.color.a = 0.7f;
    marker_msg_.markers.push_back(sphere);
    auto arrow = makeMarker("goal", 1, visualization_msgs::Marker::ARROW, stamp);
    arrow.pose = *goal;  // the goal's x axis
    arrow.scale.x = 0.06, arrow.scale.y = arrow.scale.z = 0.006;
    arrow.color.g = 1, arrow.color.a = 0.9f;
    marker_msg_.markers.push_back(arrow);
  }
  marker_pub_.publish(marker_msg_);
}

void MpcNode::onDiagnostics(const ros::WallTimerEvent& event) {
  const adroit_mpc::RunnerWindow w = runner_->takeWindow();
  const adroit_mpc::OptimizeReport last = runner_->lastReport();
  const double window = std::max(1e-9, (event.current_real - event.last_real).toSec());
  static std::uint64_t last_diverged = 0, last_rejected = 0;  // one node per process
  const std::uint64_t diverged = runner_->diverged(), rejected = rejections_.total();
  const double state_age = stateAgeWall();

  rosutil::StatusBuilder s("adroit_mpc", "behaviour MPC");
  if (diverged > last_diverged)
    s.raise(diagnostic_msgs::DiagnosticStatus::WARN,
            std::to_string(diverged - last_diverged) + " diverged solve(s) (not published, plan reset)");
  if (!params_.lockstep && state_age > params_.state_timeout)
    s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "no state: not publishing (driver watchdog in charge)");
  if (rejected > last_rejected) s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "rejected input");
  s.raise(diagnostic_msgs::DiagnosticStatus::OK, "planning " + task_name_);
  last_diverged = diverged;
  last_rejected = rejected;

  const double n = std::max(1, w.solves);
  s.add("task", task_name_);
  s.add("planner", params_.planner);
  s.add("mode", params_.force_mode ? "force" : "pneumatic");
  s.add("lockstep", params_.lockstep);
  s.add("horizon_s", runner_->planningHorizon());
  s.add("solves", runner_->solves());
  s.add("solve_rate_hz", w.solves / window);
  // Thesis table 6.2: mean time of each part of an optimise in this window.
  s.add("time_rollout_ms", 1e3 * w.sum.rollout / n);
  s.add("time_derivatives_ms", 1e3 * w.sum.derivatives / n);
  s.add("time_cost_ms", 1e3 * w.sum.cost / n);
  s.add("time_backward_pass_ms", 1e3 * w.sum.backward / n);
  s.add("time_line_search_ms", 1e3 * w.sum.line_search / n);
  s.add("time_total_ms", 1e3 * w.sum.total / n);
  s.add("time_total_max_ms", 1e3 * w.total_max);
  s.add("cost", last.cost_after);
  s.add("cost_before", last.cost_before);
  s.add("mu", last.mu);
  s.add("alpha", last.alpha);
  s.add("policy_age_mean_ms", w.age_samples > 0 ? 1e3 * w.age_sum / w.age_samples : 0.0);
  s.add("policy_age_max_ms", 1e3 * w.age_max);
  // From a state's stamp to its plan's publication (robot clock), and how far ahead of the
  // state the plans started (latency compensation; 0 when off).
  s.add("plan_latency_ms", 1e3 * w.latency_sum / n);
  s.add("latency_compensated_ms", 1e3 * w.compensated_sum / n);
  s.add("diverged", diverged);
  s.add("policies_published", runner_->published());
  s.add("commands_sent", commands_sent_.load());
  s.add("references_sent", references_sent_.load());
  s.add("state_age_ms", std::isfinite(state_age) ? 1e3 * state_age : -1.0);
  s.add("joint_states_accepted", joint_states_accepted_.load());
  s.add("odom_accepted", odom_accepted_.load());
  s.add("stale_stops", stale_stops_.load());
  s.add("lockstep_failures", lockstep_failures_.load());
  rejections_.addTo(s, "rejected");
  s.publish(diag_pub_);
}

}  // namespace adroit::mpc_node
