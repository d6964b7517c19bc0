#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "adroit_pneumatics/fast_exp.h"
#include "adroit_pneumatics/flow.h"

using namespace adroit::pneumatics;

TEST(Flow, ContinuousAtChokeRatio) {
  const double pd = 1e5, theta = chokeRatio();
  // theta = ((k+1)/2)^(k/(k-1)) with k = 1.4 is about 1.893 (notes, table 4.1).
  EXPECT_NEAR(theta, 1.893, 1e-3);
  const double below = flowZ(pd * theta * (1 - 1e-9), pd);
  const double above = flowZ(pd * theta * (1 + 1e-9), pd);
  EXPECT_NEAR(below, above, 1e-6 * above);
}

TEST(Flow, AntisymmetricAndZeroAtEqualPressure) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> p(5e4, 8e5);
  for (int i = 0; i < 200; ++i) {
    const double a = p(rng), b = p(rng);
    EXPECT_DOUBLE_EQ(flowPhi(a, b), -flowPhi(b, a));
    EXPECT_EQ(flowPhi(a, b) > 0, a > b);
  }
  EXPECT_EQ(flowPhi(3e5, 3e5), 0.0);
}

TEST(Flow, ChokedFlowIsLinearInUpstreamPressure) {
  const double pd = 1e5;
  EXPECT_NEAR(flowPhi(8e5, pd), 2.0 * flowPhi(4e5, pd), 1e-12 * flowPhi(8e5, pd));
  // Unchoked flow is not: halving the ratio's distance from 1 does not halve the flow.
  EXPECT_GT(std::abs(flowPhi(1.2e5, pd) - 2.0 * flowPhi(1.1e5, pd)), 1e-3 * flowPhi(1.2e5, pd));
}

TEST(Flow, TableMatchesExactFunction) {
  const FlowTable& t = flowTable();
  const double beta = flowBeta();
  for (double pu = 1.01e5; pu < 7e5; pu += 3.7e3) {
    for (double pd : {1.01325e5, 3e5, 6.2e5}) {
      EXPECT_NEAR(t.phi(pu, pd), flowPhi(pu, pd), 1e-4 * beta * std::max(pu, pd)) << pu << " " << pd;
    }
  }
  // Choked: the downstream pressure has no influence.
  double d1, d2;
  t.phi(4e5, 1e5, &d1, &d2);
  EXPECT_EQ(d2, 0.0);
  // Derivative sign: more upstream pressure, more flow; more downstream, less.
  t.phi(4e5, 3e5, &d1, &d2);  // unchoked (ratio 1.33 < 1.89)
  EXPECT_GT(d1, 0);
  EXPECT_LT(d2, 0);
}

TEST(Gompertz, PortsOpenInOppositeDirectionsWithDeadZone) {
  for (int v : {1, 2}) {
    const ValveParams p = valveParams(v);
    EXPECT_LT(p.inlet(-5), p.inlet(0));
    EXPECT_LT(p.inlet(0), p.inlet(5));
    EXPECT_GT(p.exhaust(-5), p.exhaust(0));
    EXPECT_GT(p.exhaust(0), p.exhaust(5));
    // Closed ports keep their leak (offset); at full command the port is nearly fully
    // open (valve 2's inlet reaches about 96 % of a at 5 V).
    EXPECT_NEAR(p.inlet(-5), p.inlet.offset, 1e-3 * p.inlet.offset);
    EXPECT_GT(p.inlet(5), p.inlet.offset + 0.9 * p.inlet.a);
    EXPECT_GT(p.exhaust(-5), p.exhaust.offset + 0.9 * p.exhaust.a);
    // Dead zone: around 0 V both ports are mostly closed (fig. 4.4).
    EXPECT_LT(p.inlet(0) - p.inlet.offset, 0.1 * p.inlet.a);
    EXPECT_LT(p.exhaust(0) - p.exhaust.offset, 0.1 * p.exhaust.a);
  }
  EXPECT_THROW(valveParams(3), std::invalid_argument);
}

TEST(FastExp, MatchesStdExp) {
  for (double x = -700; x < 700; x += 0.731) EXPECT_NEAR(fastExp(x), std::exp(x), 1e-11 * std::exp(x)) << x;
  EXPECT_EQ(fastExp(-800), 0.0);
  EXPECT_TRUE(std::isinf(fastExp(800)));
}

TEST(Gompertz, TableMatchesExactCurve) {
  // The plant evaluates areas from GompertzTable: offset + a H_b(c (u + d)).
  for (int v : {1, 2}) {
    const ValveParams p = valveParams(v);
    for (const GompertzArea& g : {p.inlet, p.exhaust}) {
      const GompertzTable& t = gompertzTable(g.b);
      EXPECT_EQ(&t, &gompertzTable(g.b));  // shared
      for (double u = -6.0; u <= 6.0; u += 0.0137) {
        const double exact = g.offset + g.a * std::exp(-g.b * std::exp(-g.c * (u + g.d)));
        EXPECT_NEAR(g.offset + g.a * t(g.c * (u + g.d)), exact, 1e-5 * g.a) << v << " " << u;
      }
    }
  }
  EXPECT_THROW(GompertzTable(0.0), std::invalid_argument);
}
