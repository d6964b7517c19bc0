// The characterisation's analysis on synthetic signals whose answers are computed here,
// independently of the code under test (closed forms of first-order lags, sinusoids, ramps),
// its schedules and safety limits, and the model facts it reads from the ADROIT MJCF.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "adroit_core/mujoco_model.h"
#include "adroit_driver/characterisation.h"

namespace adroit::driver::characterisation {
namespace {

// ------------------------------------------------------------------ detection of a departure

TEST(Characterisation, OnsetDetectorFiresOnTheFirstSampleBeyondFiveSigmaAndNeverOnNoise) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.0035);
  std::vector<double> training;
  for (int i = 0; i < 150; ++i) training.push_back(0.2 + noise(rng));
  double mean = 0, var = 0;
  for (double x : training) mean += x / training.size();
  for (double x : training) var += (x - mean) * (x - mean) / (training.size() - 1);
  const double threshold = std::max(5 * std::sqrt(var), 0.01);

  OnsetDetector d(5.0, 0.01);
  EXPECT_FALSE(d.feed(10.0)) << "not armed";
  for (int i = 0; i < 5; ++i) d.train(training[i]);
  EXPECT_FALSE(d.arm()) << "too few samples to know the noise";
  d.reset();
  for (double x : training) d.train(x);
  ASSERT_TRUE(d.arm());
  EXPECT_NEAR(d.threshold(), threshold, 1e-12);
  for (int i = 0; i < 2000; ++i) ASSERT_FALSE(d.feed(0.2 + noise(rng))) << "noise sample " << i;
  // A ramp of 2 rad/s sampled at 500 Hz: the first sample past the threshold fires, once.
  int fired_at = -1, expected = -1;
  for (int k = 0; k < 100; ++k) {
    const double x = 0.2 + 2.0 * k * 0.002;
    if (expected < 0 && std::fabs(x - mean) > threshold) expected = k;
    if (d.feed(x)) {
      EXPECT_EQ(fired_at, -1) << "fires once";
      fired_at = k;
    }
  }
  EXPECT_EQ(fired_at, expected);
  EXPECT_TRUE(d.fired());

  // A joint still moving while the baseline is learnt is no rest: not armed.
  OnsetDetector moving(5.0, 0.01, 0.05);
  for (int k = 0; k < 100; ++k) moving.train(0.01 * k);
  EXPECT_FALSE(moving.arm());
  EXPECT_FALSE(moving.feed(10.0));
}

TEST(Characterisation, FirstDepartureRespectsDirectionAndWindow) {
  Series s;
  for (int k = 0; k < 100; ++k) s.add(k * 0.01, k < 50 ? 1.0 : k < 60 ? 1.5 : 0.4);
  const Baseline b = baselineOf(s, 0.0, 0.3);
  EXPECT_DOUBLE_EQ(b.mean, 1.0);
  EXPECT_DOUBLE_EQ(b.sigma, 0.0);
  EXPECT_EQ(b.samples, 30);
  EXPECT_NEAR(firstDeparture(s, 0.0, 1.0, b, 0.1, +1), 0.50, 1e-9);
  EXPECT_NEAR(firstDeparture(s, 0.0, 1.0, b, 0.1, -1), 0.60, 1e-9);
  EXPECT_NEAR(firstDeparture(s, 0.55, 1.0, b, 0.1, 0), 0.55, 1e-9);
  EXPECT_TRUE(std::isnan(firstDeparture(s, 0.0, 0.45, b, 0.1, 0)));
}

// ------------------------------------------------------------------ bang-bang strokes

TEST(Characterisation, StrokeOfASinusoidIsTwiceItsAmplitude) {
  const double amplitude = 0.4, f = 5.0;
  Series q;
  for (int k = 0; k < 1000; ++k) {
    const double t = k * 0.002;
    q.add(t, 0.6 + amplitude * std::sin(2 * M_PI * f * t + 0.7));
  }
  const Stroke s = measureStroke(q, 0.0, f, 8, 1, 1.0, 0.9);
  EXPECT_EQ(s.cycles, 7);
  EXPECT_NEAR(s.peak_to_peak, 2 * amplitude, 2 * amplitude * 1e-3);
  EXPECT_NEAR(s.low, 0.2, 1e-3);
  EXPECT_NEAR(s.high, 1.0, 1e-3);
  EXPECT_NEAR(s.fraction, 0.8, 1e-3);
  EXPECT_FALSE(s.complete);
  EXPECT_TRUE(measureStroke(q, 0.0, f, 8, 1, 0.85, 0.9).complete);
}

