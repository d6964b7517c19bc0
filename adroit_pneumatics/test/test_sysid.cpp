#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "adroit_pneumatics/excitation.h"
#include "adroit_pneumatics/sysid.h"

using namespace adroit::pneumatics;

namespace {
// Noise-free data of model m under an excitation; moving: the piston pumps the volume at
// 1.3 Hz (the volume rate is its derivative), else a fixed volume. The model's dead time
// applies (the previous sample's command for its first td).
Recording generate(const ParametricModel& m, const std::string& kind, double seconds, std::uint64_t seed,
                   bool moving = false) {
  ExcitationParams e;
  e.kind = kind;
  e.seed = seed;
  e.sweep_period = 20.0;
  Excitation ex(e);
  Recording r;
  r.dt = 0.005;
  const double w_pump = 2 * 3.14159265 * 1.3;
  double p = 101325, w = 0.0;
  for (int k = 0; k < static_cast<int>(seconds / r.dt); ++k) {
    const double t = k * r.dt, u = ex.next(t, r.dt);
    r.volts.push_back(u);
    r.pressure.push_back(p);
    r.volume.push_back(moving ? 1.3e-6 + 0.9e-6 * std::sin(w_pump * t) : 1.5e-6);
    r.volume_rate.push_back(moving ? 0.9e-6 * w_pump * std::cos(w_pump * t) : 0.0);
    r.supply.push_back(620e3 - 10e3 * std::sin(0.3 * t));
    p = m.stepDelayed(p, k ? w : u, u, r.dt, r.inputs(r.size() - 1));
    w = u;
  }
  return r;
}
}  // namespace

TEST(Lm, FitsAnExponential) {
  auto res = [](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    r.resize(50);
    for (int i = 0; i < 50; ++i) r[i] = x[0] * std::exp(-x[1] * i * 0.1) - 3.0 * std::exp(-0.7 * i * 0.1);
  };
  const LmResult out = levenbergMarquardt(res, Eigen::Vector2d(1.0, 0.1));
  EXPECT_NEAR(out.x[0], 3.0, 1e-6);
  EXPECT_NEAR(out.x[1], 0.7, 1e-6);
}

TEST(Sysid, RecoversParametricModelFromNoiseFreeData) {
  ParametricParams truth;
  truth.c2 = 0.12, truth.c3 = 2.5, truth.c4 = 0.3, truth.c7 = 70, truth.c8 = 0.15, truth.c9 = 12, truth.cg = 0.25;
  const ParametricModel m(truth);
  const Recording sweep = generate(m, "sweep", 40.0, 1);
  const Recording random = generate(m, "random", 30.0, 2);
  const FitReport rep = fitParametricModel(sweep, random, false);
  EXPECT_NEAR(rep.params.c2, truth.c2, 0.02);
  EXPECT_NEAR(rep.params.c7, truth.c7, 0.05 * truth.c7);
  EXPECT_NEAR(rep.params.c9, truth.c9, 0.05 * truth.c9);
  const Recording test = generate(m, "random", 20.0, 3);
  EXPECT_LT(predictionRmse(test, ParametricModel(rep.params)).percent, 0.5);
}

TEST(Sysid, CsvRoundTripAndErrors) {
  Recording r;
  r.dt = 0.005;
  for (int k = 0; k < 10; ++k) {
    r.volts.push_back(0.1 * k);
    r.pressure.push_back(1e5 + k);
    r.volume.push_back(1e-6);
    r.volume_rate.push_back(0);
    r.supply.push_back(6e5);
  }
  const std::string path = testing::TempDir() + "/rec.csv";
  writeRecordingCsv(path, r);
  const Recording back = readRecordingCsv(path);
  EXPECT_EQ(back.size(), 10u);
  EXPECT_NEAR(back.dt, 0.005, 1e-9);
  EXPECT_DOUBLE_EQ(back.pressure[3], 1e5 + 3);
  {
    FILE* f = std::fopen(path.c_str(), "w");
    std::fputs("t,volts,pressure,volume,volume_rate,supply\n0,1,2,3,4,5\n0.005,1,x,3,4,5\n", f);
    std::fclose(f);
  }
  try {
    readRecordingCsv(path);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(":3:"), std::string::npos) << e.what();
  }
}

