// The planner lifecycle shared by iLQG, predictive sampling and CEM (DESIGN.md §2; structure after
// MuJoCo MPC): initialise (allocate everything once), set state, optimise (warm-started by
// shifting the previous plan), policy / action at any time, best trajectory.
#pragma once

#include <adroit_core/tvlg_policy.h>
#include <adroit_mpc/synergies.h>
#include <adroit_mpc/task.h>

#include <mujoco/mujoco.h>

#include <adroit_core/mujoco_model.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace adroit_mpc {

struct PlannerState {
  double time = 0;
  std::vector<double> qpos, qvel, act;  // planning model sizes nq, nv, na
};

struct PlannerSettings {
  double horizon = 0.3;      // s
  double dt = 0.01;          // s, knot spacing = the planning model's timestep
  int threads = 0;           // workers (0 = hardware cores)
  int iterations = 1;        // per optimize()
  bool synergies = true;     // five synergy controls after the actuators (thesis 6.4.5)
  // iLQG
  double fd_epsilon = 1e-6;
  bool fd_centered = false;
  int derivative_skip = 3;   // finite-difference derivatives at every k-th knot, held between
  // FD nudges solved from the nominal's solution (FdSettings::warmstart_from_nominal): the
  // same derivatives to the solver's precision at 0.7x the derivative time (README).
  bool fd_warmstart = true;
  // B through the generalised forces of the linear actuators (FdSettings::force_space_controls):
  // one nudge per actuated DOF instead of one per control, the same B to FD precision.
  bool fd_force_space = true;
  // Reuse of derivatives across optimise() calls (FdSettings::max_age, reuse_tolerance): a
  // knot takes a linearisation of an earlier call at about its time, computed at most
  // derivative_max_age seconds of plan time ago, unless the trajectory there moved more than
  // derivative_reuse_tolerance (m or rad; velocities as dt |dv|) from the state it was taken at.
  // 0: every call computes every knot of the skip pattern (the path before).
  double derivative_max_age = 0.1;
  double derivative_reuse_tolerance = 0.5;
  double mu_initial = 1e-6;  // LM regularisation (small: MPC must take large steps, thesis 6.4)
  double feedback_scale = 1.0;
  // sampling planners (predictive sampling, cross entropy)
  int samples = 16;          // candidates per iteration, the current plan's spline included
  int spline_points = 5;     // control knots of a sampled plan (zero-order hold between)
  std::uint64_t seed = 0x5eed;  // candidate i draws its noise from the stream seed + 7919 i
  double noise_scale = 0.1;  // predictive sampling: fraction of each control's range
  // cross entropy: the elites are the cem_elites cheapest candidates; the sampling std per
  // spline value (fraction of each control's range) starts at cem_std_initial and follows
  // the elites' spread within [cem_std_min, cem_std_initial].
  int cem_elites = 4;
  double cem_std_initial = 0.2;
  double cem_std_min = 0.05;  // the floor keeps the MPC exploring as the state moves on
  // The cost of stepping the tendon tensions from one knot to the next (every planner, in its
  // rollouts): 0.5 w sum_a ((ctrl_a(t) - ctrl_a(t - 1)) / range_a)^2 per knot, the first knot
  // against what the previous plan applies at its start. A cylinder follows a tension only as
  // fast as its chamber fills (time constant ~20 ms, thesis 8.1), so a plan that steps a tendon
  // across its range in one knot cannot be tracked. 0: no such cost. At 1 a full-range step
  // costs 0.5 per tendon (README "Plans the cylinders can follow").
  double tension_step_weight = 1.0;
};

// Time split of one optimize() (thesis table 6.2), seconds.
struct OptimizeReport {
  double rollout = 0, derivatives = 0, cost = 0, backward = 0, line_search = 0, total = 0;
  double cost_before = 0, cost_after = 0;
  double mu = 0, alpha = 0;
  int iterations = 0;
  int derivative_knots = 0;  // knots whose derivatives were evaluated (the rest held or reused)
  bool improved = false;
  bool diverged = false;  // non-finite cost: the plan was reset to the safe warm start
};