TEST(Characterisation, HighestCompleteFrequencyAndTheCrossing) {
  BangBangResult r;
  r.complete_fraction = 0.9;
  const double f[] = {2, 4, 6, 8}, fraction[] = {1.0, 0.95, 0.8, 0.5};
  for (int i = 0; i < 4; ++i) {
    Stroke s;
    s.frequency = f[i];
    s.fraction = fraction[i];
    s.complete = fraction[i] >= 0.9;
    r.strokes.push_back(s);
  }
  summariseBangBang(&r);
  EXPECT_DOUBLE_EQ(r.highest_complete_hz, 4.0);
  EXPECT_NEAR(r.crossing_hz, 4 + (0.9 - 0.95) / (0.8 - 0.95) * 2, 1e-12);
  // A late complete stroke after an incomplete one does not count (the strokes stayed incomplete).
  r.strokes[3].complete = true;
  summariseBangBang(&r);
  EXPECT_DOUBLE_EQ(r.highest_complete_hz, 4.0);
  r.strokes[0].complete = false;
  summariseBangBang(&r);
  EXPECT_TRUE(std::isnan(r.highest_complete_hz));
  EXPECT_TRUE(std::isnan(r.crossing_hz));
}

// ------------------------------------------------------------------ limit-to-limit movement

TEST(Characterisation, MovementTimeOfADelayedFirstOrderApproach) {
  // q = 1.2 - 1.1 (1 - exp(-(t - tc - D) / tau)) after the delay: an extension towards 0.1 rad.
  const double tc = 0.5, delay = 0.012, tau = 0.025, window = 0.3, start = 1.2, size = 1.1;
  Series q;
  for (int k = 0; k < 1000; ++k) {
    const double t = k * 0.001, x = t - tc - delay;
    q.add(t, x <= 0 ? start : start - size * (1 - std::exp(-x / tau)));
  }
  const double excursion = size * (1 - std::exp(-(window - delay) / tau));
  const double expected = delay - tau * std::log(1 - 0.9 * excursion / size);
  const Movement m = measureMovement(q, tc, tc + window, -1, 1.571);
  EXPECT_NEAR(m.start, start, 1e-12);
  EXPECT_NEAR(m.excursion, excursion, 1e-4);
  EXPECT_NEAR(m.fraction_of_range, excursion / 1.571, 1e-4);
  EXPECT_NEAR(m.time, expected, 2e-4);
  EXPECT_FALSE(m.flexion);
  // No movement at all: no time.
  EXPECT_TRUE(std::isnan(measureMovement(q, 0.0, 0.4, -1, 1.571).time));

  SequenceResult r;
  Movement a = m, b = m;
  a.joint = "FFJ2";
  b.joint = "FFJ1";
  Movement still = measureMovement(q, 0.0, 0.4, +1, 1.0);
  still.joint = "FFJ1";
  r.moves = {a, b, still};
  summariseSequence(&r);
  EXPECT_EQ(r.joints, 2);
  EXPECT_EQ(r.moved, 2);
  EXPECT_NEAR(r.total, 2 * m.time, 1e-12);
  EXPECT_NEAR(r.mean_movement, m.time, 1e-12);
}

// ------------------------------------------------------------------ reflex latencies

