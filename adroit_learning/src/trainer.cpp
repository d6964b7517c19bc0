#include "adroit_learning/trainer.h"

#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace adroit {

namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string padded(int i) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%03d", i);
  return buf;
}

}  // namespace

std::string validate(const TrainerSettings& s) {
  if (s.iterations < 1) return "iterations must be positive";
  if (s.samples < 2) return "samples per iteration must be at least 2 (the dynamics fit needs a spread)";
  if (!(s.noise_scale > 0) || !std::isfinite(s.noise_scale)) return "noise level must be positive";
  if (!(s.smoothing_width >= 0) || !std::isfinite(s.smoothing_width)) return "smoothing width must be >= 0 steps";
  if (!(s.initial_state_noise >= 0 && s.initial_state_noise <= 1)) return "initial-state noise must be in [0, 1]";
  if (s.initial_state_noise_from < 0) return "the initial-state noise start iteration must be >= 0";
  if (s.gmm_history < 1) return "gmm_history must be positive";
  if (s.threads < 0) return "threads must be >= 0 (0 = one per core)";
  return "";
}

std::vector<double> initialStateOffsets(NormalNoise& rng, const std::vector<double>& joint_range, double level) {
  std::vector<double> offset(joint_range.size());
  for (std::size_t j = 0; j < offset.size(); ++j) offset[j] = (rng.uniform() - 0.5) * level * joint_range[j];
  return offset;
}

Trainer::Trainer(const TrainingTask& task, const TrainerSettings& settings, RolloutBackend& backend)
    : task_(task),
      settings_(settings),
      backend_(backend),
      layout_(task, backend.jointNames(), backend.cylinderNames(), backend.hasObject()),
      joint_range_(backend.jointRanges()),
      rng_(settings.seed),
      pool_(static_cast<std::size_t>(std::max(0, settings.threads))),
      kl_update_(layout_.nx(), layout_.nu(), task.horizon),
      epsilon_(task.epsilon) {
  const std::string bad = validate(settings);
  if (!bad.empty()) throw std::invalid_argument(bad);
  settings_.gmm.pool = settings_.dynamics.pool = settings_.kl.pool = &pool_;
  if (static_cast<int>(joint_range_.size()) != layout_.joints())
    throw std::invalid_argument("backend reports " + std::to_string(joint_range_.size()) + " joint ranges for " +
                                std::to_string(layout_.joints()) + " joints");
  cost_ = std::make_unique<TrajectoryCost>(task_, layout_, backend_.initialState(task_, layout_), backend_.objectGeometry());
  controller_ = LgController::initial(layout_.nx(), task.horizon, Eigen::VectorXd::Constant(layout_.nu(), task.initial_command),
                                      Eigen::VectorXd::Constant(layout_.nu(), task.initial_variance * settings.noise_scale));
  startFromActions(settings.initial_actions);
  if (!settings_.output_dir.empty()) {
    ::mkdir(settings_.output_dir.c_str(), 0755);  // an existing directory is fine; writability is tested next
    writeFileAtomically(settings_.output_dir + "/learning_curve.csv", learningCurveCsv({}));
  }
}

void Trainer::startFromActions(const Eigen::MatrixXd& actions) {
  if (actions.size() == 0) return;
  if (actions.rows() != layout_.nu() || actions.cols() != task_.horizon)
    throw std::invalid_argument("initial actions are " + std::to_string(actions.rows()) + "x" + std::to_string(actions.cols()) +
                                ", the task needs " + std::to_string(layout_.nu()) + "x" + std::to_string(task_.horizon));
  if (!actions.allFinite()) throw std::invalid_argument("initial actions are not all finite");
  for (int t = 0; t < task_.horizon; ++t) controller_.k[t] = actions.col(t);
}

std::vector<RolloutRequest> Trainer::makeRequests(int count, double state_noise) {
  std::vector<RolloutRequest> requests(count);
  for (auto& r : requests) {
    r.noise = smoothedNoise(rng_, layout_.nu(), task_.horizon, settings_.smoothing_width);
    if (state_noise > 0) r.joint_offset = initialStateOffsets(rng_, joint_range_, state_noise);
  }
  return requests;
}

PolicyFile Trainer::policyFile(const LgController& controller, int iteration, double cost_mean) const {
  PolicyFile p;
  p.task = task_.name;
  p.scene = task_.scene;
  p.state_layout = layout_.describe();
  p.control_dt = task_.control_dt;
  p.iteration = iteration;
  p.cost_mean = cost_mean;
  p.joints = layout_.joint_names;
  p.cylinders = layout_.cylinder_names;
  for (int c : layout_.action_cylinders) p.actions.push_back(layout_.cylinder_names[c]);
  p.locked_command = layout_.locked_command;
  p.controller = controller;
  return p;
}

