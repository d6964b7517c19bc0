// Time of one LQ backward pass (adroit::BackwardPass) at the behaviour MPC's sizes, with
// box-constrained controls (projected-Newton QP per step) and without (plain Cholesky, the
// baseline measured in the same run). Thesis table 6.2 budgets 10 ms for the "Backpass"
// of the dynamic-manipulation MPC (horizon 0.3 s at 5 ms = 60 steps).
//
// Problems are random but shaped like the MPC's: A near identity, B of full rank, positive
// definite costs, and control bounds that bind for about a third of the controls. "cold"
// starts every QP from k = 0; "warm" from the previous pass's k (what an MPC iteration sees
// when the plan changes little).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "adroit_core/lq_backward_pass.h"
#include "adroit_core/timing_stats.h"

namespace {

using namespace adroit;
using Eigen::MatrixXd;
using Eigen::VectorXd;

MatrixXd randn(std::mt19937& rng, int rows, int cols, double scale) {
  std::normal_distribution<double> normal(0.0, scale);
  MatrixXd m(rows, cols);
  for (int i = 0; i < m.size(); ++i) m(i) = normal(rng);
  return m;
}

LqApproximation randomProblem(int nx, int nu, int T, unsigned seed) {
  std::mt19937 rng(seed);
  LqApproximation lq(nx, nu, T);
  for (int t = 0; t < T; ++t) {
    lq.A[t] = MatrixXd::Identity(nx, nx) + randn(rng, nx, nx, 0.3 / std::sqrt(nx));
    lq.B[t] = randn(rng, nx, nu, 0.1);
    const MatrixXd Gx = randn(rng, nx, nx, 1.0 / std::sqrt(nx));
    lq.lxx[t] = Gx * Gx.transpose() + 0.1 * MatrixXd::Identity(nx, nx);
    lq.lx[t] = randn(rng, nx, 1, 1.0);
    lq.luu[t] = 0.01 * MatrixXd::Identity(nu, nu);
    lq.lu[t] = randn(rng, nu, 1, 0.01);
  }
  const MatrixXd G = randn(rng, nx, nx, 1.0 / std::sqrt(nx));
  lq.lxx[T] = G * G.transpose() + MatrixXd::Identity(nx, nx);
  lq.lx[T] = randn(rng, nx, 1, 1.0);
  return lq;
}

struct Timing {
  double median_ms = 0;
  double clamped_fraction = 0;
  bool ok = true;
};

enum class Mode { kUnbounded, kBoundedCold, kBoundedWarm };

Timing timePass(const LqApproximation& lq, Mode mode, RegularizationType regularization, int repetitions) {
  BackwardPassSettings settings;
  settings.regularization = regularization;
  BackwardPass pass(lq.nx, lq.nu, lq.horizon, settings);
  FeedbackGains gains;
  gains.resize(lq.nx, lq.nu, lq.horizon);
  const std::vector<VectorXd> u_nominal(lq.horizon, VectorXd::Zero(lq.nu));
  const bool bounded = mode != Mode::kUnbounded;
  const VectorXd u_min = bounded ? VectorXd::Constant(lq.nu, -1.0) : VectorXd();
  const VectorXd u_max = bounded ? VectorXd::Constant(lq.nu, 1.0) : VectorXd();
  const double mu = 1e-6;
  SampleStats stats;
  stats.reserve(repetitions);
  Timing timing;
  pass.run(lq, u_nominal, u_min, u_max, mu, gains);  // warm-up (caches, page faults)
  for (int r = 0; r < repetitions; ++r) {
    if (mode == Mode::kBoundedCold)
      for (auto& k : gains.k) k.setZero();
    Stopwatch watch;
    const BackwardPassResult result = pass.run(lq, u_nominal, u_min, u_max, mu, gains);
    stats.add(watch.elapsed());
    timing.ok = timing.ok && result.ok;
    timing.clamped_fraction = static_cast<double>(result.clamped_controls) / (lq.nu * lq.horizon);
  }
  timing.median_ms = stats.summary().median * 1e3;
  return timing;
}

}  // namespace

int main(int argc, char** argv) {
  const int repetitions = argc > 1 ? std::atoi(argv[1]) : 21;
  struct Size {
    int nx, nu, T;
    const char* what;
  };
  const Size sizes[] = {{60, 45, 60, "hand, 0.3 s at 5 ms"},
                        {60, 45, 30, "hand, short horizon"},
                        {68, 53, 60, "arm + hand"},
                        {68, 53, 30, "arm + hand, short"}};
  std::printf("one backward pass, median of %d (ms); clamped = share of controls at a bound\n", repetitions);
  std::printf("%-3s %-3s %-3s  %-22s %9s %11s %11s %12s %8s  %s\n", "nx", "nu", "T", "problem",
              "Cholesky", "box cold", "box warm", "box+state-reg", "clamped", "box cold / Cholesky");
  double headline = 0;
  bool all_ok = true;
  for (const Size& s : sizes) {
    const LqApproximation lq = randomProblem(s.nx, s.nu, s.T, 1234);
    const Timing base = timePass(lq, Mode::kUnbounded, RegularizationType::kControl, repetitions);
    const Timing cold = timePass(lq, Mode::kBoundedCold, RegularizationType::kControl, repetitions);
    const Timing warm = timePass(lq, Mode::kBoundedWarm, RegularizationType::kControl, repetitions);
    const Timing state = timePass(lq, Mode::kBoundedCold, RegularizationType::kState, repetitions);
    all_ok = all_ok && base.ok && cold.ok && warm.ok && state.ok;
    std::printf("%-3d %-3d %-3d  %-22s %9.2f %11.2f %11.2f %12.2f %7.0f%%  %.2f\n", s.nx, s.nu, s.T, s.what,
                base.median_ms, cold.median_ms, warm.median_ms, state.median_ms, 100 * cold.clamped_fraction,
                cold.median_ms / base.median_ms);
    if (s.nx == 60 && s.T == 60) headline = cold.median_ms;
  }
  if (!all_ok) std::printf("warning: a pass reported a non-positive-definite Quu\n");
  // Thesis table 6.2: Backpass 0.010 s for the dynamic-manipulation MPC.
  std::printf("RESULT adroit_core/backward_pass_box_nx60_nu45_T60 %.3g ms target <= 10 %s\n", headline,
              headline <= 10 && all_ok ? "PASS" : "FAIL");
  return all_ok ? 0 : 1;
}