TEST(Characterisation, ReflexLatenciesFromTheDetectingSample) {
  // Pressure of the filling extensor at 250 Hz: atmosphere until 1.0175 s, then +30 kPa/ms.
  // Reacting joint at 500 Hz: held at 1.0 rad until 1.035 s, then extending at 5 rad/s.
  Series p, q;
  for (int k = 0; k < 400; ++k) {
    const double t = k * 0.004;
    p.add(t, 101.3e3 + (t > 1.0175 ? 30e6 * (t - 1.0175) : 0.0));
  }
  for (int k = 0; k < 800; ++k) {
    const double t = k * 0.002;
    q.add(t, 1.0 - (t > 1.035 ? 5.0 * (t - 1.035) : 0.0));
  }
  // Expected, by hand: the first pressure sample past 5 kPa is at 1.020 s (75 kPa up; 1.016 s is
  // before the rise); the first joint sample past 0.01 rad down is at 1.038 s (0.015; 1.036 s: 0.005).
  ReflexTrial t;
  t.t_pulse = 1.0;
  t.t_detect = 1.010;
  t.t_receive = 1.0102;
  t.t_command = 1.0104;
  measureReflex(p, q, -1, ReflexThresholds(), &t);
  ASSERT_TRUE(t.valid) << t.note;
  EXPECT_NEAR(t.t_pressure, 1.020, 1e-9);
  EXPECT_NEAR(t.t_motion, 1.038, 1e-9);
  EXPECT_NEAR(t.pressureLatency(), 0.010, 1e-9);
  EXPECT_NEAR(t.motionLatency(), 0.028, 1e-9);

  // Motion the wrong way (a flexion) is not the reaction.
  ReflexTrial wrong = t;
  measureReflex(p, q, +1, ReflexThresholds(), &wrong);
  EXPECT_FALSE(wrong.valid);
  EXPECT_EQ(wrong.note, "no motion");
  // A detection before the disturbance was commanded is noise.
  ReflexTrial early = t;
  early.t_detect = 0.99;
  measureReflex(p, q, -1, ReflexThresholds(), &early);
  EXPECT_FALSE(early.valid);

  ReflexResult r;
  ReflexTrial slower = t;
  slower.t_detect = 1.006;  // latencies 14 and 32 ms
  slower.t_command = 1.0065;
  r.trials = {t, slower, early, t};
  summariseReflex(&r);
  EXPECT_EQ(r.valid, 3);
  EXPECT_NEAR(r.pressure_latency, 0.010, 1e-9);
  EXPECT_NEAR(r.motion_latency, 0.028, 1e-9);
  EXPECT_NEAR(r.detection_delay, 0.010, 1e-9);
  EXPECT_NEAR(r.transport_delay, 0.0002, 1e-9);
}

// ------------------------------------------------------------------ valve step

Series delayedLag(double t_step, double delay, double tau, double p0, double p1, double rate, double noise, int seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, noise);
  Series p;
  for (int k = 0; k < static_cast<int>(rate); ++k) {
    const double t = k / rate, x = t - t_step - delay;
    p.add(t, p0 + (x > 0 ? (p1 - p0) * (1 - std::exp(-x / tau)) : 0.0) + (noise > 0 ? n(rng) : 0.0));
  }
  return p;
}

TEST(Characterisation, StepOfADelayedFirstOrderLagGivesItsDelayAndTimeConstant) {
  const double delay = 0.005, tau = 0.015;
  const Series p = delayedLag(0.3, delay, tau, 101e3, 600e3, 1000, 0, 1);
  const StepResponse s = measureStep(p, 0.3, 0.7);
  EXPECT_NEAR(s.p_initial, 101e3, 1);
  EXPECT_NEAR(s.p_final, 600e3, 1);
  EXPECT_NEAR(s.dead_time, delay, 2e-4);
  EXPECT_NEAR(s.time_constant, tau, 0.02 * tau);
  EXPECT_NEAR(s.rise_time, tau * std::log(9.0), 0.02 * tau * std::log(9.0));
  EXPECT_NEAR(s.t63, delay + tau, 5e-4);
  EXPECT_GT(s.first_change, delay);
  EXPECT_LT(s.first_change, delay + 0.002);

  // Falling, with sensor noise (2 kPa) and 250 Hz samples, as the driver publishes them.
  const Series q = delayedLag(0.3, delay, tau, 600e3, 103e3, 250, 2e3, 2);
  const StepResponse f = measureStep(q, 0.3, 0.7);
  EXPECT_NEAR(f.dead_time, delay, 1.5e-3);
  EXPECT_NEAR(f.time_constant, tau, 0.1 * tau);
  EXPECT_LT(f.p_final, f.p_initial);

  // No response: no times.
  const StepResponse none = measureStep(delayedLag(0.3, delay, tau, 101e3, 101e3, 250, 2e3, 3), 0.3, 0.7);
  EXPECT_TRUE(std::isnan(none.time_constant));
}

