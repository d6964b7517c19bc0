#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/tracking_floor.h"

using namespace adroit::pneumatics;

namespace {
constexpr double kDt = 0.005, kLimit = 2.0;

PlantOptions exactPlant() {
  PlantOptions o;
  o.tube_delay = 0;
  o.area_spread = o.offset_spread = 0;
  return o;
}
SupplyParams stiffSupply() {
  SupplyParams s;
  s.sag_per_mass_flow = 0;  // the floor is given the supply; keep it constant
  return s;
}
double stepRef(int k) { return k < 20 ? 150e3 : k < 40 ? 500e3 : k < 60 ? 250e3 : 450e3; }  // Pa, 100 ms levels
}  // namespace

// No controller within the limit that learns of each level as it comes does better: every
// constant command in [-2, 2] V and proportional controllers of several gains, run on the
// plant itself from the same start, end with at least the floor's squared error.
TEST(TrackingFloor, NoControllerWithinTheLimitDoesBetter) {
  const CylinderSpec spec = cylinderSpec("M9");
  const double travel = 0.5 * spec.stroke, volume = spec.dead_volume + spec.bore_area * travel, rate = 0;
  TrackingFloor floor(spec, kLimit);
  floor.reset(constants::kAtmosphere);
  double floor_sq = 0;
  for (int k = 0; k < 80; ++k) floor_sq += std::pow(floor.step(stepRef(k), kDt, volume, 0.0, 620e3) - stepRef(k), 2);
  const auto run = [&](double constant, double gain) {  // u = constant + gain (ref - p), clamped
    PneumaticPlant plant({spec}, stiffSupply(), 1, exactPlant());
    double sq = 0;
    for (int k = 0; k < 80; ++k) {
      const double u = std::clamp(constant + gain * (stepRef(k) - plant.pressure()[0]), -kLimit, kLimit);
      plant.step(kDt, &u, &travel, &rate);
      sq += std::pow(plant.pressure()[0] - stepRef(k), 2);
    }
    return sq;
  };
  double best = 1e300;
  for (double u = -kLimit; u <= kLimit + 1e-9; u += 0.25) best = std::min(best, run(u, 0.0));
  for (double gain : {1e-6, 3e-6, 1e-5, 3e-5, 1e-4}) best = std::min(best, run(0.0, gain));
  EXPECT_LE(floor_sq, best);
  EXPECT_GT(floor_sq, 0.2 * best);  // a bound, not zero: the jumps take time to fill
}

// Within reach it lands on the reference exactly; a reference given now acts only after the
// dead time.
TEST(TrackingFloor, StopsOnTheReferenceAfterTheDeadTime) {
  const CylinderSpec spec = cylinderSpec("M9");
  const double volume = spec.dead_volume + 0.5 * spec.bore_area * spec.stroke;
  TrackingFloor now(spec, kLimit), late(spec, kLimit, 0.002);
  now.reset(300e3), late.reset(300e3);
  const double first = now.step(300e3, 0.001, volume, 0, 620e3);
  EXPECT_DOUBLE_EQ(first, 300e3);
  // A small change is within one 1 ms step's reach: on it at once without a dead time.
  EXPECT_DOUBLE_EQ(now.step(305e3, 0.001, volume, 0, 620e3), 305e3);
  late.step(300e3, 0.001, volume, 0, 620e3);
  EXPECT_DOUBLE_EQ(late.step(305e3, 0.001, volume, 0, 620e3), 300e3);  // given at 1 ms, acts at 3 ms
  EXPECT_DOUBLE_EQ(late.step(305e3, 0.001, volume, 0, 620e3), 300e3);
  EXPECT_DOUBLE_EQ(late.step(305e3, 0.001, volume, 0, 620e3), 305e3);
  // Non-finite input: unchanged.
  EXPECT_DOUBLE_EQ(now.step(std::nan(""), 0.001, volume, 0, 620e3), 305e3);
}

// Holding one command per step, it ends the step on a reachable reference, and never beats
// the floor that stops exactly.
TEST(TrackingFloor, HoldingOneCommandPerStepEndsOnTheReference) {
  const CylinderSpec spec = cylinderSpec("M9");
  const double volume = spec.dead_volume + 0.5 * spec.bore_area * spec.stroke;
  TrackingFloor hold(spec, kLimit), exact(spec, kLimit);
  hold.setHoldCommandPerStep(true);
  hold.reset(300e3), exact.reset(300e3);
  EXPECT_NEAR(hold.step(320e3, kDt, volume, 0, 620e3), 320e3, 1.0);
  double sq_hold = 0, sq_exact = 0;
  for (int k = 0; k < 80; ++k) {
    const double ref = stepRef(k);
    sq_hold += std::pow(hold.step(ref, kDt, volume, 0, 620e3) - ref, 2);
    sq_exact += std::pow(exact.step(ref, kDt, volume, 0, 620e3) - ref, 2);
  }
  EXPECT_GE(sq_hold, sq_exact);
  EXPECT_LT(sq_hold, 4 * sq_exact);  // the same plant, the same reach
}

