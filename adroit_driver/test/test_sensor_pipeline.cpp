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

// The ring buffer behaves as the plain list it replaces (a reference implemented on a
// vector here) through wrap-arounds, growth, clears and time shifts.
TEST(DelayLine, RingMatchesAPlainListThroughWrapAroundGrowthAndShifts) {
  struct Reference {
    std::vector<std::pair<double, std::vector<double>>> frames;
    const std::vector<double>& at(double t) {
      while (frames.size() >= 2 && frames[1].first <= t + 1e-9) frames.erase(frames.begin());
      return frames.front().second;
    }
  };
  for (const bool reserved : {true, false}) {
    DelayLine line;
    if (reserved) line.reserve(6, 3);  // delays up to 3 ms at 1 ms pushes: ceil(3) + 3 frames
    Reference ref;
    double t = 0;
    for (int k = 0; k < 500; ++k) {
      t += 0.001;
      const std::vector<double> frame = {t, -t, static_cast<double>(k)};
      line.push(t, frame);
      ref.frames.emplace_back(t, frame);
      const double delay = (k / 100) % 2 ? 0.0015 : 0.0005 * (k % 7);  // varying reads, some far back
      ASSERT_EQ(line.at(t - delay), ref.at(t - delay)) << "step " << k << (reserved ? " reserved" : "");
      ASSERT_EQ(line.size(), ref.frames.size());
      if (k == 250) {
        line.shiftTime(0.5);
        for (auto& f : ref.frames) f.first += 0.5;
        t += 0.5;
      }
      if (k == 300) {
        line.clear();
        ref.frames.clear();
        EXPECT_TRUE(line.empty());
      }
    }
    if (reserved) {
      EXPECT_EQ(line.capacity(), 6u) << "a line that was reserved enough never grows";
    }
  }
}

TEST(DelayLine, OlderFramesStayReadableUntilPassed) {
  DelayLine line;
  line.reserve(3, 1);
  for (int k = 0; k < 3; ++k) line.push(0.001 * k, {static_cast<double>(k)});
  EXPECT_EQ(line.at(-1.0)[0], 0);  // the oldest
  line.push(0.003, {3.0});         // full: grows rather than dropping the frame still needed
  EXPECT_EQ(line.at(-1.0)[0], 0);
  EXPECT_EQ(line.at(0.0025)[0], 2);
  EXPECT_EQ(line.at(0.01)[0], 3);
  EXPECT_EQ(line.size(), 1u);
}

TEST(SensorPipeline, ValuesAreFiniteUnlessTheTruthIsNot) {
  SensorRealism params;
  SensorPipeline p(params, ActuationMode::kPneumatic, {1e-4}, 101325.0, 0.0, 0.002);
  p.restart(0.0, truthAt(0.0));
  for (int k = 1; k <= 10; ++k) p.update(0.002 * k, 0.002, truthAt(0.0));
  EXPECT_TRUE(allFinite(p.sensed()));
  Signals bad = truthAt(0.0);
  bad.pressure[0] = std::nan("");
  for (int k = 11; k <= 20; ++k) p.update(0.002 * k, 0.002, bad);
  EXPECT_FALSE(allFinite(p.sensed()));
  Signals s = p.sensed();
  s.pressure[0] = 1.0;
  s.tension[0] = 1.0;
  EXPECT_TRUE(allFinite(s));
  s.object[12] = INFINITY;
  EXPECT_FALSE(allFinite(s));
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

// A slide joint (a keypad key) reads in metres with the linear sensor's spread and steps,
// a hinge beside it with the Hall sensor's radians.
TEST(SensorPipeline, SlideJointsReadWithTheLinearSensorsSpread) {
  SensorRealism params;
  params.joint_delay = 0;
  SensorPipeline p(params, ActuationMode::kPneumatic, {1e-4}, 101325.0, 0.0);
  p.setSlideJoints({0, 1});
  Signals truth = truthAt(0.0);
  truth.joint_position = {0.0, -0.003};
  truth.joint_velocity = {0.0, 0.0};
  truth.joint_effort = {0.0, 0.0};
  p.restart(0.0, truth);
  double hinge2 = 0, slide2 = 0, slide_v2 = 0;
  const int n = 4000;
  for (int k = 1; k <= n; ++k) {
    p.update(k * 0.002, 0.002, truth);
    const double key = p.sensed().joint_position[1];
    hinge2 += std::pow(p.sensed().joint_position[0], 2);
    slide2 += std::pow(key + 0.003, 2);
    slide_v2 += std::pow(p.sensed().joint_velocity[1], 2);
    ASSERT_NEAR(std::remainder(key, params.slide_quantum), 0.0, 1e-12) << "not on the linear sensor's steps";
  }
  EXPECT_NEAR(std::sqrt(hinge2 / n), params.joint_noise_std, 0.15 * params.joint_noise_std);
  EXPECT_NEAR(std::sqrt(slide2 / n), std::hypot(params.slide_noise_std, params.slide_quantum / std::sqrt(12.0)),
              0.15 * params.slide_noise_std);
  EXPECT_NEAR(std::sqrt(slide_v2 / n), params.slide_velocity_noise_std, 0.1 * params.slide_velocity_noise_std);
}

}  // namespace
}  // namespace adroit::driver
