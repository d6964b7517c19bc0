// The closed-loop MPC, once, for every user: the node's planner and control threads,
// mpc_success's emulated real time, and any trainer or expert that needs an MPC in the loop.
// ROS-free. The split follows OCS2's MPC / MRT idea (structure only):
//
//  * MPC side (one thread): planOnce(state) observes the task on the measured state, hands the
//    task to the planner, optionally plans from the state the running policy is predicted to
//    reach when this plan takes over (latency_compensation.h), optimises, and publishes the
//    policy unless the solve diverged. Statistics for diagnostics.
//  * Control side (one thread, may be the same one): updatePolicy(t) takes the newest
//    published policy whose activation time has come (PolicyExchange), action() / reference()
//    evaluate it. It never waits for the MPC side and allocates nothing; a policy older than
//    its horizon is not acted on (it says nothing about now, e.g. after a stall).
//  * The task: changed by any thread under taskMutex() (services, goals, key sequences).
//
// When a plan takes over (PlanTiming): on a robot in real time it is late by its latency
// already and is acted on from its publication; in emulated real time the caller holds the
// world while planOnce runs, then steps it on the running policy until the new one takes over
// at its state's time + its latency (the solve's wall time, or a fixed one).
#pragma once

#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/latency_compensation.h>
#include <adroit_mpc/planner.h>
#include <adroit_mpc/policy_exchange.h>
#include <adroit_mpc/task.h>

#include <mujoco/mujoco.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

namespace adroit_mpc {

enum class PlanTiming {
  // A robot in real time (the node): latency = clock() at publication - the state's time;
  // the plan is acted on from its publication.
  kRealTime,
  // Emulated real time (benchmarks): latency = planOnce's wall time, or fixed_latency; the
  // plan is acted on from its state's time + latency.
  kEmulated,
};

struct RunnerSettings {
  PlanTiming timing = PlanTiming::kRealTime;
  std::function<double()> clock;  // kRealTime: the robot's clock (the states' time base), s
  double fixed_latency = -1;      // kEmulated: >= 0 replaces the wall time (reproducible runs)
  bool latency_compensation = false;
  double feedback_scale = 1.0;  // of the policy's gains, on the control side and in the prediction
  // Called on the MPC thread with the task's events (keys, phases) and the time of the state
  // they were observed on, as soon as planOnce has observed them (before it optimises);
  // outside the task lock.
  std::function<void(double, const std::vector<TaskEvent>&)> on_events;
};

struct PlanOutcome {
  OptimizeReport report;
  bool published = false;  // false: the solve diverged (non-finite cost); the plan was reset
  double latency = 0;      // s, the state's time to publication (what the estimate recorded)
  double compensated = 0;  // s, how far ahead of the state the plan started (prediction)
  double activation = 0;   // when the published plan takes over (control side's clock)
};

// Statistics of the solves and control ticks since the last takeWindow().
struct RunnerWindow {
  OptimizeReport sum;  // table 6.2 times, summed
  double total_max = 0;
  int solves = 0;
  double latency_sum = 0, compensated_sum = 0;
  double age_sum = 0, age_max = 0;  // of the policies acted on (recordPolicyAge)
  int age_samples = 0;
};

class MpcRunner {
 public:
  using Exchange = PolicyExchange<PlanPolicy>;

  // model: the planning model, outliving the runner; task: bound to it. Initialises the
  // planner (allocates everything). Throws std::invalid_argument on bad settings.
  MpcRunner(const mjModel* model, std::unique_ptr<Planner> planner, std::unique_ptr<Task> task,
            const PlannerSettings& settings, RunnerSettings runner_settings);

  // ---- task: any thread, holding taskMutex() ----
  std::mutex& taskMutex() { return task_mutex_; }
  Task& task() { return *task_; }
  // Another task (bound to the model) or horizon: the planner is re-initialised (allocates)
  // at the next planOnce.
  void replaceTask(std::unique_ptr<Task> task);
  void setHorizon(double seconds);
  double horizon() const;  // the one asked for (pending or in use)

  // ---- MPC side: one thread ----
  // Re-initialises the planner on the calling thread (its workers inherit its scheduling).
  void initializePlanner();
  // world_waits: the caller holds the world still until the plan is in (a warm-up before a
  // run): no prediction, and the plan takes over at once; its latency is still recorded.
  PlanOutcome planOnce(const PlannerState& state, bool world_waits = false);
  const Planner& planner() const { return *planner_; }
  const PlannerState& planState() const { return plan_state_; }  // the last plan's start
  double expectedLatency() const { return latency_.expected(); }

  // ---- statistics: any thread ----
  RunnerWindow takeWindow();
  OptimizeReport lastReport() const;
  std::uint64_t solves() const { return solves_.load(); }
  std::uint64_t diverged() const { return diverged_.load(); }
  std::uint64_t published() const { return published_.load(); }
  double planningHorizon() const { return planning_horizon_.load(); }  // of the plans made now

  // ---- control side: one thread; never waits, never allocates ----
  bool updatePolicy(double t) { return exchange_.update(t); }
  bool hasPolicy() const { return exchange_.hasActive(); }
  const PlanPolicy& policy() const { return exchange_.active().policy; }  // hasPolicy()
  std::uint64_t policySerial() const { return hasPolicy() ? exchange_.active().serial : 0; }
  // A policy is acted on while t - its first knot <= its horizon (knots x dt).
  bool usable(double t, double* age = nullptr) const;
  // ctrl (model nu) at t on the measured state. False (send nothing) when no policy is usable
  // or a control came out non-finite.
  bool action(double t, const double* qpos, const double* qvel, const double* act, double* ctrl) const;
  // PlanPolicy::reference of the active policy (the pools' force reference): the number of
  // samples written, 0 (send nothing) when no policy is usable or a value is non-finite.
  int reference(double t, const double* qpos, const double* qvel, const double* act, int max_samples,
                double* out) const;
  void recordPolicyAge(double age);  // for the statistics; skipped rather than wait

 private:
  void observe(const PlannerState& state);
  double predictStart(bool world_waits);
  double measureLatency(double state_time, double wall_seconds) const;
  void recordSolve(const PlanOutcome& outcome);

  const mjModel* model_;
  RunnerSettings run_;
  std::unique_ptr<Planner> planner_;

  // Task and settings (task_mutex_).
  mutable std::mutex task_mutex_;
  std::unique_ptr<Task> task_;
  PlannerSettings settings_;
  bool task_replaced_ = false;
  std::optional<double> pending_horizon_;

  // MPC side.
  adroit::DataPtr observe_data_;
  PlannerState plan_state_;
  StatePredictor predictor_;
  LatencyEstimate latency_;
  PlanPolicy running_;  // the newest published policy, kept for the prediction
  bool have_running_ = false;

  Exchange exchange_;

  mutable std::mutex stats_mutex_;
  RunnerWindow window_;
  OptimizeReport last_report_;
  std::atomic<std::uint64_t> solves_{0}, diverged_{0}, published_{0};
  std::atomic<double> planning_horizon_{0};
};

}  // namespace adroit_mpc
