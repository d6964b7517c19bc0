#include <adroit_core/timing_stats.h>
#include <adroit_mpc/mpc_runner.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace adroit_mpc {

namespace {

bool allFinite(const double* v, std::size_t n) {
  return std::all_of(v, v + n, [](double x) { return std::isfinite(x); });
}

}  // namespace

MpcRunner::MpcRunner(const mjModel* model, std::unique_ptr<Planner> planner, std::unique_ptr<Task> task,
                     const PlannerSettings& settings, RunnerSettings runner_settings)
    : model_(model), run_(std::move(runner_settings)), planner_(std::move(planner)), task_(std::move(task)),
      settings_(settings) {
  if (!model_ || !planner_ || !task_) throw std::invalid_argument("MpcRunner: needs a model, a planner and a task");
  if (run_.timing == PlanTiming::kRealTime && !run_.clock)
    throw std::invalid_argument("MpcRunner: real-time timing needs the robot's clock");
  if (!(run_.feedback_scale >= 0 && run_.feedback_scale <= 1))
    throw std::invalid_argument("MpcRunner: feedback_scale must be in [0, 1]");
  planner_->initialize(model_, *task_, settings_);
  planning_horizon_ = settings_.horizon;
  observe_data_ = adroit::makeData(model_);
  plan_state_.qpos.assign(model_->qpos0, model_->qpos0 + model_->nq);
  plan_state_.qvel.assign(model_->nv, 0.0);
  plan_state_.act.assign(model_->na, 0.0);
  predictor_.initialize(model_);
  running_.bind(model_);
  exchange_.forEachPolicy([&](PlanPolicy& p) { p.bind(model_); });
}

// ---- task ------------------------------------------------------------------------------------

void MpcRunner::replaceTask(std::unique_ptr<Task> task) {
  if (!task) throw std::invalid_argument("MpcRunner::replaceTask: no task");
  task_ = std::move(task);
  task_replaced_ = true;
}

void MpcRunner::setHorizon(double seconds) { pending_horizon_ = seconds; }

double MpcRunner::horizon() const { return pending_horizon_ ? *pending_horizon_ : settings_.horizon; }

// ---- MPC side --------------------------------------------------------------------------------

void MpcRunner::initializePlanner() {
  std::lock_guard<std::mutex> lock(task_mutex_);
  planner_->initialize(model_, *task_, settings_);
}

PlanOutcome MpcRunner::planOnce(const PlannerState& state, bool world_waits) {
  const adroit::Stopwatch wall;
  copyPlannerState(model_, state, plan_state_);
  observe(state);
  PlanOutcome out;
  out.compensated = predictStart(world_waits);
  planner_->setState(plan_state_);
  out.report = planner_->optimize();
  out.published = !out.report.diverged && std::isfinite(out.report.cost_after);
  if (out.published) {
    planner_->policy(exchange_.back());
  } else if (!out.report.diverged) {
    planner_->reset();  // a non-finite cost the planner did not flag: back to the safe warm start too
  }
  // Every solve counts towards the latency (how long planning takes), a diverged one too.
  out.latency = measureLatency(state.time, wall.elapsed());
  latency_.record(out.latency);
  recordSolve(out);
  if (!out.published) return out;
  out.activation = run_.timing == PlanTiming::kEmulated && !world_waits ? state.time + out.latency : Exchange::kAtOnce;
  exchange_.publish(out.activation);
  published_.fetch_add(1, std::memory_order_relaxed);
  if (run_.latency_compensation) {  // a copy per plan (~0.5 MB for typing): only when used
    planner_->policy(running_);
    have_running_ = true;
  }
  return out;
}