// ------------------------------------------------------------------ chirp and bandwidth

// A first-order lag K / (1 + s tau) driven by the chirp, integrated exactly for an input linear
// over each 0.1 ms step, sampled at `rate`.
Series lagResponse(const ChirpParams& c, double gain, double tau, double rate, double t0) {
  Series y;
  const double dt = 1e-4, a = std::exp(-dt / tau);
  double x = gain * chirpVolts(c, -t0), next_sample = 0;
  const double b1 = 1 - tau / dt * (1 - a);  // weight of the step's end input (first-order hold)
  for (double t = 0; t <= t0 + c.duration + 1e-9; t += dt) {
    if (t >= next_sample - 1e-12) {
      y.add(t, x);
      next_sample += 1.0 / rate;
    }
    const double u0 = gain * chirpVolts(c, t - t0), u1 = gain * chirpVolts(c, t + dt - t0);
    x = a * x + (1 - a - b1) * u0 + b1 * u1;
  }
  return y;
}

TEST(Characterisation, ChirpThroughAFirstOrderLagGivesItsCornerFrequency) {
  ChirpParams c;
  c.f0 = 1;
  c.f1 = 100;
  c.duration = 10;
  c.offset = 0.5;
  c.amplitude = 0.25;
  const double corner = 25.0, tau = 1 / (2 * M_PI * corner), gain = 4e5;  // Pa per volt
  const Series y = lagResponse(c, gain, tau, 250, 0.5);
  const std::vector<GainPoint> points = chirpGains(y, c, 0.5);
  ASSERT_GT(points.size(), 20u);
  EXPECT_LT(points.back().frequency, 0.45 * 250 + 1e-9) << "windows beyond the sample rate are dropped";
  for (const auto& g : points) {
    const double w = 2 * M_PI * g.frequency * tau;
    ASSERT_NEAR(g.gain, gain / std::sqrt(1 + w * w), 0.03 * gain) << g.frequency << " Hz";
    ASSERT_NEAR(g.phase, -std::atan(w), 0.05) << g.frequency << " Hz";
  }
  const Bandwidth bw = criticalFrequency(points, 2.0);
  EXPECT_NEAR(bw.reference_gain, gain, 0.01 * gain);
  EXPECT_NEAR(bw.critical_hz, corner, 0.03 * corner);
  EXPECT_NEAR(bw.phase_at_critical, -M_PI / 4, 0.1);

  // Without a lag there is no -3 dB point in the band.
  const Series flat = lagResponse(c, gain, 1e-5, 250, 0.5);
  EXPECT_TRUE(std::isnan(criticalFrequency(chirpGains(flat, c, 0.5), 2.0).critical_hz));
}

