// The pressure controller's specialised iLQG backward pass (state [p, w], one control,
// everything in scalars) against the generic one of adroit_core (adroit::BackwardPass,
// Eigen, box QP) on the same problem: nx = 2, nu = 1, T = 100, the pool's horizon.
//
// IlqgSolver::backward is private, so the scalar recursion timed here is a line-for-line
// copy of it (pressure_control.cpp: same cost, same dynamics [a p + c w + b u, u], same
// clamping and value update). Both passes run on the same linearisation, and the bench
// checks that they produce the same gains before it times them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "adroit_core/lq_backward_pass.h"
#include "adroit_core/timing_stats.h"

namespace {

constexpr int kHorizon = 100;
// IlqgParams defaults (SI units: Pa, V).
constexpr double kAlphaP = 1e-12, kAlphaU = 1e-4, kAlphaW = 1e-4, kUMin = -2.0, kUMax = 2.0;

// A linearisation along a nominal like the pool's: pressure 2..4 bar gauge tracking a sine,
// a = dp'/dp just below 1, b = dp'/du ~ 20 kPa/V per 5 ms step, c = dead-time share of w.
struct Nominal {
  std::vector<double> p, w, u, a, b, c, p_ref, u_des;
};

Nominal makeNominal(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-1.0, 1.0);
  Nominal n;
  for (int i = 0; i <= kHorizon; ++i) {
    n.p.push_back(3e5 + 1e5 * std::sin(0.05 * i));
    n.p_ref.push_back(3.2e5 + 1e5 * std::sin(0.05 * i + 0.3));
    n.u_des.push_back(0.1 * jitter(rng));
    n.u.push_back(1.9 * std::sin(0.08 * i));  // near the bounds at the peaks: some clamp
    n.w.push_back(i == 0 ? 0.0 : n.u[i - 1]);
    n.a.push_back(0.97 + 0.02 * jitter(rng));
    n.b.push_back(2e4 * (1 + 0.2 * jitter(rng)));
    n.c.push_back(5e3 * (1 + 0.2 * jitter(rng)));
  }
  return n;
}

// Copy of adroit::pneumatics::IlqgSolver::backward (see the file comment).
bool scalarBackward(const Nominal& n, double reg, std::vector<double>& kff, std::vector<double>& kp,
                    std::vector<double>& kw, double* expected) {
  const double ap = kAlphaP, au = kAlphaU, aw = kAlphaW;
  double V1 = -2.0 * ap * (n.p_ref[kHorizon] - n.p[kHorizon]), V2 = 0, V11 = 2.0 * ap, V12 = 0, V22 = 0;
  double dv = 0;
  for (int i = kHorizon - 1; i >= 0; --i) {
    const double a = n.a[i], b = n.b[i], c = n.c[i], u = n.u[i];
    const double lp = -2.0 * ap * (n.p_ref[i] - n.p[i]);
    const double lw = -2.0 * aw * (u - n.w[i]);
    const double lu = -2.0 * au * (n.u_des[i] - u) + 2.0 * aw * (u - n.w[i]);
    const double Qp = lp + a * V1;
    const double Qw = lw + c * V1;
    const double Qu = lu + b * V1 + V2;
    const double Qpp = 2.0 * ap + a * a * V11;
    const double Qpw = a * c * V11;
    const double Qww = 2.0 * aw + c * c * V11;
    const double Quu = 2.0 * au + 2.0 * aw + b * b * V11 + 2.0 * b * V12 + V22;
    const double Qup = a * (b * V11 + V12);
    const double Quw = -2.0 * aw + c * (b * V11 + V12);
    const double H = Quu + reg;
    if (!(H > 0)) return false;
    double k = -Qu / H, Kp = -Qup / H, Kw = -Quw / H;
    if (u + k > kUMax) {
      k = kUMax - u;
      Kp = Kw = 0;
    } else if (u + k < kUMin) {
      k = kUMin - u;
      Kp = Kw = 0;
    }
    kff[i] = k;
    kp[i] = Kp;
    kw[i] = Kw;
    dv += k * Qu + 0.5 * k * k * Quu;
    V1 = Qp + Kp * Quu * k + Kp * Qu + Qup * k;
    V2 = Qw + Kw * Quu * k + Kw * Qu + Quw * k;
    V11 = Qpp + Kp * Quu * Kp + 2.0 * Kp * Qup;
    V12 = Qpw + Kp * Quu * Kw + Kp * Quw + Qup * Kw;
    V22 = Qww + Kw * Quu * Kw + 2.0 * Kw * Quw;
  }
  *expected = dv;
  return std::isfinite(dv);
}

