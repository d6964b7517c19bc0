// Compute per iteration of the trajectory-centric RL trainer (thesis ch. 8.2; Levine & Abbeel
// 2014) at the size -- nx = 100 states, nu = 40 controls, T = 100 steps, N = 5
// rollouts per iteration -- next to the rollout time of the in-process simulation backend
// (a program, not a test; DESIGN.md section 5).
//
// Problem: a random stable time-varying linear-Gaussian system (smooth in t, so the GMM prior
// over (x, u, x') is informative), the initial controller LgController::initial, N rollouts
// per iteration with the smoothed exploration noise, the samples of the last 3 iterations
// feeding the GMM. Cost of thesis 8.4.1's shape: ||q - q*||^2 + 0.001 ||u||^2 per step
// (q = the first half of x), terminal 10 ||q - q*||^2.
//
// Phases timed per iteration: GMM fit (EM), dynamics fit with the GMM prior, cost expansion
// (second-order expansion per sample and step, averaged over the samples), KL-constrained
// update (dual descent on eta, plus the expected cost of the old controller for the step
// size). The new controller generates the next iteration's rollouts on the synthetic system.
//
// Baseline in the same run: 5 rollouts of T = 100 control steps of 10 ms (5 driver steps of
// 2 ms each) of adroit_driver's SimulatedRobot (scene arm_hand, pneumatic mode, random valve
// commands in [-2, 2] V). Update and rollouts alternate (update first on even iterations,
// rollouts first on odd ones) so both see the same machine load.
//
// Usage: learning_bench [--iterations N] [--epsilon E] [--scene NAME] [--seed S] [--threads N] [--out DIR]
//   --threads: workers of the adroit_core::ThreadPool the GMM, the dynamics fit and the KL
//          update use; 0 (default) one per core, 1 no pool (serial)
//   --out: directory of phases.csv and the plot drawn from it by plot_learning.py (installed
//          next to this program); default learning_bench_out
#include <adroit_core/command_line.h>
#include <adroit_core/normal_noise.h>
#include <adroit_core/run_program.h>
#include <adroit_core/thread_pool.h>
#include <adroit_core/timing_stats.h>
#include <adroit_description/scenes.h>
#include <adroit_driver/simulated_robot.h>
#include <adroit_learning/dynamics_fit.h>
#include <adroit_learning/kl_update.h>
#include <adroit_learning/lg_controller.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

using adroit::LgController;
using adroit::LgDynamics;
using adroit::NormalNoise;
using adroit::QuadraticCost;
using adroit::Rollout;

namespace {

constexpr int kNx = 100, kNu = 40, kT = 100, kN = 5, kHistory = 3;
constexpr int kDriverStepsPerControl = 5;  // 10 ms control step of 2 ms driver steps

std::vector<std::string> g_results;

void result(const std::string& name, double value, const char* unit, const char* op, double target) {
  g_results.push_back(adroit::resultLine("adroit_learning", name, value, unit, op, target));
}

// ---------------------------------------------------------------- the synthetic system
// x_{t+1} = A_t x + B_t u + c_t + w, w ~ N(0, noise^2 I); A_t, B_t, c_t blend two random
// endpoints smoothly over t. Each A endpoint has spectral norm 0.97, so every A_t (a convex
// combination) does too: stable.
struct SyntheticSystem {
  std::vector<Eigen::MatrixXd> A, B;
  std::vector<Eigen::VectorXd> c;
  Eigen::VectorXd x0_mean;
  double x0_std = 0.05, noise_std = 0.01;

  SyntheticSystem(NormalNoise& rng) {
    const auto gaussian = [&](int rows, int cols, double scale) {
      Eigen::MatrixXd m(rows, cols);
      for (int j = 0; j < cols; ++j)
        for (int i = 0; i < rows; ++i) m(i, j) = scale * rng();
      return m;
    };
    Eigen::MatrixXd Aend[2], Bend[2];
    Eigen::VectorXd cend[2];
    for (int e = 0; e < 2; ++e) {
      Aend[e] = gaussian(kNx, kNx, 1.0);
      Aend[e] *= 0.97 / Eigen::JacobiSVD<Eigen::MatrixXd>(Aend[e]).singularValues()[0];
      Bend[e] = gaussian(kNx, kNu, 0.3 / std::sqrt(static_cast<double>(kNu)));
      cend[e] = gaussian(kNx, 1, 0.02);
    }
    for (int t = 0; t < kT; ++t) {
      const double s = 0.5 - 0.5 * std::cos(3.14159265358979323846 * t / (kT - 1));
      A.push_back((1 - s) * Aend[0] + s * Aend[1]);
      B.push_back((1 - s) * Bend[0] + s * Bend[1]);
      c.push_back((1 - s) * cend[0] + s * cend[1]);
    }
    x0_mean = gaussian(kNx, 1, 0.5);
  }

