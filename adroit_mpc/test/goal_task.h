// Test helpers shared by the planner and runner tests: small inline MuJoCo models (a point
// mass on two rails, a pendulum) and a quadratic goal task on their scalar joints.
#pragma once

#include <adroit_mpc/task.h>

#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit_mpc::test {

inline const char* kPointMass = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01" gravity="0 0 0"/>
  <worldbody>
    <body name="mass">
      <joint name="x" type="slide" axis="1 0 0" damping="0.2"/>
      <joint name="y" type="slide" axis="0 1 0" damping="0.2"/>
      <geom type="sphere" size="0.05" mass="1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="x" ctrlrange="-1 1"/>
    <motor joint="y" ctrlrange="-1 1"/>
  </actuator>
</mujoco>)";

inline const char* kPendulum = R"(
<mujoco><compiler autolimits="true"/>
  <option timestep="0.01"/>
  <worldbody>
    <body name="pole">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.05"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02" mass="0" contype="0" conaffinity="0"/>
      <geom type="sphere" pos="0 0 -0.5" size="0.05" mass="1" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="hinge" ctrlrange="-4 4"/>
  </actuator>
</mujoco>)";

// w_p |q - goal|^2 + w_v |v|^2 + w_u |u|^2 on hinge / slide coordinates, terminal x10 (state
// terms), with exact Gauss-Newton derivatives (scalar joints only: dq = dqpos).
// poison: every cost NaN (a diverging solve). report: observe() returns the label as an event.
class GoalTask : public Task {
 public:
  GoalTask(std::vector<double> goal, double w_p, double w_v, double w_u, std::string label = "goal")
      : goal_(std::move(goal)), w_p_(w_p), w_v_(w_v), w_u_(w_u), label_(std::move(label)) {}
  std::string name() const override { return "goal"; }
  std::unique_ptr<Task> clone() const override { return std::make_unique<GoalTask>(*this); }
  void copyParametersFrom(const Task& other) override {
    const auto* o = dynamic_cast<const GoalTask*>(&other);
    if (!o) throw std::invalid_argument("not a GoalTask");
    goal_ = o->goal_;
    poison = o->poison;
  }
  void bind(const mjModel* m, int) override { nv_ = m->nv; }
  std::unique_ptr<TaskScratch> makeScratch(const mjModel*) const override { return std::make_unique<TaskScratch>(); }
  double runningCost(const mjModel*, const mjData* d, const Eigen::VectorXd& u, double, TaskScratch&) const override {
    return stateCost(d, 1.0, nullptr) + w_u_ * u.squaredNorm();
  }
  double terminalCost(const mjModel*, const mjData* d, double, TaskScratch&) const override {
    return stateCost(d, 10.0, nullptr);
  }
  double runningCostDerivatives(const mjModel*, const mjData* d, const Eigen::VectorXd& u, double, TaskScratch&,
                                CostDerivatives& out) const override {
    out.setZero();
    out.lu = 2 * w_u_ * u;
    out.luu.diagonal().setConstant(2 * w_u_);
    return stateCost(d, 1.0, &out) + w_u_ * u.squaredNorm();
  }
  double terminalCostDerivatives(const mjModel*, const mjData* d, double, TaskScratch&,
                                 CostDerivatives& out) const override {
    out.setZero();
    return stateCost(d, 10.0, &out);
  }
  std::vector<TaskEvent> observe(const mjModel*, const mjData*, double) override {
    if (!report) return {};
    return {{"label", label_}};
  }
  std::vector<std::string> weightNames() const override { return {}; }
  double weight(const std::string&) const override { return 0; }
  void setWeight(const std::string&, double) override {}
  double error(const mjModel*, const mjData* d) const override {
    double e = 0;
    for (std::size_t i = 0; i < goal_.size(); ++i) e += (d->qpos[i] - goal_[i]) * (d->qpos[i] - goal_[i]);
    return std::sqrt(e);
  }
  bool poison = false, report = false;

 private:
  double stateCost(const mjData* d, double scale, CostDerivatives* out) const {
    if (poison) return std::numeric_limits<double>::quiet_NaN();
    double c = 0;
    for (std::size_t i = 0; i < goal_.size(); ++i) {
      const double e = d->qpos[i] - goal_[i];
      c += scale * w_p_ * e * e;
      if (out) {
        out->lx[i] += 2 * scale * w_p_ * e;
        out->lxx(i, i) += 2 * scale * w_p_;
      }
    }
    for (int i = 0; i < nv_; ++i) {
      c += scale * w_v_ * d->qvel[i] * d->qvel[i];
      if (out) {
        out->lx[nv_ + i] += 2 * scale * w_v_ * d->qvel[i];
        out->lxx(nv_ + i, nv_ + i) += 2 * scale * w_v_;
      }
    }
    return c;
  }
  std::vector<double> goal_;
  double w_p_, w_v_, w_u_;
  std::string label_;
  int nv_ = 0;
};

}  // namespace adroit_mpc::test
