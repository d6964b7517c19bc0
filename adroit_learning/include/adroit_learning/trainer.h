// The trajectory-centric RL loop of thesis 8.2 (Algorithm 2), ROS-free: each iteration runs N
// rollouts of the current linear-Gaussian controller on a RolloutBackend, fits the GMM prior
// over the recent iterations' samples and the per-step dynamics, expands the cost, and takes
// a KL-constrained step, adapting the step size epsilon from predicted vs actual improvement.
// The trainer node and the benchmark drive it; it writes the policies and the learning curve.
#pragma once
#include <adroit_core/normal_noise.h>
#include <adroit_learning/dynamics_fit.h>
#include <adroit_learning/kl_update.h>
#include <adroit_learning/policy_file.h>
#include <adroit_learning/rollout_backend.h>
#include <adroit_learning/trajectory_cost.h>

#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <vector>

namespace adroit {

struct TrainerSettings {
  int iterations = 15;
  int samples = 5;                  // rollouts per iteration (N)
  std::uint64_t seed = 1;
  double noise_scale = 1.0;         // multiplies the task's initial exploration variance
  // Gaussian kernel width of the exploration noise, in steps. 0 (white) learned fastest in
  // robustness_bench (fig. 8.5) at the tasks' 25 Hz; wider kernels drop the tube more often.
  double smoothing_width = 0.0;
  double initial_state_noise = 0;   // level s: joints start within +-s/2 of their range
  int initial_state_noise_from = 0; // first iteration with initial-state noise (8.5.1)
  int gmm_history = 3;              // iterations of samples the GMM prior is fitted on
  int threads = 0;                  // GMM, dynamics fit and KL update workers (0 = one per core)
  GmmSettings gmm;
  DynamicsFitSettings dynamics;
  KlUpdateSettings kl;
  std::string output_dir;           // "" = write nothing
  // Learning from imitation (thesis 10.4): the first iteration samples around these controls
  // (nu x T, a demonstration's: demonstrationActions) with the task's exploration noise,
  // instead of around the task's initial_command. Empty: learning from experience only.
  Eigen::MatrixXd initial_actions;
};

// Checks the settings; "" when valid, else one line naming the bad field.
std::string validate(const TrainerSettings& settings);

struct IterationReport {
  int iteration = 0;
  bool ok = false;                // false: the rollouts failed, the controller is unchanged
  std::string message;            // why not ok
  double cost_mean = 0, cost_std = 0;
  double joint_rms_mean = 0, angle_error_mean = 0;
  int successes = 0, drops = 0, samples = 0;
  double kl = 0, eta = 0, epsilon = 0;  // of the update that followed the rollouts
  bool kl_converged = false;
  double rollout_s = 0, gmm_s = 0, dynamics_s = 0, cost_s = 0, update_s = 0;
  std::string policy_path;        // the controller that ran these rollouts
};

class Trainer {
 public:
  // Throws TaskError / std::invalid_argument for a task that does not fit the backend's
  // robot, PolicyFileError when output_dir cannot be written.
  Trainer(const TrainingTask& task, const TrainerSettings& settings, RolloutBackend& backend);

  // Runs the next iteration. Never throws for a failed rollout (reported, not ok); a
  // cancelled iteration returns ok = false with message "cancelled".
  IterationReport iterate();
  bool finished() const { return iteration_ >= settings_.iterations; }
  int iteration() const { return iteration_; }
  void cancel() { cancel_.store(true); }
  bool cancelled() const { return cancel_.load(); }

  const LgController& controller() const { return controller_; }
  const StateLayout& layout() const { return layout_; }
  const TrajectoryCost& cost() const { return *cost_; }
  const TrainingTask& task() const { return task_; }
  const std::vector<IterationReport>& history() const { return history_; }
  double epsilon() const { return epsilon_; }
  PolicyFile policyFile(const LgController& controller, int iteration, double cost_mean) const;

  // The requests of one iteration: smoothed exploration noise per sample and, from
  // initial_state_noise_from on, joint offsets (public for the benchmark's evaluation runs).
  std::vector<RolloutRequest> makeRequests(int count, double state_noise);

 private:
  void writeLearningCurve() const;
  void startFromActions(const Eigen::MatrixXd& actions);  // settings.initial_actions as the first mean

  TrainingTask task_;
  TrainerSettings settings_;
  RolloutBackend& backend_;
  StateLayout layout_;
  std::unique_ptr<TrajectoryCost> cost_;
  std::vector<double> joint_range_;  // rad, per layout joint (for initial-state noise)
  NormalNoise rng_;
  LgController controller_;
  ThreadPool pool_;  // the update's phases (the rollouts have the backend's own workers)
  KlUpdate kl_update_;
  Gmm gmm_;
  std::deque<std::vector<Rollout>> recent_;  // the last gmm_history iterations' samples
  double epsilon_, eta_ = 1.0, kl_slope_ = -1.0;
  // Step-size adaptation: the last update's expected cost of the old controller and predicted
  // cost of the new one under the fitted dynamics, and the old controller's sample mean.
  bool have_prediction_ = false;
  double previous_expected_ = 0, previous_predicted_ = 0, previous_actual_ = 0;
  int iteration_ = 0;
  std::atomic<bool> cancel_{false};
  std::vector<IterationReport> history_;
};

// Initial-state noise of level s: per joint, uniform in +-s/2 of its range (rad).
std::vector<double> initialStateOffsets(NormalNoise& rng, const std::vector<double>& joint_range, double level);

// Learning curve: iteration, cost mean/std, successes, KL, eta, epsilon, phase seconds.
std::string learningCurveCsv(const std::vector<IterationReport>& history);

}  // namespace adroit