// The plan as the control side uses it: a TVLG policy on the model's actuator controls
// (synergies already mapped), evaluated at any time with feedback on the measured state.
class PlanPolicy {
 public:
  void bind(const mjModel* model);  // allocates once
  // ctrl (model nu) at time t from the measured state; allocates nothing.
  void action(double t, const double* qpos, const double* qvel, const double* act, double* ctrl,
              double feedback_scale = 1.0) const;
  // The policy as a reference for actuators that track one (the pools in pneumatic mode):
  // sample j, at t + j dt (dt = the policy's knot spacing), is u(t + j dt) + K(t + j dt) dx,
  // dx = the state measured now minus the plan's: the feedback on today's deviation, carried
  // along the rest of the plan. Sample 0 is what action() gives. Writes at most max_samples
  // rows of nu (row-major) up to the policy's last knot; returns how many. Allocates nothing.
  int reference(double t, const double* qpos, const double* qvel, const double* act, int max_samples, double* out,
                double feedback_scale = 1.0) const;
  adroit::TvlgPolicy policy;  // x = [qpos qvel act], dx = [dq dv act], u = actuator controls
  double cost = 0;

 private:
  void deviation(double t, const double* qpos, const double* qvel, const double* act) const;  // -> dx_
  void clampInto(double* ctrl) const;  // u_ within the actuators' ranges

  const mjModel* model_ = nullptr;
  mutable Eigen::VectorXd x_nominal_, dx_, u_;
};

// Best trajectory of the last optimise (for markers, the pools' force reference and tests).
struct Trajectory {
  std::vector<double> times;                // knots
  std::vector<Eigen::VectorXd> states;      // [qpos qvel act] per knot (+ final)
  std::vector<Eigen::VectorXd> ctrl;        // actuator controls per knot (synergies mapped)
  std::vector<Eigen::VectorXd> controls;    // planner controls [actuators | synergies] per knot
  double cost = 0;
};

class Planner {
 public:
  virtual ~Planner() = default;
  virtual std::string name() const = 0;
  // `model` is the planning model; it must outlive the planner. Allocates everything.
  virtual void initialize(const mjModel* model, const Task& task, const PlannerSettings& settings) = 0;
  virtual void setState(const PlannerState& state) = 0;  // copies (no allocation)
  virtual void setTask(const Task& task) = 0;            // copyParametersFrom (no allocation)
  virtual OptimizeReport optimize() = 0;
  // Copies the best policy into `out` (allocates only the first time).
  virtual void policy(PlanPolicy& out) const = 0;
  virtual const Trajectory& bestTrajectory() const = 0;
  // Back to the safe warm start (controls at the minimum tension / rest).
  virtual void reset() = 0;
};

// "ilqg", "sampling" or "cem"; throws std::invalid_argument naming the known planners.
std::unique_ptr<Planner> makePlanner(const std::string& name);

// ---- Building blocks shared by the planners -------------------------------------------

// Checks settings against the model (dt == timestep, horizon >= 2 knots, ...); throws
// std::invalid_argument with one line naming the bad setting. Returns the number of knots T.
int validatePlannerSettings(const mjModel* model, const PlannerSettings& settings);

// Copies `in` into `out` (sized for the model at initialisation; no allocation). Throws
// std::invalid_argument naming the sizes when they do not match the model.
void copyPlannerState(const mjModel* model, const PlannerState& in, PlannerState& out);

struct KnotTrajectory;

