#include <cmath>

#include <gtest/gtest.h>

#include "adroit_pneumatics/parametric_model.h"
#include "adroit_pneumatics/params_io.h"

using namespace adroit::pneumatics;

namespace {
ParametricParams sample() {
  ParametricParams p;
  p.c2 = 0.1, p.c3 = 1.8, p.c4 = 0.4, p.c5 = -0.6, p.c6 = 0.3, p.c7 = 80, p.c8 = 0.2, p.c9 = 15, p.cg = 0.15;
  return p;
}
ParametricInputs inputs() {
  ParametricInputs in;
  in.volume = 1.2e-6;
  in.volume_rate = 2e-6;  // 2 cm^3/s
  in.supply = 600e3;
  return in;
}
}  // namespace

TEST(Parametric, ExactStepMatchesFineIntegration) {
  const ParametricModel m(sample());
  for (double u : {-2.0, -0.05, 0.3, 1.5}) {
    for (double dt : {0.005, 0.05}) {
      const double exact = m.step(250e3, u, dt, inputs());
      double p = 250e3;
      const int n = 200000;
      const double h = dt / n;
      for (int k = 0; k < n; ++k) {  // RK4 on pdot
        const double k1 = m.pressureRate(p, u, inputs()), k2 = m.pressureRate(p + h / 2 * k1, u, inputs());
        const double k3 = m.pressureRate(p + h / 2 * k2, u, inputs()), k4 = m.pressureRate(p + h * k3, u, inputs());
        p += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
      }
      EXPECT_NEAR(exact, p, 1e-6 * p) << "u " << u << " dt " << dt;
    }
  }
}

TEST(Parametric, DerivativesMatchFiniteDifferences) {
  const ParametricModel m(sample());
  for (double u : {-1.5, 0.0, 0.1, 0.7}) {
    double dp, du;
    m.step(300e3, u, 0.005, inputs(), &dp, &du);
    const double h = 1e-6;
    const double fd_u = (m.step(300e3, u + h, 0.005, inputs()) - m.step(300e3, u - h, 0.005, inputs())) / (2 * h);
    const double fd_p = (m.step(300e3 + 1, u, 0.005, inputs()) - m.step(300e3 - 1, u, 0.005, inputs())) / 2;
    EXPECT_NEAR(du, fd_u, 1e-5 * std::abs(fd_u) + 1e-3);
    EXPECT_NEAR(dp, fd_p, 1e-7);
  }
}

TEST(Parametric, SteadyStateFollowsSupplyAndInverts) {
  const ParametricModel m(sample());
  ParametricInputs in = inputs();
  const double high = m.steadyState(5.0, in);
  EXPECT_GT(high, in.room + 0.9 * (in.supply - in.room));
  in.supply = 500e3;
  EXPECT_LT(m.steadyState(5.0, in), high - 80e3);  // c_b, c_s are real-time inputs
  for (double u : {-1.0, 0.0, 0.4}) EXPECT_NEAR(m.inverseSteadyState(m.steadyState(u, in), in, -2, 2), u, 1e-6);
  EXPECT_EQ(m.inverseSteadyState(1e9, in, -2, 2), 2.0);
}

TEST(Parametric, RejectsBadParameters) {
  ParametricParams p = sample();
  p.c9 = -1;
  EXPECT_THROW(ParametricModel{p}, std::invalid_argument);
  p = sample();
  p.c8 = 1.5;
  EXPECT_THROW(ParametricModel{p}, std::invalid_argument);
}

TEST(ParamsIo, RoundTripAndMalformedFieldNamed) {
  ParameterSet set;
  set.defaults = sample();
  set.cylinders["A_FFJ2_flex"] = sample();
  set.cylinders["A_FFJ2_flex"].c7 = 55;
  const ParameterSet back = parseParameterSet(formatParameterSet(set));
  EXPECT_DOUBLE_EQ(back.defaults.c4, 0.4);
  EXPECT_DOUBLE_EQ(back.forCylinder("A_FFJ2_flex").c7, 55);
  EXPECT_DOUBLE_EQ(back.forCylinder("other").c7, 80);
  auto message = [](const std::string& text) {
    try {
      parseParameterSet(text, "x.yaml");
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message("parametric:\n  default: {c2: 0, c3: 1, c4: 0, c5: 0, c6: 0, c8: 0, c9: 1, cg: 0.1}\n"),
            "x.yaml: parametric.default.c7: missing");
  EXPECT_EQ(message("parametric:\n  default: {c2: 0, c3: 1, c4: 0, c5: 0, c6: 0, c7: abc, c8: 0, c9: 1, cg: 0.1}\n"),
            "x.yaml: parametric.default.c7: expected a number");
  EXPECT_NE(message("parametric: [").find("not valid YAML"), std::string::npos);
  EXPECT_EQ(message("other: 1\n"), "x.yaml: parametric: missing");
  EXPECT_NE(message("parametric:\n  default: {c2: 0, c3: 1, c4: 0, c5: 0, c6: 0, c7: 1, c8: 0, c9: -1, cg: 0.1}\n").find("c9"),
            std::string::npos);
}

TEST(Parametric, DeadTimeStep) {
  ParametricParams prm = sample();
  const ParametricModel plain(prm);
  prm.td = 0.002;
  const ParametricModel delayed(prm);
  const double p = 250e3, w = -1.0, u = 1.2, dt = 0.005;
  // td = 0: the previous command has no effect.
  EXPECT_EQ(plain.stepDelayed(p, w, u, dt, inputs()), plain.step(p, u, dt, inputs()));
  // td = 2 ms: w for 2 ms, then u for 3 ms (two exact steps).
  const double expected = plain.step(plain.step(p, w, 0.002, inputs()), u, 0.003, inputs());
  EXPECT_NEAR(delayed.stepDelayed(p, w, u, dt, inputs()), expected, 1e-6);
  // Derivatives against central differences.
  double dp, dw, du;
  delayed.stepDelayed(p, w, u, dt, inputs(), &dp, &dw, &du);
  const double h = 1e-4, hp = 1.0;
  EXPECT_NEAR(dp, (delayed.stepDelayed(p + hp, w, u, dt, inputs()) - delayed.stepDelayed(p - hp, w, u, dt, inputs())) / (2 * hp), 1e-6);
  const double fd_w = (delayed.stepDelayed(p, w + h, u, dt, inputs()) - delayed.stepDelayed(p, w - h, u, dt, inputs())) / (2 * h);
  const double fd_u = (delayed.stepDelayed(p, w, u + h, dt, inputs()) - delayed.stepDelayed(p, w, u - h, dt, inputs())) / (2 * h);
  EXPECT_NEAR(dw, fd_w, 1e-4 * std::abs(fd_w) + 1e-2);
  EXPECT_NEAR(du, fd_u, 1e-4 * std::abs(fd_u) + 1e-2);
  // Dead time in the YAML: optional on input (0 when absent), written on output.
  ParameterSet set;
  set.defaults = prm;
  EXPECT_DOUBLE_EQ(parseParameterSet(formatParameterSet(set)).defaults.td, 0.002);
  const std::string old = "parametric:\n  default: {c2: 0, c3: 2, c4: 0.5, c5: 0, c6: 0, c7: 80, c8: 0.2, c9: 10, cg: 0.3}\n";
  EXPECT_DOUBLE_EQ(parseParameterSet(old).defaults.td, 0.0);
  prm.td = -0.001;
  EXPECT_THROW(ParametricModel{prm}, std::invalid_argument);
}