// Per group: a cylinder that tracks exactly has no error; the floors are the same for equal
// cylinders and references.
TEST(ForceTrackingAudit, SumsPerGroup) {
  const CylinderSpec spec = cylinderSpec("M9");
  ForceTrackingAudit audit({{"FF", spec}, {"FF", spec}, {"TH", spec}}, kLimit, 0.002);
  audit.start({constants::kAtmosphere, constants::kAtmosphere, constants::kAtmosphere});
  const double v = spec.dead_volume + 0.5 * spec.bore_area * spec.stroke;
  for (int k = 0; k < 40; ++k) {
    const double want = k < 10 ? 0.0 : 20.0;  // N
    audit.add(kDt, {want, want, want}, {want, want, want + 1.0}, {v, v, v}, {0, 0, 0}, 620e3);
  }
  const auto groups = audit.groups();
  ASSERT_EQ(groups.size(), 2u);
  EXPECT_DOUBLE_EQ(groups.at("FF").rmse, 0.0);
  EXPECT_NEAR(groups.at("TH").rmse, 1.0, 1e-12);
  EXPECT_EQ(groups.at("FF").samples, 80);
  EXPECT_GT(groups.at("FF").floor, 0.5);  // the 20 N jump takes time to fill
  EXPECT_NEAR(groups.at("FF").floor, groups.at("TH").floor, 1e-9);
  EXPECT_GE(groups.at("FF").per_tick, groups.at("FF").floor);
  EXPECT_DOUBLE_EQ(groups.at("FF").max_reference, 20.0);
  EXPECT_THROW(ForceTrackingAudit({{"FF", CylinderSpec{}}}, kLimit, 0.0), std::invalid_argument);
}

TEST(ForceTrackingAudit, AReferenceBelowTheRobotsMinimumTensionCountsAgainstTheFloorsToo) {
  const CylinderSpec spec = cylinderSpec("M9");
  const double v = spec.dead_volume + 0.5 * spec.bore_area * spec.stroke;
  const auto run = [&](double min_tension) {
    ForceTrackingAudit audit({{"FF", spec}}, kLimit, 0.002);
    audit.setMinTension(min_tension);
    audit.start({constants::kAtmosphere});
    // Asked for nothing; the robot applies (and reports) its minimum.
    for (int k = 0; k < 40; ++k) audit.add(kDt, {0.0}, {0.3}, {v}, {0}, 620e3);
    return audit.groups().at("FF");
  };
  const auto without = run(0.0), with = run(0.3);
  EXPECT_NEAR(without.rmse, 0.3, 1e-12);
  EXPECT_LT(without.per_tick, 0.2);  // a chamber held near the room pressure pulls (almost) nothing
  EXPECT_NEAR(with.rmse, 0.3, 1e-12);
  EXPECT_NEAR(with.per_tick, 0.3, 1e-9);     // ... but the robot's tendon keeps its minimum
  EXPECT_NEAR(with.floor, 0.3, 1e-9);
  ForceTrackingAudit audit({{"FF", spec}}, kLimit, 0.002);
  EXPECT_THROW(audit.setMinTension(-0.1), std::invalid_argument);
  EXPECT_THROW(audit.setMinTension(std::nan("")), std::invalid_argument);
}

// Seen through the measurement's sensor, a floor holding a constant tension carries the
// sensor's noise (2 kPa on the pressure: about 2 kPa x bore area on the tension), as the
// measured tension does; the exact floor has none once it has settled.
TEST(ForceTrackingAudit, ASensedFloorCarriesTheSensorsNoise) {
  const CylinderSpec spec = cylinderSpec("M9");
  const double v = spec.dead_volume + 0.5 * spec.bore_area * spec.stroke;
  const auto settled_floor = [&](bool sensed) {
    ForceTrackingAudit audit({{"FF", spec}}, kLimit, 0.002);
    SensorParams sensor;
    sensor.pressure_quantum = 1.0;  // noise only: the quantum's own error is far smaller anyway
    if (sensed) audit.setSensor(sensor);
    audit.start({constants::kAtmosphere + 10.0 / spec.bore_area});
    for (int k = 0; k < 400; ++k) audit.add(kDt, {10.0}, {10.0}, {v}, {0}, 620e3);
    return audit.groups().at("FF").floor;
  };
  const double exact = settled_floor(false), sensed = settled_floor(true);
  const double noise = SensorParams{}.pressure_noise_std * spec.bore_area;  // N
  EXPECT_LT(exact, 0.01 * noise);
  EXPECT_GT(sensed, 0.5 * noise);  // the low-pass at 500 Hz barely thins 5 ms samples
  EXPECT_LT(sensed, 1.5 * noise);
}