// The planner's control space [actuators | synergies], its box (ctrlrange; [-1, 1] for the
// synergies), the map to model controls, and the cost of stepping the model controls between
// knots (PlannerSettings::tension_step_weight).
class ControlSpace {
 public:
  // Allocates; throws (unlimited ctrl, negative or non-finite step weight).
  void initialize(const mjModel* model, bool synergies, double step_weight = 0);
  int size() const { return static_cast<int>(lower_.size()); }
  int actuators() const { return nu_; }
  bool hasSynergies() const { return has_synergies_; }
  const Synergies& synergies() const { return synergies_; }
  const Eigen::VectorXd& lower() const { return lower_; }
  const Eigen::VectorXd& upper() const { return upper_; }
  void clamp(Eigen::VectorXd& u) const { u = u.cwiseMax(lower_).cwiseMin(upper_); }
  // Model controls of planner controls u (clamped to ctrlrange); no allocation.
  void toCtrl(const Eigen::VectorXd& u, double* ctrl) const;
  // B of the planner controls by the chain rule: B_act diag(not clamped) [I | S].
  void chainRule(const Eigen::MatrixXd& B_act, const Eigen::VectorXd& u, Eigen::MatrixXd& B) const;
  // Feedback gains on the model controls from gains on the planner controls (same chain
  // rule as B). Both chain-rule methods use member scratch: call them from one thread.
  void chainGains(const Eigen::VectorXd& u, const Eigen::MatrixXd& K, Eigen::MatrixXd& K_ctrl) const;
  // The safe warm start: every actuator at its minimum tension, synergies at rest.
  void safeControls(Eigen::VectorXd& u) const;

  // The model controls in effect when the next plan starts: `plan`'s at `time` (linear between
  // its knots, its ends held). The first knot's step is costed against them; forgetApplied():
  // no plan runs, the first knot is free. Call between rollouts (not thread-safe); no allocation.
  void holdApplied(const KnotTrajectory& plan, double time);
  void forgetApplied() { has_applied_ = false; }
  double stepWeight() const { return step_weight_; }
  // The step cost of knot t of `plan` (its ctrl filled up to knot t).
  double stepCost(const KnotTrajectory& plan, int t) const;
  // Its gradient and Gauss-Newton Hessian in the planner controls of knot t, the neighbouring
  // knots held at `plan`'s controls (knot t's cost and knot t + 1's), added to lu and luu.
  // Uses member scratch: call from one thread. No allocation.
  void addStepDerivatives(const KnotTrajectory& plan, int t, Eigen::VectorXd& lu, Eigen::MatrixXd& luu) const;

 private:
  int nu_ = 0;
  bool has_synergies_ = false;
  Synergies synergies_;
  Eigen::VectorXd lower_, upper_;
  double step_weight_ = 0;
  Eigen::VectorXd step_scale_;  // w / range^2 per actuator
  Eigen::VectorXd applied_;
  bool has_applied_ = false;
  mutable Eigen::VectorXd ctrl_, mask_, step_gradient_, step_curvature_;
  mutable Eigen::MatrixXd scaled_map_;  // diag(curvature) S
};

// A rolled-out plan: T knots of controls and T + 1 states, with the per-knot costs.
struct KnotTrajectory {
  void resize(const mjModel* model, int knots, int controls);  // allocates
  std::vector<double> times;               // T + 1
  std::vector<Eigen::VectorXd> states;     // T + 1, [qpos qvel act]
  std::vector<Eigen::VectorXd> controls;   // T, planner controls
  std::vector<Eigen::VectorXd> ctrl;       // T, model controls
  std::vector<double> costs;               // T + 1 (last = terminal)
  double total = 0;
};

// Per-worker simulation memory of a rollout (one mjData, the task's scratch).
struct RolloutWorkspace {
  void initialize(const mjModel* model, const Task& task);  // allocates
  adroit::DataPtr data;
  std::unique_ptr<TaskScratch> scratch;
  Eigen::VectorXd dx;  // tangent-space state difference (2 nv + na)
};

// Simulates from `initial` (state at `t0`): at knot t, control(t, data, u) writes the planner
// controls (data holds the knot's state), then ctrl = clamp, mj_forward, the running cost,
// the integrator; the terminal cost at the end. Non-finite states stop the rollout with an
// infinite total. Allocates nothing.
template <typename ControlLaw>
void rollout(const mjModel* m, const Task& task, const ControlSpace& space, const Eigen::VectorXd& initial,
             double t0, ControlLaw&& control, RolloutWorkspace& w, KnotTrajectory& out);