  Rollout rollout(const LgController& controller, NormalNoise& rng, double noise_width) const {
    Rollout r;
    r.x.resize(kNx, kT + 1);
    r.u.resize(kNu, kT);
    const Eigen::MatrixXd noise = adroit::smoothedNoise(rng, kNu, kT, noise_width);
    for (int i = 0; i < kNx; ++i) r.x(i, 0) = x0_mean[i] + x0_std * rng();
    for (int t = 0; t < kT; ++t) {
      controller.action(t, r.x.col(t), noise.col(t), r.u.col(t));
      r.x.col(t + 1).noalias() = A[t] * r.x.col(t);
      r.x.col(t + 1).noalias() += B[t] * r.u.col(t);
      r.x.col(t + 1) += c[t];
      for (int i = 0; i < kNx; ++i) r.x(i, t + 1) += noise_std * rng();
    }
    return r;
  }
};

// ---------------------------------------------------------------- the cost
// l_t = ||q - q*||^2 + wu ||u||^2, l_T = wT ||q - q*||^2 with q = x.head(nx / 2).
struct TaskCost {
  Eigen::VectorXd q_target;
  double wu = 0.001, wT = 10.0;

  double sample(const Rollout& r) const {
    const int nq = static_cast<int>(q_target.size());
    double total = 0;
    for (int t = 0; t < kT; ++t)
      total += (r.x.col(t).head(nq) - q_target).squaredNorm() + wu * r.u.col(t).squaredNorm();
    return total + wT * (r.x.col(kT).head(nq) - q_target).squaredNorm();
  }

  // Second-order expansion of l_t at (x, u): derivatives lx, lu, lxx, luu, lux as a generic
  // cost function returns them (dense), then moved to absolute coordinates
  // (cxx = lxx, cx = lx - lxx x - lux' u, ...) and averaged into `out` with weight w.
  void expandAt(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& u,
                double w, QuadraticCost& out, Eigen::MatrixXd& lxx, Eigen::VectorXd& lx, Eigen::MatrixXd& luu,
                Eigen::VectorXd& lu, Eigen::MatrixXd& lux) const {
    const int nq = static_cast<int>(q_target.size());
    const double scale = t < kT ? 1.0 : wT;
    lxx.setZero();
    lxx.topLeftCorner(nq, nq).diagonal().setConstant(2.0 * scale);
    lx.setZero();
    lx.head(nq) = 2.0 * scale * (x.head(nq) - q_target);
    out.cxx[t] += w * lxx;
    out.cx[t].noalias() += w * (lx - lxx * x);
    if (t == kT) return;
    luu.setZero();
    luu.diagonal().setConstant(2.0 * wu);
    lu = 2.0 * wu * u;
    lux.setZero();
    out.cuu[t] += w * luu;
    out.cux[t] += w * lux;
    out.cx[t].noalias() -= w * (lux.transpose() * u);
    out.cu[t].noalias() += w * (lu - luu * u - lux * x);
  }

  void expand(const std::vector<Rollout>& samples, QuadraticCost& out) const {
    out.resize(kNx, kNu, kT);
    Eigen::MatrixXd lxx(kNx, kNx), luu(kNu, kNu), lux(kNu, kNx);
    Eigen::VectorXd lx(kNx), lu(kNu);
    const double w = 1.0 / static_cast<double>(samples.size());
    for (const Rollout& r : samples) {
      for (int t = 0; t < kT; ++t) expandAt(t, r.x.col(t), r.u.col(t), w, out, lxx, lx, luu, lu, lux);
      expandAt(kT, r.x.col(kT), Eigen::VectorXd::Zero(kNu), w, out, lxx, lx, luu, lu, lux);
    }
  }
};

// ---------------------------------------------------------------- the rollout baseline
// 5 rollouts of T control steps of the simulated robot, each from the reset keyframe, with
// random valve commands in [-2, 2] V held for one control step (5 driver steps).
class SimBaseline {
 public:
  SimBaseline(const std::string& scene, std::uint64_t seed) : rng_(seed) {
    adroit::driver::SimConfig config;
    config.model_path = adroit::description::sceneFile(adroit::description::descriptionShareDir(), scene, false);
    config.mode = adroit::driver::ActuationMode::kPneumatic;
    config.initial_keyframe = "rest";
    robot_ = std::make_unique<adroit::driver::SimulatedRobot>(config);
    names_ = robot_->cylinderNames();
    volts_.assign(names_.size(), 0.0);
  }
  std::size_t cylinders() const { return names_.size(); }