TEST(Characterisation, ChirpScheduleSweepsFromF0ToF1) {
  ChirpParams c;
  c.f0 = 2;
  c.f1 = 60;
  c.duration = 4;
  c.offset = 0.1;
  c.amplitude = 0.5;
  EXPECT_NEAR(chirpFrequency(c, 0), 2, 1e-12);
  EXPECT_NEAR(chirpFrequency(c, 4), 60, 1e-9);
  for (double t : {0.5, 2.0, 3.9}) {  // the phase's rate is the frequency
    const double h = 1e-6;
    EXPECT_NEAR((chirpPhase(c, t + h) - chirpPhase(c, t - h)) / (2 * h), 2 * M_PI * chirpFrequency(c, t), 1e-3);
  }
  EXPECT_DOUBLE_EQ(chirpVolts(c, -1), 0.1);
  EXPECT_DOUBLE_EQ(chirpVolts(c, 5), 0.1);
  c.amplitude = 5;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

// ------------------------------------------------------------------ schedules and limits

TEST(Characterisation, BangBangPushesAtMostMaxPushTimeAndExhaustsTheAntagonist) {
  BangBangParams p;  // push 5 V for at most 0.25 s, then hold 0 V; antagonist -5 V
  auto at = [&](double f, double t) { return bangBangVolts(p, f, t); };
  EXPECT_DOUBLE_EQ(at(1, 0.1).flex, 5);
  EXPECT_DOUBLE_EQ(at(1, 0.1).ext, -5);
  EXPECT_DOUBLE_EQ(at(1, 0.35).flex, 0) << "held after the push time";
  EXPECT_DOUBLE_EQ(at(1, 0.6).ext, 5);
  EXPECT_DOUBLE_EQ(at(1, 0.6).flex, -5);
  EXPECT_DOUBLE_EQ(at(1, 0.85).ext, 0);
  EXPECT_DOUBLE_EQ(at(10, 0.04).flex, 5);
  EXPECT_DOUBLE_EQ(at(10, 0.06).ext, 5);
  EXPECT_DOUBLE_EQ(at(10, 1.04).flex, 5) << "periodic";
  EXPECT_EQ(bangBangCycles(p, 2), 6);
  p.min_window = 1.0;
  EXPECT_EQ(bangBangCycles(p, 20), 20);
  p.frequencies = {4, 2};
  EXPECT_THROW(p.validate(), std::invalid_argument);

  SequenceParams s;  // pre 0.4 s, flexion 0.4 s, extension 0.4 s
  EXPECT_DOUBLE_EQ(sequenceVolts(s, 0.1).ext, 5);
  EXPECT_DOUBLE_EQ(sequenceVolts(s, 0.5).flex, 5);
  EXPECT_DOUBLE_EQ(sequenceVolts(s, 0.5).ext, -5);
  EXPECT_DOUBLE_EQ(sequenceVolts(s, 0.9).ext, 5);
  EXPECT_DOUBLE_EQ(sequenceVolts(s, 1.3).flex, 0) << "idle after the block";
}

// Every schedule stays inside its own safety limits: the limiter never has to act on it.
TEST(Characterisation, SchedulesRespectTheirLimits) {
  const double dt = 0.002;
  auto run = [&](const CommandLimits& limits, double duration, const std::function<PairVolts(double)>& volts) {
    CommandLimiter lim(2, limits);
    double high = 0, longest = 0;
    for (double t = 0; t < duration; t += dt) {
      const PairVolts v = volts(t);
      EXPECT_EQ(lim.apply(0, t, v.flex), v.flex) << t;
      EXPECT_EQ(lim.apply(1, t, v.ext), v.ext) << t;
      high = v.flex > limits.high_volts ? high + dt : 0;
      longest = std::max(longest, high);
    }
    EXPECT_EQ(lim.interventions(), 0u);
    return longest;
  };
  BangBangParams b;
  for (double f : {0.5, 1.0, 2.0, 7.0, 20.0})
    EXPECT_NEAR(run(b.limits(), 4.0, [&](double t) { return bangBangVolts(b, f, t); }),
                std::min(b.max_push_time, 0.5 / f), 2 * dt)
        << f << " Hz: full supply at most max_push_time";
  SequenceParams s;
  run(s.limits(), s.blockTime() + 0.1, [&](double t) { return sequenceVolts(s, t); });
  ReflexParams r;
  run(r.limits(), r.trial, [&](double t) { return reflexVolts(r, t).disturbed; });
  run(r.limits(), r.trial, [&](double t) { return reflexVolts(r, t).reacting; });
  StepParams st;
  run(st.limits(), st.duration(), [&](double t) { return stepVolts(st, t); });
  ChirpParams c;
  c.amplitude = 1.0;
  run(c.limits(), c.start() + c.duration, [&](double t) { return chirpPlanVolts(c, t); });
  ForceParams fo;
  EXPECT_NEAR(run(fo.limits(), fo.duration(), [&](double t) { return forceVolts(fo, t); }), fo.hold, 2 * dt);
}

TEST(Characterisation, StepReflexAndForceSchedules) {
  StepParams st;
  st.levels = {2, 5};
  const auto steps = st.steps();
  ASSERT_EQ(steps.size(), 4u);
  EXPECT_DOUBLE_EQ(steps[0].from, -5);
  EXPECT_DOUBLE_EQ(steps[0].to, 2);
  EXPECT_DOUBLE_EQ(steps[3].from, 5);
  EXPECT_DOUBLE_EQ(steps[3].to, -5);
  for (const auto& s : steps) {
    EXPECT_DOUBLE_EQ(stepVolts(st, s.time - 0.01).flex, s.from);
    EXPECT_DOUBLE_EQ(stepVolts(st, s.time + 0.01).flex, s.to);
    EXPECT_DOUBLE_EQ(stepVolts(st, s.time + st.hold + 0.01).flex, 0.0);
    EXPECT_DOUBLE_EQ(stepVolts(st, s.time).ext, -5.0) << "antagonist exhausted";
  }
  EXPECT_NEAR(steps.back().time + st.hold + st.gap, st.duration(), 1e-12);
  EXPECT_DOUBLE_EQ(stepVolts(st, 0.1).flex, 5.0) << "pinned first";

  ReflexParams r;
  EXPECT_DOUBLE_EQ(reflexVolts(r, 0.1).reacting.flex, 5.0);
  EXPECT_DOUBLE_EQ(reflexVolts(r, 0.6).reacting.flex, 0.0) << "held flexed";
  EXPECT_DOUBLE_EQ(reflexVolts(r, 0.6).reacting.ext, -5.0);
  EXPECT_DOUBLE_EQ(reflexVolts(r, 0.1).disturbed.ext, 5.0) << "extended first";
  EXPECT_DOUBLE_EQ(reflexVolts(r, 0.6).disturbed.flex, -5.0) << "rests extended";
  EXPECT_DOUBLE_EQ(reflexVolts(r, 0.6).disturbed.ext, 0.0);
  EXPECT_DOUBLE_EQ(reflexVolts(r, r.pulse + 0.01).disturbed.flex, 5.0);
  EXPECT_DOUBLE_EQ(reflexVolts(r, r.pulse + r.pulse_time + 0.001).disturbed.flex, -5.0);
  r.trial = 1.0;
  EXPECT_THROW(r.validate(), std::invalid_argument);

  ForceParams f;
  EXPECT_DOUBLE_EQ(forceVolts(f, 0.1).flex, 5.0);
  EXPECT_DOUBLE_EQ(forceVolts(f, 0.1).ext, -5.0);
  EXPECT_DOUBLE_EQ(forceVolts(f, f.extStart() + 0.1).ext, 5.0);
  EXPECT_DOUBLE_EQ(forceVolts(f, f.extStart() + 0.1).flex, -5.0);
  EXPECT_DOUBLE_EQ(forceVolts(f, f.extEnd() + 0.1).ext, 0.0);
}

TEST(Characterisation, LimiterCutsFullSupplyAfterMaxHighTime) {
  CommandLimits l;
  l.max_high_time = 0.3;
  CommandLimiter lim(2, l);
  double last = 0;
  for (int k = 0; k <= 250; ++k) {  // 0.5 s of 5 V on cylinder 0 at 500 Hz
    const double t = k * 0.002;
    last = lim.apply(0, t, 5.0);
    if (t <= 0.3 - 1e-9) {
      ASSERT_DOUBLE_EQ(last, 5.0) << t;
    } else if (t > 0.3 + 0.002) {
      ASSERT_DOUBLE_EQ(last, 0.0) << t;
    }
    EXPECT_DOUBLE_EQ(lim.apply(1, t, 3.0), 3.0) << "below high_volts: never limited";
  }
  EXPECT_GT(lim.interventions(), 90u);
  EXPECT_DOUBLE_EQ(lim.apply(0, 0.502, 5.0), 0.0) << "stays cut while the request stays high";
  EXPECT_DOUBLE_EQ(lim.apply(0, 0.504, -5.0), -5.0);
  EXPECT_DOUBLE_EQ(lim.apply(0, 0.506, 5.0), 5.0) << "a new push after the request dropped";
  EXPECT_DOUBLE_EQ(lim.apply(1, 0.508, 7.0), 5.0) << "clamped to max_volts";
  EXPECT_DOUBLE_EQ(lim.apply(1, 0.510, NAN), 0.0) << "a non-finite request holds";
  l.hold_volts = 4.5;
  EXPECT_THROW(l.validate(), std::invalid_argument);
}

// ------------------------------------------------------------------ the model

class ModelFacts : public ::testing::Test {
 protected:
  void SetUp() override { model_ = loadModelFile(std::string(ADROIT_MJCF_DIR) + "/arm_hand.xml").model; }
  ModelPtr model_;
};

TEST_F(ModelFacts, EveryActuatedJointHasAnAntagonisticPair) {
  const auto pairs = jointPairs(model_.get());
  EXPECT_EQ(pairs.size(), 24u) << "4 arm + 2 wrist + 18 finger and thumb joints";
  const JointPair& mcp = findPair(pairs, "FFJ2");
  EXPECT_EQ(mcp.flexor, "A_FFJ2_flex");
  EXPECT_EQ(mcp.flex_sign, 1) << "flexion is positive (towards the palm)";
  EXPECT_DOUBLE_EQ(mcp.flexLimit(), mcp.upper);
  EXPECT_NEAR(mcp.range(), 1.571, 1e-9);
  EXPECT_THROW(findPair(pairs, "FFJ0"), std::invalid_argument) << "coupled to FFJ1, no cylinders of its own";
  // The MJCF's values: damping 0.05 N m s/rad, M9 cylinders of 32.997 N at full supply.
  EXPECT_DOUBLE_EQ(mcp.damping, 0.05);
  EXPECT_NEAR(mcp.flexor_max_tension, 32.997, 1e-9);
  EXPECT_NEAR(dampingBoundTime(mcp, 1.1, true), 1.1 * 0.05 / (32.997 * mcp.flexor_arm), 1e-12);
  for (const auto& p : pairs) {
    EXPECT_GT(p.flexor_max_tension, 0) << p.joint;
    EXPECT_GT(p.extensor_arm, 1e-3) << p.joint;
  }
}

TEST_F(ModelFacts, FingertipLeverOfTheStraightIndexFinger) {
  const auto pairs = jointPairs(model_.get());
  EXPECT_EQ(tipSiteFor("FFJ2"), "S_fftip");
  EXPECT_EQ(tipSiteFor("THJ3"), "S_thtip");
  EXPECT_THROW(tipSiteFor("WRJ0"), std::invalid_argument);
  const FingertipLever l = fingertipLever(model_.get(), findPair(pairs, "FFJ2"), "S_fftip");
  // MCP to tip along the straight finger: proximal 45 + middle 25 + distal-to-tip 26 mm.
  EXPECT_NEAR(l.lever, 0.096, 1e-3);
  EXPECT_GT(l.flexor_arm, 0.003);
  EXPECT_LT(l.flexor_arm, 0.03);
  EXPECT_GT(l.extensor_arm, 0.003);
  EXPECT_LT(l.extensor_arm, 0.03);
  EXPECT_NEAR(fingertipForce(33.0, l.flexor_arm, l.lever), 33.0 * l.flexor_arm / 0.096, 0.02);
}

// ------------------------------------------------------------------ report

TEST(Characterisation, ReportPutsEachFigureNextToTheThesisValue) {
  Report r;
  r.driver = "simulation";
  r.scene = "arm_hand";
  r.has_bang_bang = true;
  r.bang_bang.joint = "FFJ2";
  r.bang_bang.highest_complete_hz = 3.0;
  r.bang_bang.reference_range = 1.1;
  r.bang_bang.model_range = 1.571;
  r.has_reflex = true;
  r.reflex.pressure_latency = 0.0095;
  r.reflex.motion_latency = 0.0312;
  ChirpResult c;
  c.bandwidth.critical_hz = 18.26;
  r.has_chirp = true;
  r.chirps.push_back(c);
  const std::string md = reportMarkdown(r);
  EXPECT_NE(md.find("| 3.0 Hz | about 7 Hz |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 9.5 ms | 8 ms |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 31.2 ms | 29 ms |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 18.3 Hz | about 25 Hz |"), std::string::npos) << md;
  const std::string csv = summaryCsv(r);
  EXPECT_EQ(csv.rfind("figure,measured,unit,thesis,note\n", 0), 0u);
  EXPECT_NE(csv.find("3.0,Hz,about 7 Hz"), std::string::npos) << csv;
}

}  // namespace
}  // namespace adroit::driver::characterisation