// The same with the knot cost supplied: knot_cost(t, d, u) after mj_forward at knot t
// (t == T: terminal, u unused), e.g. to take the cost derivatives while the data is fresh.
template <typename ControlLaw, typename KnotCost>
void rollout(const mjModel* m, const ControlSpace& space, const Eigen::VectorXd& initial, double t0,
             ControlLaw&& control, KnotCost&& knot_cost, RolloutWorkspace& w, KnotTrajectory& out);

// Publishes a plan: into a PlanPolicy (gains on the actuator controls, nullptr = no feedback)
// and into a Trajectory. Both allocate only when the sizes change (first call).
void writePolicy(const mjModel* model, const KnotTrajectory& plan, const std::vector<Eigen::MatrixXd>* gains,
                 PlanPolicy& out);
void writeTrajectory(const KnotTrajectory& plan, Trajectory& out);

// Reads the state of `d` as [qpos qvel act].
void readState(const mjModel* m, const mjData* d, Eigen::VectorXd& state);
// dx = state (in d) minus nominal, in the tangent space: mj_differentiatePos for qpos
// (quaternions of free and ball joints), plain difference for qvel and act.
void stateDifference(const mjModel* m, const double* nominal, const double* qpos, const double* qvel,
                     const double* act, Eigen::VectorXd& dx);
// The integrator's update after mj_forward (what mj_step does after it).
void integrateAfterForward(const mjModel* m, mjData* d);

template <typename ControlLaw, typename KnotCost>
void rollout(const mjModel* m, const ControlSpace& space, const Eigen::VectorXd& initial, double t0,
             ControlLaw&& control, KnotCost&& knot_cost, RolloutWorkspace& w, KnotTrajectory& out) {
  mjData* d = w.data.get();
  const int T = static_cast<int>(out.controls.size());
  mju_copy(d->qpos, initial.data(), m->nq);
  mju_copy(d->qvel, initial.data() + m->nq, m->nv);
  if (m->na) mju_copy(d->act, initial.data() + m->nq + m->nv, m->na);
  // The constraint solver starts cold: a worker's leftover warm start from another rollout
  // would make results depend on which worker ran what.
  mju_zero(d->qacc_warmstart, m->nv);
  out.total = 0;
  for (int t = 0; t <= T; ++t) {
    out.times[t] = t0 + t * m->opt.timestep;
    d->time = out.times[t];
    readState(m, d, out.states[t]);
    if (!out.states[t].allFinite()) {
      out.total = std::numeric_limits<double>::infinity();
      for (int k = t; k <= T; ++k) out.costs[k] = out.total;
      return;
    }
    if (t == T) break;
    control(t, static_cast<const mjData*>(d), out.controls[t]);
    space.clamp(out.controls[t]);
    space.toCtrl(out.controls[t], out.ctrl[t].data());
    mju_copy(d->ctrl, out.ctrl[t].data(), m->nu);
    mj_forward(m, d);
    out.costs[t] = knot_cost(t, d, out.controls[t]) + space.stepCost(out, t);
    out.total += out.costs[t];
    integrateAfterForward(m, d);
  }
  mj_forward(m, d);
  out.costs[T] = knot_cost(T, d, out.controls[T - 1]);
  out.total += out.costs[T];
  if (!std::isfinite(out.total)) out.total = std::numeric_limits<double>::infinity();
}

template <typename ControlLaw>
void rollout(const mjModel* m, const Task& task, const ControlSpace& space, const Eigen::VectorXd& initial,
             double t0, ControlLaw&& control, RolloutWorkspace& w, KnotTrajectory& out) {
  const int T = static_cast<int>(out.controls.size());
  rollout(
      m, space, initial, t0, std::forward<ControlLaw>(control),
      [&](int t, const mjData* d, const Eigen::VectorXd& u) {
        return t < T ? task.runningCost(m, d, u, out.times[t], *w.scratch)
                     : task.terminalCost(m, d, out.times[t], *w.scratch);
      },
      w, out);
}

}  // namespace adroit_mpc