  // Seconds of wall time for `rollouts` rollouts of `steps` control steps.
  double run(int rollouts, int steps) {
    adroit::Stopwatch sw;
    for (int r = 0; r < rollouts; ++r) {
      std::string error;
      if (!robot_->resetToKeyframe("rest", &error)) throw std::runtime_error("reset: " + error);
      for (int t = 0; t < steps; ++t) {
        for (double& v : volts_) v = -2.0 + 4.0 * rng_.uniform();
        const auto res = robot_->commandValves(names_, {}, volts_);
        if (!res.applied) throw std::runtime_error("valve command not applied: " + res.error);
        for (int k = 0; k < kDriverStepsPerControl; ++k) robot_->step();
      }
      if (robot_->safety().safe_state) throw std::runtime_error("the simulated robot entered its safe state");
    }
    return sw.elapsed();
  }

 private:
  NormalNoise rng_;
  std::unique_ptr<adroit::driver::SimulatedRobot> robot_;
  std::vector<std::string> names_;
  std::vector<double> volts_;
};

struct IterationRecord {
  double gmm = 0, dynamics = 0, cost = 0, kl = 0, rollout = 0;
  double total() const { return gmm + dynamics + cost + kl; }
  double eta = 0, kl_value = 0, epsilon = 0, sample_cost = 0;
  int eta_iterations = 0;
  bool converged = false;
};

std::string summary(const std::vector<IterationRecord>& recs, double IterationRecord::*field) {
  adroit::SampleStats s;
  for (const auto& r : recs) s.add(r.*field);
  return adroit::formatSummary(s.summary(), 1e3, "ms");
}

double median(const std::vector<IterationRecord>& recs, double IterationRecord::*field) {
  std::vector<double> v;
  for (const auto& r : recs) v.push_back(r.*field);
  return adroit::percentile(v, 50);
}

}  // namespace