// The same problem as an adroit::LqApproximation: x = [p, w], u; l = ap (pr - p)^2 +
// au (ud - u)^2 + aw (u - w)^2, terminal ap (pr - p)^2.
adroit::LqApproximation toLq(const Nominal& n) {
  adroit::LqApproximation lq(2, 1, kHorizon);
  for (int i = 0; i < kHorizon; ++i) {
    lq.A[i] << n.a[i], n.c[i], 0, 0;
    lq.B[i] << n.b[i], 1;
    lq.lx[i] << -2.0 * kAlphaP * (n.p_ref[i] - n.p[i]), -2.0 * kAlphaW * (n.u[i] - n.w[i]);
    lq.lxx[i] << 2.0 * kAlphaP, 0, 0, 2.0 * kAlphaW;
    lq.lu[i] << -2.0 * kAlphaU * (n.u_des[i] - n.u[i]) + 2.0 * kAlphaW * (n.u[i] - n.w[i]);
    lq.luu[i] << 2.0 * (kAlphaU + kAlphaW);
    lq.lux[i] << 0, -2.0 * kAlphaW;
  }
  lq.lx[kHorizon] << -2.0 * kAlphaP * (n.p_ref[kHorizon] - n.p[kHorizon]), 0;
  lq.lxx[kHorizon] << 2.0 * kAlphaP, 0, 0, 0;
  return lq;
}

template <typename Pass>
double medianMicroseconds(Pass pass, int repetitions, int inner) {
  adroit::SampleStats stats;
  stats.reserve(repetitions);
  for (int r = 0; r < repetitions; ++r) {
    adroit::Stopwatch watch;
    for (int i = 0; i < inner; ++i) pass();
    stats.add(watch.elapsed() / inner);
  }
  return stats.summary().median * 1e6;
}

}  // namespace

int main() {
  const Nominal nominal = makeNominal(3);
  const adroit::LqApproximation lq = toLq(nominal);
  const double reg = 0.0;

  std::vector<double> kff(kHorizon), kp(kHorizon), kw(kHorizon);
  double expected = 0;
  if (!scalarBackward(nominal, reg, kff, kp, kw, &expected)) {
    std::printf("scalar backward pass failed\n");
    return 1;
  }
  adroit::BackwardPass core(2, 1, kHorizon);
  adroit::FeedbackGains gains;
  gains.resize(2, 1, kHorizon);
  std::vector<Eigen::VectorXd> u_nominal(kHorizon, Eigen::VectorXd::Zero(1));
  for (int i = 0; i < kHorizon; ++i) u_nominal[i][0] = nominal.u[i];
  const Eigen::VectorXd u_min = Eigen::VectorXd::Constant(1, kUMin), u_max = Eigen::VectorXd::Constant(1, kUMax);
  const adroit::BackwardPassResult result = core.run(lq, u_nominal, u_min, u_max, reg, gains);
  // Same answer first: feedforward, both gains, and the predicted cost change.
  double max_difference = 0;
  for (int i = 0; i < kHorizon; ++i) {
    max_difference = std::max(max_difference, std::abs(gains.k[i][0] - kff[i]) / (1e-12 + std::abs(kff[i])));
    max_difference = std::max(max_difference, std::abs(gains.K[i](0, 0) - kp[i]) / (1e-300 + std::abs(kp[i])));
    max_difference = std::max(max_difference, std::abs(gains.K[i](0, 1) - kw[i]) / (1e-300 + std::abs(kw[i])));
  }
  const double dv_core = result.dV[0] + result.dV[1];
  std::printf("same problem: %d of %d steps clamped, largest relative gain difference %.1e, dV %.6g vs %.6g\n",
              result.clamped_controls, kHorizon, max_difference, dv_core, expected);
  if (!result.ok || max_difference > 1e-6 || std::abs(dv_core - expected) > 1e-6 * std::abs(expected)) {
    std::printf("the two passes disagree: not timing different computations\n");
    return 1;
  }

  volatile double sink = 0;  // keeps the passes from being optimised away
  const double scalar_us = medianMicroseconds(
      [&] {
        scalarBackward(nominal, reg, kff, kp, kw, &expected);
        sink = kff[0];
      },
      31, 2000);
  const double core_us = medianMicroseconds(
      [&] {
        core.run(lq, u_nominal, u_min, u_max, reg, gains);
        sink = gains.k[0][0];
      },
      31, 200);
  std::printf("backward pass, nx = 2, nu = 1, T = %d (median of 31, microseconds):\n", kHorizon);
  std::printf("  specialised scalar recursion (IlqgSolver::backward)   %8.2f\n", scalar_us);
  std::printf("  generic adroit::BackwardPass (Eigen, box QP)          %8.2f\n", core_us);
  std::printf("RESULT adroit_pneumatics/scalar_backward_pass_speedup %.3g x target >= 1 %s\n", core_us / scalar_us,
              core_us >= scalar_us ? "PASS" : "FAIL");
  return 0;
}
