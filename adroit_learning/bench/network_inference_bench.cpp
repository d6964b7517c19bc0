// How long one NetworkPolicy::action() takes (thesis 11.6: the network runs once per control
// step, 40 ms on the robot), for the thesis network (6 x 150 ReLU) and the small variant
// (4 x 80), next to the TVLG controller's mean action K x + k of the same sizes measured in the
// same run. Single thread (the policy sets torch's intra-op threads to 1). The state is the
// hand's with the object (nx 100: 24 joints, 40 cylinders) plus 5 touch sensors; 40 actions.
//
//   network_inference_bench [calls]     (default 20000 per row)
//
// Ends with RESULT adroit_learning/network_inference_p99 <ms> ms target <= 1 PASS|FAIL (6 x 150).
#include <adroit_learning/network_policy.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace {

constexpr int kJoints = 24, kCylinders = 40, kTouch = 5;
constexpr double kTargetP99Ms = 1.0;

std::vector<std::string> numbered(const std::string& prefix, int count) {
  std::vector<std::string> names;
  for (int i = 0; i < count; ++i) names.push_back(prefix + std::to_string(i));
  return names;
}

adroit::NetworkPolicyMetadata handMetadata() {
  adroit::NetworkPolicyMetadata m;
  m.task = "bench";
  m.scene = "hand";
  m.control_dt = 0.04;
  m.observation = adroit::ObservationSet::full;
  m.joints = numbered("J", kJoints);
  m.cylinders = numbered("C", kCylinders);
  m.touch = numbered("T", kTouch);
  m.actions = m.cylinders;
  m.state_layout = "q:24 object_position:3 object_rotation_vector:3 qdot:24 object_linear_velocity_world:3 "
                   "object_angular_velocity_body:3 pressure_bar_gauge:40";
  return m;
}

struct Timing {
  double p50 = 0, p99 = 0, max = 0;  // microseconds
};

// Times `calls` calls of step(i) one by one, after a warm-up.
Timing timeCalls(int calls, const std::function<void(int)>& step) {
  for (int i = 0; i < 1000; ++i) step(i);
  std::vector<double> us(static_cast<std::size_t>(calls));
  for (int i = 0; i < calls; ++i) {
    const auto start = std::chrono::steady_clock::now();
    step(i);
    us[static_cast<std::size_t>(i)] =
        std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count();
  }
  std::sort(us.begin(), us.end());
  const auto at = [&](double q) { return us[std::min(us.size() - 1, static_cast<std::size_t>(q * us.size()))]; };
  return {at(0.5), at(0.99), us.back()};
}

}  // namespace

int main(int argc, char** argv) {
  const int calls = argc > 1 ? std::atoi(argv[1]) : 20000;
  if (calls < 100 || calls > 100000000) {
    std::fprintf(stderr, "network_inference_bench: calls must be in [100, 1e8], got '%s'\n", argv[1]);
    return 2;
  }
  const int nx = 2 * kJoints + 12 + kCylinders;
  // A set of varied states, cycled, so no branch or cache sees one input only.
  std::mt19937_64 rng(1);
  std::normal_distribution<double> normal;
  std::vector<Eigen::VectorXd> states(64, Eigen::VectorXd(nx)), touches(64, Eigen::VectorXd(kTouch));
  for (auto& x : states)
    for (int i = 0; i < nx; ++i) x[i] = normal(rng);
  for (auto& t : touches)
    for (int i = 0; i < kTouch; ++i) t[i] = normal(rng);

  std::printf("network_inference_bench: %d calls per row, one thread; state nx %d + %d touch, %d actions\n", calls, nx,
              kTouch, kCylinders);
  std::printf("%-28s %10s %10s %10s\n", "policy", "p50 [us]", "p99 [us]", "max [us]");

  // Baseline: the TVLG mean action at one step, a dense 40 x 100 matrix-vector product.
  const Eigen::MatrixXd K = Eigen::MatrixXd::Random(kCylinders, nx);
  const Eigen::VectorXd k = Eigen::VectorXd::Random(kCylinders);
  Eigen::VectorXd u(kCylinders);
  const Timing tvlg = timeCalls(calls, [&](int i) { u.noalias() = K * states[i % 64] + k; });
  std::printf("%-28s %10.2f %10.2f %10.2f\n", "tvlg K x + k (nx 100, nu 40)", tvlg.p50, tvlg.p99, tvlg.max);

  Timing thesis;
  for (const adroit::NetworkSpec spec : {adroit::NetworkSpec{6, 150}, adroit::NetworkSpec{4, 80}}) {
    adroit::NetworkPolicy policy(handMetadata(), spec);
    const Timing t = timeCalls(calls, [&](int i) { policy.action(0, states[i % 64], touches[i % 64], u); });
    const std::string name = "network " + std::to_string(spec.hidden_layers) + " x " + std::to_string(spec.units);
    std::printf("%-28s %10.2f %10.2f %10.2f   (p50 %.0fx the tvlg's)\n", name.c_str(), t.p50, t.p99, t.max,
                t.p50 / std::max(tvlg.p50, 1e-3));
    if (spec.units == 150) thesis = t;
  }
  const double p99_ms = thesis.p99 / 1000.0;
  std::printf("RESULT adroit_learning/network_inference_p99 %.4f ms target <= %g %s\n", p99_ms, kTargetP99Ms,
              p99_ms <= kTargetP99Ms ? "PASS" : "FAIL");
  return 0;
}
