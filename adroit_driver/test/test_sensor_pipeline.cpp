// Sensor pipeline: sampling rate, delays, noise statistics, determinism by seed.
#include <gtest/gtest.h>

#include <cmath>

#include "adroit_driver/sensor_pipeline.h"

namespace adroit::driver {
namespace {

Signals truthAt(double q) {
  Signals s;
  s.joint_position = {q};
  s.joint_velocity = {0.0};
  s.joint_effort = {0.0};
  s.pressure = {3e5};
  s.length = {0.01};
  s.length_rate = {0.0};
  s.tension = {1.0};
  s.supply_pressure = 6e5;
  s.touch = {0.0};
  return s;
}

TEST(DelayLine, GivesNewestFrameOldEnoughAndOldestBeforeHistory) {
  DelayLine line;
  line.push(0.000, {0});
  line.push(0.001, {1});
  line.push(0.002, {2});
  EXPECT_EQ(line.at(-1.0)[0], 0);  // nothing old enough yet: the oldest
  EXPECT_EQ(line.at(0.0015)[0], 1);
  EXPECT_EQ(line.at(0.002)[0], 2);
}

TEST(SensorPipeline, WithoutRealismReportsTruthImmediately) {
  SensorRealism params;
  params.enabled = false;
  SensorPipeline p(params, ActuationMode::kPneumatic, {1e-4}, 101325.0, 0.0);
  p.restart(0.0, truthAt(0.0));
  p.update(0.001, 0.001, truthAt(0.25));
  p.update(0.002, 0.001, truthAt(0.5));
  EXPECT_EQ(p.sensed().joint_position[0], 0.5);
  EXPECT_EQ(p.sensed().pressure[0], 3e5);
  EXPECT_DOUBLE_EQ(p.sensed().tension[0], (3e5 - 101325.0) * 1e-4);
}

TEST(SensorPipeline, JointsAreSampledAt500HzAndDelayedOneFrame) {
  SensorRealism params;
  params.joint_noise_std = 0;
  params.joint_quantum = 0;
  params.joint_velocity_noise_std = 0;
  SensorPipeline p(params, ActuationMode::kPneumatic, {1e-4}, 101325.0, 0.0);
  const double dt = 0.0005;  // physics at 2 kHz: the MCU still samples at 500 Hz
  p.restart(0.0, truthAt(0.0));
  std::vector<double> seen;
  for (int k = 1; k <= 40; ++k) {
    const double t = k * dt;
    p.update(t, dt, truthAt(t));  // the true angle equals the time
    seen.push_back(p.sensed().joint_position[0]);
  }
  // Readings only take values sampled on the 2 ms grid, 2 ms (joint_delay) late.
  for (std::size_t k = 0; k < seen.size(); ++k) {
    const double t = (k + 1) * dt;
    const double expected = std::max(0.0, std::floor((t - params.joint_delay) / 0.002 + 1e-9) * 0.002);
    EXPECT_NEAR(seen[k], expected, 1e-12) << "at t = " << t;
  }
}

TEST(SensorPipeline, NoiseHasTheConfiguredSpreadAndRepeatsWithTheSeed) {
  SensorRealism params;
  params.joint_quantum = 0;
  params.joint_delay = 0;
  auto run = [&](std::uint64_t seed) {
    params.seed = seed;
    SensorPipeline p(params, ActuationMode::kPneumatic, {1e-4}, 101325.0, 0.0);
    p.restart(0.0, truthAt(0.0));
    std::vector<double> q;
    for (int k = 1; k <= 4000; ++k) {
      p.update(k * 0.002, 0.002, truthAt(0.0));
      q.push_back(p.sensed().joint_position[0]);
    }
    return q;
  };
  const auto a = run(3), b = run(3), c = run(4);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  double sum2 = 0;
  for (double v : a) sum2 += v * v;
  const double std = std::sqrt(sum2 / a.size());
  EXPECT_NEAR(std, params.joint_noise_std, 0.1 * params.joint_noise_std);
}

}  // namespace
}  // namespace adroit::driver