TEST(Excitation, StaysInRangeAndRejectsUnknownKind) {
  for (const char* kind : {"steps", "sweep", "random", "chirp"}) {
    ExcitationParams p;
    p.kind = kind;
    Excitation e(p);
    for (int k = 0; k < 4000; ++k) {
      const double u = e.next(k * 0.005, 0.005);
      ASSERT_LE(std::abs(u), p.amplitude + 1e-12) << kind;
    }
  }
  ExcitationParams bad;
  bad.kind = "noise";
  EXPECT_THROW(Excitation{bad}, std::invalid_argument);
}

TEST(Sysid, RecoversDeadTime) {
  // Noise-free data from a model with a 2 ms input dead time (the tube delay).
  ParametricParams truth;
  truth.c2 = 0.05, truth.c3 = 2.5, truth.c4 = 0.3, truth.c7 = 70, truth.c8 = 0.15, truth.c9 = 12, truth.cg = 0.25;
  truth.td = 0.002;
  const ParametricModel m(truth);
  const FitReport rep = fitParametricModel(generate(m, "sweep", 40.0, 1), generate(m, "random", 20.0, 2), FitOptions{});
  EXPECT_NEAR(rep.params.td, 0.002, 0.0002);
  EXPECT_LT(predictionRmse(generate(m, "random", 10.0, 3), ParametricModel(rep.params)).percent, 0.5);
}

TEST(Sysid, RecoversSaturatingModelFromItsOwnData) {
  // Noise-free data of the saturating form on a moving piston (volume and volume rate
  // vary), with a dead time; the fit starts from eq. 5.5 as the bench's does.
  ParametricParams truth;
  truth.form = ParametricForm::kSaturating;
  truth.c2 = 0.05, truth.c3 = 2.5, truth.c4 = 0.3, truth.c5 = -1.4, truth.v0 = 0.05, truth.c7 = 250, truth.c8 = 0.3;
  truth.c9 = 40, truth.cg = 0.25, truth.u_sat = 4.0, truth.e_fill = 150e3, truth.e_exhaust = 900e3, truth.td = 0.002;
  const ParametricModel m(truth);
  FitOptions o;
  o.form = ParametricForm::kSaturating;
  o.fit_volume = true;
  const FitReport rep = fitParametricModel(generate(m, "sweep", 40.0, 1), generate(m, "random", 30.0, 2, true), o);
  const ParametricParams& q = rep.params;
  ASSERT_EQ(q.form, ParametricForm::kSaturating);
  EXPECT_NEAR(q.td, truth.td, 0.0001);
  EXPECT_NEAR(q.c5, truth.c5, 0.05 * std::abs(truth.c5));
  EXPECT_NEAR(q.c7, truth.c7, 0.05 * truth.c7);
  EXPECT_NEAR(q.c9, truth.c9, 0.05 * truth.c9);
  EXPECT_NEAR(q.u_sat, truth.u_sat, 0.1 * truth.u_sat);
  EXPECT_NEAR(q.e_fill, truth.e_fill, 0.05 * truth.e_fill);
  EXPECT_NEAR(q.v0, truth.v0, 0.02);
  EXPECT_LT(predictionRmse(generate(m, "random", 10.0, 3, true), ParametricModel(q)).percent, 0.2);
}

// A recording path from the command line is read only if it is a regular file: a FIFO would
// block the identification for good, a device read without end.
TEST(Sysid, RecordingFromAFifoOrDeviceIsRefusedWithoutReading) {
  const std::string fifo = testing::TempDir() + "/rec_fifo_" + std::to_string(getpid());
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& path : {fifo, std::string("/dev/zero"), testing::TempDir()}) {
    try {
      readRecordingCsv(path);
      ADD_FAILURE() << path << " was read";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(path + ": not a regular file"), std::string::npos) << e.what();
    }
  }
  unlink(fifo.c_str());
}
