#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <fstream>

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

// The error message of parsing text as a parameter file ("no error" if it parses).
static std::string parseMessage(const std::string& text) {
  try {
    parseParameterSet(text, "x.yaml");
  } catch (const std::runtime_error& e) {
    return std::string(e.what());
  }
  return std::string("no error");
}

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
  EXPECT_EQ(parseMessage("parametric:\n  default: {c2: 0, c3: 1, c4: 0, c5: 0, c6: 0, c8: 0, c9: 1, cg: 0.1}\n"),
            "x.yaml: parametric.default.c7: missing");
  EXPECT_EQ(parseMessage("parametric:\n  default: {c2: 0, c3: 1, c4: 0, c5: 0, c6: 0, c7: abc, c8: 0, c9: 1, cg: 0.1}\n"),
            "x.yaml: parametric.default.c7: expected a number");
  EXPECT_NE(parseMessage("parametric: [").find("not valid YAML"), std::string::npos);
  EXPECT_EQ(parseMessage("other: 1\n"), "x.yaml: parametric: missing");
  EXPECT_NE(parseMessage("parametric:\n  default: {c2: 0, c3: 1, c4: 0, c5: 0, c6: 0, c7: 1, c8: 0, c9: -1, cg: 0.1}\n").find("c9"),
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

namespace {
ParametricParams saturating() {
  ParametricParams p = sample();
  p.form = ParametricForm::kSaturating;
  p.c5 = -1.4, p.v0 = 0.05, p.c7 = 300, p.c9 = 40, p.u_sat = 4.0, p.e_fill = 150e3, p.e_exhaust = 900e3;
  return p;
}
// RK4 on pressureRate at dt / n.
double integrate(const ParametricModel& m, double p, double u, double dt, const ParametricInputs& in, int n = 200000) {
  const double h = dt / n;
  for (int k = 0; k < n; ++k) {
    const double k1 = m.pressureRate(p, u, in), k2 = m.pressureRate(p + h / 2 * k1, u, in);
    const double k3 = m.pressureRate(p + h / 2 * k2, u, in), k4 = m.pressureRate(p + h * k3, u, in);
    p += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
  }
  return p;
}
}  // namespace

TEST(Saturating, ExactStepMatchesFineIntegration) {
  const ParametricModel m(saturating());
  ParametricInputs in = inputs();
  // Fills from the room and exhausts from the supply (deep in the saturated, constant-rate
  // part), small moves near equilibrium, compression and expansion of the chamber.
  for (double vdot : {-8e-6, 0.0, 2e-6}) {
    in.volume_rate = vdot;
    for (double p0 : {101325.0, 250e3, 590e3}) {
      for (double u : {-3.0, -0.05, 0.3, 3.0}) {
        for (double dt : {0.002, 0.005, 0.05}) {
          const double exact = m.step(p0, u, dt, in);
          EXPECT_NEAR(exact, integrate(m, p0, u, dt, in, 20000), 1e-6 * p0) << "p0 " << p0 << " u " << u << " dt " << dt << " vdot " << vdot;
        }
      }
    }
  }
  // The saturation is real: a fill from the room runs slower than eq. 5.5's exponential
  // with the same k and s* would (here by more than 20 %).
  in.volume_rate = 0;
  const ParametricModel::CommandTerms t = m.terms(3.0, in);
  const double linear = t.a / t.k + (101325.0 - t.a / t.k) * std::exp(-t.k * 0.002);
  EXPECT_LT(m.step(101325.0, 3.0, 0.002, in) - 101325.0, 0.8 * (linear - 101325.0));
}

TEST(Saturating, DerivativesMatchFiniteDifferences) {
  ParametricParams prm = saturating();
  prm.td = 0.0021;
  const ParametricModel m(prm);
  ParametricInputs in = inputs();
  for (double vdot : {-8e-6, 0.0, 2e-6}) {
    in.volume_rate = vdot;
    for (double p : {101325.0, 300e3, 600e3}) {
      for (double w : {-2.0, 0.2, 3.0}) {
        for (double u : {-1.5, 0.0, 0.1, 2.5}) {
          double dp, dw, du;
          m.stepDelayed(p, w, u, 0.005, in, &dp, &dw, &du);
          const double h = 1e-5, hp = 1.0;
          const auto at = [&](double pp, double ww, double uu) { return m.stepDelayed(pp, ww, uu, 0.005, in); };
          const double fd_p = (at(p + hp, w, u) - at(p - hp, w, u)) / (2 * hp);
          const double fd_w = (at(p, w + h, u) - at(p, w - h, u)) / (2 * h);
          const double fd_u = (at(p, w, u + h) - at(p, w, u - h)) / (2 * h);
          const std::string where = "p " + std::to_string(p) + " w " + std::to_string(w) + " u " + std::to_string(u);
          EXPECT_NEAR(dp, fd_p, 1e-6) << where;
          EXPECT_NEAR(dw, fd_w, 1e-4 * std::abs(fd_w) + 1.0) << where;
          EXPECT_NEAR(du, fd_u, 1e-4 * std::abs(fd_u) + 1.0) << where;
        }
      }
    }
  }
  // At equilibrium (x0 = 0) the step stays there and d/dp is the linear decay.
  in.volume_rate = 0;
  const ParametricModel::CommandTerms t = m.terms(0.4, in);
  double dp;
  EXPECT_DOUBLE_EQ(m.advance(t.a / t.k, t, 0.005, &dp), t.a / t.k);
  EXPECT_NEAR(dp, std::exp(-t.k * 0.005), 1e-12);
}

TEST(Saturating, IsEq55WithoutSaturation) {
  // eq. 5.5 with tau = 1 + c6 v maps exactly onto the saturating form with v0 = 1/c6 and
  // c5, c7, c9 divided by 1 + c6; e_fill, e_exhaust, u_sat -> infinity leave the rest.
  ParametricParams eq55 = sample();
  eq55.c6 = 2.5;
  const ParametricModel a(eq55), b(saturatingFromEq55(eq55, 1e15, 1e15, 1e15));
  ParametricInputs in = inputs();
  for (double v : {0.3e-6, 1.2e-6, 2.2e-6}) {
    in.volume = v;
    for (double p : {101325.0, 400e3})
      for (double u : {-2.0, 0.0, 1.0}) EXPECT_NEAR(b.step(p, u, 0.005, in), a.step(p, u, 0.005, in), 1e-6 * p);
  }
  // With finite saturation they differ.
  const ParametricModel c(saturatingFromEq55(eq55, 100e3, 1e6, 3.0));
  EXPECT_GT(std::abs(c.step(101325.0, 2.0, 0.005, in) - a.step(101325.0, 2.0, 0.005, in)), 1e3);
}

TEST(Saturating, StaysFiniteWhenCompressionDominates) {
  // A piston compressing the chamber faster than the valve acts: k is floored, the step
  // stays finite and continuous in vdot.
  const ParametricModel m(saturating());
  ParametricInputs in = inputs();
  double last = std::nan("");
  for (double vdot = -1e-4; vdot <= 0; vdot += 1e-6) {
    in.volume_rate = vdot;
    double dp, du;
    const double p = m.step(300e3, 0.0, 0.005, in, &dp, &du);
    ASSERT_TRUE(std::isfinite(p) && std::isfinite(dp) && std::isfinite(du)) << vdot;
    if (std::isfinite(last)) {
      ASSERT_LT(std::abs(p - last), 5e3) << vdot;
    }
    last = p;
  }
  // Zero volume (a missing length reading) with the smallest v0: finite.
  ParametricParams prm = saturating();
  prm.v0 = 1e-6;
  in.volume = 0, in.volume_rate = 0;
  EXPECT_TRUE(std::isfinite(ParametricModel(prm).step(300e3, 1.0, 0.005, in)));
}

TEST(Saturating, RejectsBadParametersNamingThem) {
  const auto message = [](ParametricParams p) {
    try {
      ParametricModel{p};
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  ParametricParams p = saturating();
  p.e_fill = 0;
  EXPECT_NE(message(p).find("e_fill"), std::string::npos);
  p = saturating();
  p.v0 = -0.1;
  EXPECT_NE(message(p).find("v0"), std::string::npos);
  p = saturating();
  p.u_sat = std::nan("");
  EXPECT_EQ(message(p), "parametric model: u_sat is not finite");
  // The eq. 5.5 form ignores the saturating form's fields.
  p.form = ParametricForm::kEq55;
  EXPECT_EQ(message(p), "parametric model: u_sat is not finite");  // but never a NaN
  p.u_sat = -1;
  EXPECT_EQ(message(p), "no error");
}

TEST(ParamsIo, SaturatingFormRoundTripAndFieldErrors) {
  ParameterSet set;
  set.defaults = saturating();
  set.defaults.td = 0.0021;
  set.cylinders["A_WRJ1_flex"] = sample();  // forms mix per cylinder
  const ParameterSet back = parseParameterSet(formatParameterSet(set));
  EXPECT_EQ(back.defaults.form, ParametricForm::kSaturating);
  EXPECT_DOUBLE_EQ(back.defaults.e_fill, 150e3);
  EXPECT_DOUBLE_EQ(back.defaults.v0, 0.05);
  EXPECT_DOUBLE_EQ(back.defaults.td, 0.0021);
  EXPECT_EQ(back.forCylinder("A_WRJ1_flex").form, ParametricForm::kEq55);
  const std::string full =
      "form: saturating, c2: 0, c3: 2, c4: 0.5, c5: -1.4, v0: 0.01, c7: 300, c8: 0.4, c9: 40, cg: 0.2, u_sat: 4, "
      "e_fill: 150000, e_exhaust: 1000000, td: 0.002";
  EXPECT_EQ(parseMessage("parametric:\n  default: {" + full + "}\n"), "no error");
  // Every field of the saturating form is required (td too), and each is named.
  for (const char* field : {"c5", "v0", "c7", "u_sat", "e_fill", "e_exhaust", "td"}) {
    std::string text = full;
    const std::size_t at = text.find(std::string(", ") + field + ":");
    const std::size_t end = text.find(',', at + 2);
    text.erase(at, end - at);
    EXPECT_EQ(parseMessage("parametric:\n  default: {" + text + "}\n"), std::string("x.yaml: parametric.default.") + field + ": missing");
  }
  std::string nan = full;
  nan.replace(nan.find("e_fill: 150000"), 14, "e_fill: .nan");
  EXPECT_EQ(parseMessage("parametric:\n  default: {" + nan + "}\n"), "x.yaml: parametric.default.e_fill: not finite");
  std::string inf = full;
  inf.replace(inf.find("v0: 0.01"), 8, "v0: .inf");
  EXPECT_EQ(parseMessage("parametric:\n  default: {" + inf + "}\n"), "x.yaml: parametric.default.v0: not finite");
  EXPECT_EQ(parseMessage("parametric:\n  default: {" + full + ", c6: 1}\n").rfind("x.yaml: parametric.default.c6: ", 0), 0u);
  EXPECT_EQ(parseMessage("parametric:\n  default: {form: lambert, c2: 0}\n"),
            "x.yaml: parametric.default.form: expected eq5.5 or saturating");
  // Eq. 5.5 files without a form (all files before it existed) load as before.
  EXPECT_EQ(parseParameterSet("parametric:\n  default: {c2: 0, c3: 2, c4: 0.5, c5: 0, c6: 0, c7: 80, c8: 0.2, c9: 10, "
                              "cg: 0.3}\n").defaults.form, ParametricForm::kEq55);
}

// A parameter file named in a pool's parameters is read only if it is a regular file within
// 1 MB: a FIFO would block the pool's start for good, a device or huge log read without end.
TEST(ParamsIo, ParameterFileMustBeASmallRegularFile) {
  const std::string dir = testing::TempDir() + "/params_io_" + std::to_string(getpid());
  mkdir(dir.c_str(), 0700);
  const std::string fifo = dir + "/fifo.yaml", big = dir + "/big.yaml";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  std::ofstream(big) << "# " << std::string(2 * 1024 * 1024, 'x') << "\n";
  const auto error = [](const std::string& path) {
    try {
      loadParameterSet(path);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(error(fifo), fifo + ": not a regular file (a FIFO)");
  EXPECT_EQ(error(dir), dir + ": not a regular file (a directory)");
  EXPECT_EQ(error(big), big + ": 2 MB, over the limit of 1 MB");
  unlink(fifo.c_str());
  unlink(big.c_str());
  rmdir(dir.c_str());
}