void MpcRunner::observe(const PlannerState& state) {
  // The task's progress on the real system (key presses, phases) on the measured state.
  const mjModel* m = model_;
  mjData* d = observe_data_.get();
  d->time = state.time;
  mju_copy(d->qpos, state.qpos.data(), m->nq);
  mju_copy(d->qvel, state.qvel.data(), m->nv);
  if (m->na > 0) mju_copy(d->act, state.act.data(), m->na);
  mj_forward(m, d);
  std::vector<TaskEvent> events;
  {
    std::lock_guard<std::mutex> lock(task_mutex_);
    events = task_->observe(m, d, state.time);
    // Another task or horizon: re-initialise (allocates; only on such a change).
    if (task_replaced_ || pending_horizon_) {
      if (pending_horizon_) settings_.horizon = *pending_horizon_;
      pending_horizon_.reset();
      task_replaced_ = false;
      planner_->initialize(m, *task_, settings_);
      planning_horizon_ = settings_.horizon;
    }
    planner_->setTask(*task_);
  }
  if (!events.empty() && run_.on_events) run_.on_events(state.time, events);
}

double MpcRunner::predictStart(bool world_waits) {
  // Observed on the measured state; planned from where the running policy will have taken the
  // robot when this plan takes over. Not while the world waits for the plan (a warm-up; in
  // lockstep the measured latency is 0 anyway).
  if (!run_.latency_compensation || world_waits || !have_running_) return 0;
  return predictor_.predict(running_, run_.feedback_scale, latency_.expected(), plan_state_);
}

double MpcRunner::measureLatency(double state_time, double wall_seconds) const {
  if (run_.timing == PlanTiming::kRealTime) return run_.clock() - state_time;  // the robot's clock
  return run_.fixed_latency >= 0 ? run_.fixed_latency : wall_seconds;
}

void MpcRunner::recordSolve(const PlanOutcome& out) {
  solves_.fetch_add(1, std::memory_order_relaxed);
  if (!out.published) diverged_.fetch_add(1, std::memory_order_relaxed);
  const OptimizeReport& r = out.report;
  std::lock_guard<std::mutex> lock(stats_mutex_);
  RunnerWindow& w = window_;
  w.sum.rollout += r.rollout, w.sum.derivatives += r.derivatives, w.sum.cost += r.cost;
  w.sum.backward += r.backward, w.sum.line_search += r.line_search, w.sum.total += r.total;
  w.total_max = std::max(w.total_max, r.total);
  ++w.solves;
  w.latency_sum += out.latency;
  w.compensated_sum += out.compensated;
  last_report_ = r;
}

// ---- statistics ------------------------------------------------------------------------------

RunnerWindow MpcRunner::takeWindow() {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return std::exchange(window_, RunnerWindow());
}

OptimizeReport MpcRunner::lastReport() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return last_report_;
}

void MpcRunner::recordPolicyAge(double age) {
  std::unique_lock<std::mutex> lock(stats_mutex_, std::try_to_lock);  // the control side never waits
  if (!lock.owns_lock()) return;
  window_.age_sum += age;
  window_.age_max = std::max(window_.age_max, age);
  ++window_.age_samples;
}

// ---- control side ----------------------------------------------------------------------------

bool MpcRunner::usable(double t, double* age) const {
  if (!hasPolicy()) return false;
  const adroit::TvlgPolicy& p = policy().policy;
  const double a = t - p.t0;
  if (age) *age = a;
  return a <= p.knots() * p.dt + 1e-9;  // 1 ns for the rounding of times summed in steps
}

bool MpcRunner::action(double t, const double* qpos, const double* qvel, const double* act, double* ctrl) const {
  if (!usable(t)) return false;
  policy().action(t, qpos, qvel, act, ctrl, run_.feedback_scale);
  return allFinite(ctrl, static_cast<std::size_t>(model_->nu));
}

int MpcRunner::reference(double t, const double* qpos, const double* qvel, const double* act, int max_samples,
                         double* out) const {
  if (!usable(t)) return 0;
  const int samples = policy().reference(t, qpos, qvel, act, max_samples, out, run_.feedback_scale);
  return allFinite(out, static_cast<std::size_t>(samples) * model_->nu) ? samples : 0;
}

}  // namespace adroit_mpc