IterationReport Trainer::iterate() {
  IterationReport report;
  report.iteration = iteration_;
  report.epsilon = epsilon_;
  const int T = task_.horizon;
  const bool state_noise = iteration_ >= settings_.initial_state_noise_from;
  std::vector<RolloutRequest> requests =
      makeRequests(settings_.samples, state_noise ? settings_.initial_state_noise : 0.0);

  auto start = std::chrono::steady_clock::now();
  std::vector<RolloutResult> results = backend_.run(task_, layout_, controller_, requests, cancel_);
  report.rollout_s = secondsSince(start);
  std::vector<Rollout> samples;
  for (std::size_t i = 0; i < results.size(); ++i) {
    if (!results[i].ok) {
      report.message = cancel_.load() ? "cancelled"
                                      : "rollout " + std::to_string(i) + " failed: " + results[i].error +
                                            "; iteration aborted, controller unchanged";
      history_.push_back(report);
      writeLearningCurve();
      ++iteration_;  // the attempt counts, so a robot that keeps failing cannot loop forever
      return report;
    }
    samples.push_back(std::move(results[i].sample));
  }

  // Costs and success of the controller that ran.
  report.samples = static_cast<int>(samples.size());
  std::vector<double> costs;
  for (const Rollout& r : samples) {
    const TaskOutcome o = cost_->outcome(r);
    costs.push_back(o.cost);
    report.joint_rms_mean += o.joint_rms / samples.size();
    report.angle_error_mean += o.angle_error / samples.size();
    report.successes += o.success;
    report.drops += o.dropped;
  }
  for (double c : costs) report.cost_mean += c / costs.size();
  for (double c : costs) report.cost_std += (c - report.cost_mean) * (c - report.cost_mean) / costs.size();
  report.cost_std = std::sqrt(report.cost_std);
  if (!settings_.output_dir.empty()) {
    report.policy_path = settings_.output_dir + "/policy_" + padded(iteration_) + ".tvlg";
    writePolicyFile(report.policy_path, policyFile(controller_, iteration_, report.cost_mean));
  }

  // Step size from the last update's prediction against what its controller just did.
  if (have_prediction_) {
    epsilon_ = adjustEpsilon(epsilon_, previous_expected_, previous_predicted_, previous_actual_, report.cost_mean);
    report.epsilon = epsilon_;
  }

  start = std::chrono::steady_clock::now();
  recent_.push_back(samples);
  while (static_cast<int>(recent_.size()) > settings_.gmm_history) recent_.pop_front();
  std::vector<Rollout> prior_samples;
  for (const auto& it : recent_) prior_samples.insert(prior_samples.end(), it.begin(), it.end());
  gmm_.fit(transitionPoints(prior_samples), settings_.gmm);
  report.gmm_s = secondsSince(start);

  start = std::chrono::steady_clock::now();
  const LgDynamics dynamics = fitDynamics(samples, &gmm_, settings_.dynamics);
  report.dynamics_s = secondsSince(start);

  start = std::chrono::steady_clock::now();
  QuadraticCost quadratic(layout_.nx(), layout_.nu(), T);
  cost_->expand(samples, quadratic);
  report.cost_s = secondsSince(start);

  start = std::chrono::steady_clock::now();
  try {
    TrajectoryMarginals marginals;
    forwardMarginals(dynamics, controller_, marginals, &pool_);
    const double expected_old = expectedCost(quadratic, marginals);
    KlUpdateSettings kl = settings_.kl;
    kl.eta_init = eta_;
    kl.kl_slope_init = kl_slope_;
    KlUpdateResult result = kl_update_.update(dynamics, quadratic, controller_, epsilon_, kl);
    report.kl = result.kl;
    report.eta = result.eta;
    report.kl_converged = result.converged;
    eta_ = result.eta;
    kl_slope_ = result.kl_slope;
    // The quadratic's constants are dropped, so expected costs are compared as differences.
    previous_expected_ = expected_old;
    previous_predicted_ = result.predicted_cost;
    previous_actual_ = report.cost_mean;
    have_prediction_ = true;
    controller_ = std::move(result.controller);
    report.ok = true;
  } catch (const std::exception& e) {
    report.message = std::string("KL update failed: ") + e.what() + "; controller unchanged";
  }
  report.update_s = secondsSince(start);
  history_.push_back(report);
  writeLearningCurve();
  ++iteration_;
  return report;
}

void Trainer::writeLearningCurve() const {
  if (settings_.output_dir.empty()) return;
  writeFileAtomically(settings_.output_dir + "/learning_curve.csv", learningCurveCsv(history_));
}

std::string learningCurveCsv(const std::vector<IterationReport>& history) {
  std::ostringstream out;
  out << "iteration,ok,cost_mean,cost_std,joint_rms_mean,angle_error_mean,successes,drops,samples,kl,eta,epsilon,"
         "rollout_s,gmm_s,dynamics_s,cost_s,update_s\n";
  for (const auto& r : history)
    out << r.iteration << ',' << r.ok << ',' << r.cost_mean << ',' << r.cost_std << ',' << r.joint_rms_mean << ','
        << r.angle_error_mean << ',' << r.successes << ',' << r.drops << ',' << r.samples << ',' << r.kl << ','
        << r.eta << ',' << r.epsilon << ',' << r.rollout_s << ',' << r.gmm_s << ',' << r.dynamics_s << ','
        << r.cost_s << ',' << r.update_s << '\n';
  return out.str();
}

}  // namespace adroit
