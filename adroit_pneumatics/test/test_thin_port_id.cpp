// Thin-port identification (eq. 4.12) on noise-free data from the plant model: the table 4.4
// valve, the dead volume and the leak orifice come back within 10 %.
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "adroit_pneumatics/excitation.h"
#include "adroit_pneumatics/thin_port_id.h"

using namespace adroit::pneumatics;

namespace {

void expectPortNear(const GompertzArea& got, const GompertzArea& truth, const char* name) {
  EXPECT_NEAR(got.offset, truth.offset, 0.1 * truth.offset) << name;
  EXPECT_NEAR(got.a, truth.a, 0.1 * truth.a) << name;
  EXPECT_NEAR(got.c, truth.c, 0.1 * std::abs(truth.c)) << name;
  // b and d enter only as b e^{-c d}: the curve's centre (command of opening a / e).
  const double centre = std::log(truth.b) / truth.c - truth.d;
  EXPECT_NEAR(gompertzCentre(got), centre, 0.1 * std::abs(centre)) << name;
  // The whole curve, over the command range.
  for (double u = -5; u <= 5; u += 0.05) EXPECT_NEAR(got(u), truth(u), 0.1 * truth(u)) << name << " u " << u;
}
}  // namespace

TEST(ThinPortId, RecoversValveDeadVolumeAndLeakFromNoiseFreeData) {
  // Truth: AIRPEL M9 with valve 1 (table 4.4), v_0 = 0.1 cm^3, leak d = 1.9665e-4 m (4.5).
  const CylinderSpec truth = cylinderSpec("M9");
  CylinderSpec leak_free = truth;
  leak_free.leak_area = 0.0;
  std::vector<Recording> valve_data;
  for (double travel : {0.005, 0.015, 0.035}) {
    valve_data.push_back(recordLockedCylinder(leak_free, travel, "steps", 1.5, 1));
    valve_data.push_back(recordLockedCylinder(leak_free, travel, "random", 1.5, 2));
  }
  // Start: the other valve of table 4.4, a dead volume twice too large, no leak.
  ThinPortParams start;
  start.valve = valveParams(2);
  start.dead_volume = 2e-7;
  ThinPortFitOptions o;
  const ThinPortFitReport valve = fitThinPort(valve_data, start, o);
  expectPortNear(valve.params.valve.inlet, truth.valve.inlet, "inlet");
  expectPortNear(valve.params.valve.exhaust, truth.valve.exhaust, "exhaust");
  EXPECT_NEAR(valve.params.dead_volume, truth.dead_volume, 0.1 * truth.dead_volume);
  // The rate error falls by more than 20x (what remains is the midpoint rule's error on the
  // fastest, smallest-volume samples).
  EXPECT_LT(valve.rate_rmse, 0.05 * thinPortRateRmse(valve_data, start));

  // The leaky cylinder with that valve: leak orifice (and dead volume again).
  std::vector<Recording> leak_data;
  for (double travel : {0.005, 0.02}) leak_data.push_back(recordLockedCylinder(truth, travel, "steps", 1.5, 3));
  ThinPortParams start2 = valve.params;
  start2.leak_area = 1e-8;
  ThinPortFitOptions o2;
  o2.fit_valve = false, o2.fit_leak = true;
  const ThinPortFitReport leak = fitThinPort(leak_data, start2, o2);
  EXPECT_NEAR(leak.params.leak_area, truth.leak_area, 0.1 * truth.leak_area);
  EXPECT_NEAR(leak.params.dead_volume, truth.dead_volume, 0.1 * truth.dead_volume);
}

TEST(ThinPortId, RejectsEmptyInput) {
  EXPECT_THROW(fitThinPort({}, ThinPortParams{}), std::invalid_argument);
}