int main(int argc, char** argv) {
  int iterations = 8;
  double epsilon = 0.2 * kT;  // KL bound of the whole trajectory (0.2 per step)
  std::string scene = "arm_hand", out_dir = "learning_bench_out";
  std::uint64_t seed = 1;
  int threads = 0;
  adroit::CommandLine args(argc, argv,
                           "usage: learning_bench [--iterations N] [--epsilon E] [--scene NAME] [--seed S] "
                           "[--threads N] [--out DIR]");
  while (args.next()) {
    if (args.is("--iterations")) iterations = static_cast<int>(args.integer());
    else if (args.is("--epsilon")) epsilon = args.number();
    else if (args.is("--scene")) scene = args.text();
    else if (args.is("--seed")) seed = static_cast<std::uint64_t>(args.integer());
    else if (args.is("--threads")) threads = static_cast<int>(args.integer());
    else if (args.is("--out")) out_dir = args.text();
    else args.unknown();
  }
  if (iterations < kHistory) iterations = kHistory;  // at least one iteration with the full history

  std::unique_ptr<adroit::ThreadPool> pool;
  if (threads != 1) pool = std::make_unique<adroit::ThreadPool>(static_cast<std::size_t>(std::max(threads, 0)));
  std::printf("learning_bench: nx %d, nu %d, T %d, N %d rollouts per iteration, GMM over the last %d iterations, "
              "%zu thread(s)\n",
              kNx, kNu, kT, kN, kHistory, pool ? pool->size() : std::size_t{1});
  NormalNoise rng(seed), sys_rng(seed + 100);
  const SyntheticSystem synthetic(sys_rng);
  TaskCost cost_fn;
  cost_fn.q_target = Eigen::VectorXd::Zero(kNx / 2);
  for (int i = 0; i < kNx / 2; ++i) cost_fn.q_target[i] = 0.5 * sys_rng();

  SimBaseline sim(scene, seed + 200);
  std::printf("baseline: SimulatedRobot, scene %s, pneumatic, %zu cylinders, %d x %d control steps of %d x %.0f ms\n",
              scene.c_str(), sim.cylinders(), kN, kT, kDriverStepsPerControl, 2.0);

  LgController controller =
      LgController::initial(kNx, kT, Eigen::VectorXd::Zero(kNu), Eigen::VectorXd::Constant(kNu, 1.0));
  const double noise_width = 2.0;  // steps
  std::vector<std::vector<Rollout>> history;  // the last kHistory iterations' samples
  adroit::KlUpdate kl_update(kNx, kNu, kT);
  adroit::KlUpdateSettings kl_settings;
  adroit::GmmSettings gmm_settings;
  adroit::DynamicsFitSettings dynamics_settings;
  gmm_settings.pool = dynamics_settings.pool = kl_settings.pool = pool.get();
  adroit::Gmm gmm;
  QuadraticCost cost;
  std::vector<IterationRecord> records;
  double previous_expected = 0, previous_predicted = 0, previous_actual = 0;

  std::printf("\n%4s %9s %9s %9s %9s %9s | %9s %7s | %9s %8s %8s %5s %11s\n", "iter", "gmm_ms", "dyn_ms", "cost_ms",
              "kl_ms", "total_ms", "roll_ms", "ratio", "epsilon", "eta", "kl", "evals", "sample_cost");
  for (int it = 0; it < iterations; ++it) {
    IterationRecord rec;
    // Samples of the current controller on the synthetic system (the robot's part; not timed).
    std::vector<Rollout> samples;
    for (int n = 0; n < kN; ++n) samples.push_back(synthetic.rollout(controller, rng, noise_width));
    double actual = 0;
    for (const Rollout& r : samples) actual += cost_fn.sample(r);
    actual /= kN;
    rec.sample_cost = actual;
    history.push_back(samples);
    if (static_cast<int>(history.size()) > kHistory) history.erase(history.begin());
    // Step size from the last update's prediction and this iteration's samples.
    if (it > 0) epsilon = adroit::adjustEpsilon(epsilon, previous_expected, previous_predicted, previous_actual, actual);
    rec.epsilon = epsilon;

    const auto update = [&]() {
      adroit::Stopwatch sw;
      std::vector<Rollout> recent;
      for (const auto& h : history) recent.insert(recent.end(), h.begin(), h.end());
      gmm.fit(adroit::transitionPoints(recent), gmm_settings);
      rec.gmm = sw.elapsed();

      sw.restart();
      const LgDynamics dyn = adroit::fitDynamics(samples, &gmm, dynamics_settings);
      rec.dynamics = sw.elapsed();

      sw.restart();
      cost_fn.expand(samples, cost);
      rec.cost = sw.elapsed();

      sw.restart();
      adroit::TrajectoryMarginals old_marginals;
      adroit::forwardMarginals(dyn, controller, old_marginals, pool.get());
      previous_expected = adroit::expectedCost(cost, old_marginals);
      const adroit::KlUpdateResult res = kl_update.update(dyn, cost, controller, epsilon, kl_settings);
      rec.kl = sw.elapsed();
      kl_settings.eta_init = res.eta;  // warm start, as a trainer does
      kl_settings.kl_slope_init = res.kl_slope;
      rec.eta = res.eta;
      rec.kl_value = res.kl;
      rec.eta_iterations = res.iterations;
      rec.converged = res.converged;
      previous_predicted = res.predicted_cost;
      previous_actual = actual;
      controller = res.controller;
    };
    const auto rollouts = [&]() { rec.rollout = sim.run(kN, kT); };
    if (it % 2 == 0) {
      update();
      rollouts();
    } else {
      rollouts();
      update();
    }
    records.push_back(rec);
    std::printf("%4d %9.1f %9.1f %9.1f %9.1f %9.1f | %9.1f %7.3f | %9.3g %8.3g %8.3g %5d %11.5g%s\n", it, 1e3 * rec.gmm,
                1e3 * rec.dynamics, 1e3 * rec.cost, 1e3 * rec.kl, 1e3 * rec.total(), 1e3 * rec.rollout,
                rec.total() / rec.rollout, rec.epsilon, rec.eta, rec.kl_value, rec.eta_iterations, rec.sample_cost,
                rec.converged ? "" : " (eta search not converged)");
    std::fflush(stdout);
  }

  // Summary per phase; the ratio per iteration pairs each update with its own rollout block.
  adroit::SampleStats total, ratio, rollout;
  for (const auto& r : records) {
    total.add(r.total());
    ratio.add(r.total() / r.rollout);
    rollout.add(r.rollout);
  }
  std::printf("\nper iteration over %d iterations (min / median / p99 / max):\n", iterations);
  std::printf("  %-34s %s\n", "GMM fit (EM, 3 restarts)", summary(records, &IterationRecord::gmm).c_str());
  std::printf("  %-34s %s\n", "dynamics fit with the GMM prior", summary(records, &IterationRecord::dynamics).c_str());
  std::printf("  %-34s %s\n", "cost expansion", summary(records, &IterationRecord::cost).c_str());
  std::printf("  %-34s %s\n", "KL update (dual descent on eta)", summary(records, &IterationRecord::kl).c_str());
  std::printf("  %-34s %s\n", "total compute", adroit::formatSummary(total.summary(), 1e3, "ms").c_str());
  std::printf("  %-34s %s\n", "5 rollouts, SimulatedRobot",
              adroit::formatSummary(rollout.summary(), 1e3, "ms").c_str());
  std::printf("  %-34s %s\n", "compute / rollout (paired)", adroit::formatSummary(ratio.summary(), 1, "").c_str());
  std::printf("  %-34s %.0f ms (5 x %d x 10 ms, real time: hardware or the ROS simulation node)\n",
              "5 rollouts, real-time backends", 1e3 * kN * kT * 0.01, kT);

  const double medians[4] = {median(records, &IterationRecord::gmm), median(records, &IterationRecord::dynamics),
                             median(records, &IterationRecord::cost), median(records, &IterationRecord::kl)};
  const char* names[4] = {"GMM fit", "dynamics fit", "cost expansion", "KL update"};
  const int dominant = static_cast<int>(std::max_element(medians, medians + 4) - medians);
  std::printf("  dominant phase: %s (%.0f %% of the median total)\n", names[dominant],
              100.0 * medians[dominant] / total.summary().median);

  // CSV and plot.
  std::filesystem::create_directories(out_dir);
  const std::string csv_path = out_dir + "/phases.csv";
  {
    std::ofstream f(csv_path);
    if (!f) throw std::runtime_error("cannot write " + csv_path);
    f.precision(9);
    f << "iteration,gmm_s,dynamics_s,cost_s,kl_s,total_s,rollout_s,epsilon,eta,kl,eta_evaluations,sample_cost\n";
    for (std::size_t i = 0; i < records.size(); ++i) {
      const auto& r = records[i];
      f << i << ',' << r.gmm << ',' << r.dynamics << ',' << r.cost << ',' << r.kl << ',' << r.total() << ','
        << r.rollout << ',' << r.epsilon << ',' << r.eta << ',' << r.kl_value << ',' << r.eta_iterations << ','
        << r.sample_cost << '\n';
    }
  }
  std::printf("\nwrote %s\n", csv_path.c_str());
  const std::string plotter = (std::filesystem::path(argv[0]).parent_path() / "plot_learning.py").string();
  if (std::filesystem::exists(plotter)) {
    const adroit::ProgramResult r = adroit::runProgram({"/usr/bin/python3", plotter, out_dir});
    if (!r.ok()) std::printf("plot_learning.py failed (%s; CSV written)\n", r.describe().c_str());
  }

  // The requirement is on a trainer's steady state: only iterations whose GMM already sees
  // the full history of kHistory iterations count (the GMM's cost grows with it).
  adroit::SampleStats steady;
  for (std::size_t i = kHistory - 1; i < records.size(); ++i) steady.add(records[i].total());
  std::printf("  %-34s %s (iterations >= %d: full GMM history)\n", "total compute, steady state",
              adroit::formatSummary(steady.summary(), 1e3, "ms").c_str(), kHistory - 1);
  result("compute_per_iteration_s", steady.summary().median, "s", "<=", 1.0);
  for (const auto& line : g_results) std::printf("%s\n", line.c_str());
  // Informational: compute and rollouts would overlap only with a pipelined trainer.
  std::printf("FIGURE adroit_learning/compute_over_rollout_ratio %.4g ratio (median of the paired blocks; "
              "in-process SimulatedRobot, not real time)\n",
              ratio.summary().median);
  return 0;
}