// The floors learn of a sample's reference at that sample: a jump counts in full where it
// is given, and the chamber moves towards it only from then on.
TEST(ForceTrackingAudit, AJumpCountsInFullAtTheSampleItIsGiven) {
  const CylinderSpec spec = cylinderSpec("M9");
  const double v = spec.dead_volume + 0.5 * spec.bore_area * spec.stroke;
  ForceTrackingAudit audit({{"FF", spec}}, kLimit, 0.002);
  audit.start({constants::kAtmosphere});
  for (int k = 0; k < 10; ++k) audit.add(kDt, {0.0}, {0.0}, {v}, {0}, 620e3);
  const double before = audit.lastPerTickTension()[0];
  const auto settled = audit.groups().at("FF");
  audit.add(kDt, {20.0}, {0.0}, {v}, {0}, 620e3);  // the jump: given now
  const double at_jump = audit.lastPerTickTension()[0];
  EXPECT_NEAR(at_jump, before, 0.01);  // not moved towards it yet
  const auto after = audit.groups().at("FF");
  const auto sum = [](double rmse, long n) { return rmse * rmse * static_cast<double>(n); };
  // The jump's sample adds its whole error to both floors.
  EXPECT_NEAR(sum(after.per_tick, after.samples) - sum(settled.per_tick, settled.samples), std::pow(20.0 - at_jump, 2),
              1e-6);
  EXPECT_NEAR(sum(after.floor, after.samples) - sum(settled.floor, settled.samples), std::pow(20.0 - at_jump, 2), 0.5);
  audit.add(kDt, {20.0}, {0.0}, {v}, {0}, 620e3);
  EXPECT_GT(audit.lastPerTickTension()[0], before + 1.0);  // under way one sample later
}

// At each sample, what the reference given `lead` earlier said about that instant against
// the reference as it came.
TEST(PreviewAudit, MeasuresHowFarThePreviewMissed) {
  PreviewAudit audit({"FF"}, {0.0, 0.01, 0.05});
  audit.addReference(0.0, 0.005, 10, std::vector<double>(10, 0.0));    // says 0 N up to 45 ms
  audit.addReference(0.02, 0.005, 10, std::vector<double>(10, 10.0));  // from 20 ms: 10 N
  for (int k = 0; k < 4; ++k) audit.addSample(0.02 + 0.005 * k, {10.0});
  const auto rmse = audit.groups().at("FF");
  ASSERT_EQ(rmse.size(), 3u);
  EXPECT_DOUBLE_EQ(rmse[0], 0.0);  // the reference as it came
  // 10 ms ahead: at 20 and 25 ms the newest reference then was the first (0 N), at 30 and
  // 35 ms the second.
  EXPECT_NEAR(rmse[1], std::sqrt(200.0 / 4), 1e-9);
  EXPECT_TRUE(std::isnan(rmse[2]));  // no reference 50 ms before any sample
  EXPECT_THROW(PreviewAudit({"FF"}, {-0.01}), std::invalid_argument);
  audit.addReference(0.05, 0.0, 10, std::vector<double>(10, 1.0));  // dt 0: ignored
  audit.addReference(0.05, 0.005, 10, std::vector<double>(3, 1.0));  // wrong size: ignored
  audit.addSample(0.06, {10.0});
  EXPECT_DOUBLE_EQ(audit.groups().at("FF")[0], 0.0);
}

TEST(ReferenceStepAudit, LargestAndPercentilePerGroup) {
  // Two columns in group A, one in B; 101 rows. A's first column climbs 0.5 N a row and jumps
  // 30 N once; its second holds; B climbs 2 N a row.
  ReferenceStepAudit audit({"A", "A", "B"});
  const std::size_t rows = 101, n = 3;
  std::vector<double> forces(rows * n);
  for (std::size_t k = 0; k < rows; ++k) {
    forces[k * n] = 0.5 * k + (k >= 50 ? 30.0 : 0.0);
    forces[k * n + 1] = 5.0;
    forces[k * n + 2] = 2.0 * k;
  }
  audit.addReference(rows, forces.data(), forces.size());
  EXPECT_NEAR(audit.largest("A"), 30.5, 1e-12);
  EXPECT_NEAR(audit.largest("B"), 2.0, 1e-12);
  // A: 200 steps, 100 of 0 N, 99 of 0.5 N, one of 30.5 N: its 99th percentile is a 0.5 N step.
  EXPECT_NEAR(audit.percentile99("A"), 0.5 + ReferenceStepAudit::kBin, 1e-9);
  EXPECT_NEAR(audit.percentile99("B"), 2.0, 1e-9);  // every step 2 N: the bin's edge is capped at the largest
  EXPECT_EQ(audit.largest("C"), 0.0);
  audit.addReference(2, forces.data(), 5);  // a wrong size changes nothing
  EXPECT_NEAR(audit.largest("A"), 30.5, 1e-12);
}
