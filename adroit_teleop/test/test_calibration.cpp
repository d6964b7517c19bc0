// Glove calibration: the ridge fit recovers a known affine map from noisy samples within a
// tolerance derived from the noise; masks, defaults and clamping; the YAML file round-trips
// exactly and every kind of malformed file is refused with the file named.
#include <adroit_teleop/calibration.h>
#include <gtest/gtest.h>
#include <stdlib.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>

#include "temp_dir.h"
#include "unreadable_files.h"

using namespace adroit::teleop;

namespace {

std::vector<std::string> names(int J) {
  std::vector<std::string> n;
  for (int j = 0; j < J; ++j) n.push_back("J" + std::to_string(j));
  return n;
}

std::vector<JointRange> wide(int J) { return std::vector<JointRange>(J, JointRange{-100, 100}); }

using adroit::teleop::test::scratchDir;

std::string tempPath(const std::string& name) { return scratchDir() + "/" + name; }

std::string writeTemp(const std::string& name, const std::string& text) {
  const std::string path = tempPath(name);
  std::ofstream(path) << text;
  return path;
}

std::string loadError(const std::string& text) {
  const std::string path = writeTemp("bad_cal.yaml", text);
  try {
    loadCalibration(path);
  } catch (const CalibrationError& e) {
    return e.what();
  }
  return "";
}

// A valid file for 2 sensors and 2 joints, to be broken one key at a time.
const std::string kGood =
    "version: 1\n"
    "created: \"2024-01-01T00:00:00Z\"\n"
    "note: \"test\"\n"
    "sensors: 2\n"
    "lambda: 0.0001\n"
    "joints: [A, B]\n"
    "ranges: [[-1, 1], [0, 2]]\n"
    "W: [[1, 2], [3, 4]]\n"
    "b: [0.5, 0.25]\n"
    "residual_rms: [0.01, 0.02]\n"
    "fit_samples: [10, 0]\n";

std::string replaceLine(const std::string& text, const std::string& key, const std::string& line) {
  return std::regex_replace(text, std::regex("(^|\n)" + key + ":[^\n]*\n"), "$1" + line);
}

}  // namespace

TEST(GloveCalibration, DefaultMapAndClamping) {
  GloveCalibration cal(3, {"a", "b"}, {{-1, 1}, {0.2, 0.5}});
  // Default: every joint at 0, or at the range's nearer end when 0 is outside it.
  const Eigen::VectorXd q0 = cal.apply(Eigen::Vector3d(0.3, 0.6, 0.9));
  EXPECT_DOUBLE_EQ(q0[0], 0.0);
  EXPECT_DOUBLE_EQ(q0[1], 0.2);
  Eigen::MatrixXd W(2, 3);
  W << 1, 0, 0,  //
      0, 2, 0;
  cal.setMap(W, Eigen::Vector2d(0.1, -1.0));
  const Eigen::VectorXd q = cal.apply(Eigen::Vector3d(0.5, 0.7, 0.0));
  EXPECT_DOUBLE_EQ(q[0], 0.6);  // 0.5 + 0.1, inside [-1, 1]
  EXPECT_DOUBLE_EQ(q[1], 0.4);  // 1.4 - 1.0, inside [0.2, 0.5]
  const Eigen::VectorXd qc = cal.apply(Eigen::Vector3d(2.0, 0.1, 0.0));
  EXPECT_DOUBLE_EQ(qc[0], 1.0);  // 2.1 clamped
  EXPECT_DOUBLE_EQ(qc[1], 0.2);  // -0.8 clamped
  EXPECT_THROW(cal.setMap(Eigen::MatrixXd::Zero(2, 2), Eigen::Vector2d::Zero()), CalibrationError);
  W(0, 0) = NAN;
  EXPECT_THROW(cal.setMap(W, Eigen::Vector2d::Zero()), CalibrationError);
  EXPECT_THROW(GloveCalibration(3, {"a", "a"}, {{0, 1}, {0, 1}}), CalibrationError);
  EXPECT_THROW(GloveCalibration(3, {"a"}, {{1, 0}}), CalibrationError);
  EXPECT_THROW(GloveCalibration(3, {"a"}, {}), CalibrationError);
}

TEST(GloveCalibration, FitRecoversAKnownMapWithinTheNoise) {
  const int N = 22, J = 6, K = 2000;
  const double sigma = 0.01;  // joint-angle noise of the targets, rad
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1), s_dist(0.05, 0.95);
  std::normal_distribution<double> noise(0, sigma);
  Eigen::MatrixXd W_true(J, N);
  Eigen::VectorXd b_true(J);
  for (int j = 0; j < J; ++j) {
    b_true[j] = u(rng);
    for (int i = 0; i < N; ++i) W_true(j, i) = u(rng);
  }
  std::vector<CalibrationSample> samples;
  for (int k = 0; k < K; ++k) {
    CalibrationSample x;
    x.sensors.resize(N);
    for (int i = 0; i < N; ++i) x.sensors[i] = s_dist(rng);
    x.joints = W_true * x.sensors + b_true;
    for (int j = 0; j < J; ++j) x.joints[j] += noise(rng);
    samples.push_back(x);
  }
  const GloveCalibration cal = fitCalibration(N, names(J), wide(J), samples);

  // Tolerance from the noise: least squares estimates a weight with standard deviation
  // sigma / sqrt(K var_s), var_s = 0.9^2 / 12 the variance of a uniform sensor value; allow 5
  // of them. The ridge term shrinks each weight by at most lambda / (var_s + lambda) of itself.
  const double var_s = 0.9 * 0.9 / 12;
  const double w_sd = sigma / std::sqrt(K * var_s);
  const double shrink = kDefaultRidgeLambda / (var_s + kDefaultRidgeLambda);
  const double w_tol = 5 * w_sd + shrink * W_true.cwiseAbs().maxCoeff();
  EXPECT_LT((cal.W() - W_true).cwiseAbs().maxCoeff(), w_tol);
  EXPECT_GT(w_tol, 0.001);  // the tolerance is not absurdly tight...
  EXPECT_LT(w_tol, 0.01);   // ...nor loose against weights of size ~0.5

  // Predictions at new points: the noise term of a prediction is sigma sqrt((N + 1) / K),
  // allow 5 of them, plus the shrinkage applied to the centred sensor values.
  double worst = 0, bias_bound = 0;
  for (int t = 0; t < 200; ++t) {
    Eigen::VectorXd s(N);
    for (int i = 0; i < N; ++i) s[i] = s_dist(rng);
    const Eigen::VectorXd truth = W_true * s + b_true;
    worst = std::max(worst, (cal.apply(s) - truth).cwiseAbs().maxCoeff());
    bias_bound = std::max(bias_bound, shrink * (W_true * (s - Eigen::VectorXd::Constant(N, 0.5))).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 5 * sigma * std::sqrt((N + 1.0) / K) + bias_bound);

  // The residual is the noise itself: its RMS estimate from K samples is good to ~1/sqrt(2K).
  for (int j = 0; j < J; ++j) {
    EXPECT_NEAR(cal.residual_rms[j], sigma, 0.1 * sigma) << j;
    EXPECT_EQ(cal.fit_samples[j], K);
  }
  EXPECT_DOUBLE_EQ(cal.lambda, kDefaultRidgeLambda);
}

TEST(GloveCalibration, MaskedSamplesAndUnconstrainedJoints) {
  // Joint 0 follows sensor 0 exactly, but only half the samples constrain it; in the others
  // its target is absurd and must be ignored. Joint 1 is constrained by nothing.
  const int N = 3, J = 2;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> s_dist(0.1, 0.9);
  std::vector<CalibrationSample> samples;
  for (int k = 0; k < 200; ++k) {
    CalibrationSample x;
    x.sensors = Eigen::Vector3d(s_dist(rng), s_dist(rng), s_dist(rng));
    const bool constrains = k % 2 == 0;
    x.joints = Eigen::Vector2d(constrains ? 2 * x.sensors[0] - 0.3 : 99.0, 55.0);
    x.constrained = {constrains, false};
    samples.push_back(x);
  }
  const GloveCalibration cal = fitCalibration(N, names(J), {{-5, 5}, {0.1, 1}}, samples);
  EXPECT_EQ(cal.fit_samples[0], 100);
  EXPECT_EQ(cal.fit_samples[1], 0);
  EXPECT_NEAR(cal.W()(0, 0), 2.0, 0.01);  // no noise: only the ridge shrinkage (< 0.2 %)
  EXPECT_NEAR(cal.W()(0, 1), 0.0, 0.01);
  EXPECT_NEAR(cal.b()[0], -0.3, 0.01);
  EXPECT_LT(cal.residual_rms[0], 0.01);
  // Unconstrained: zero row, offset 0 clamped into [0.1, 1].
  EXPECT_EQ(cal.W().row(1).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_DOUBLE_EQ(cal.b()[1], 0.1);
  EXPECT_EQ(cal.residual_rms[1], 0.0);
}

TEST(GloveCalibration, FewPosesManySensorsStillFitsThePoses) {
  // 4 poses held with a 22-sensor glove: far fewer distinct samples than unknowns, which
  // plain least squares cannot solve; the ridge fit reproduces the poses.
  const int N = 22, J = 3;
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> u(0.1, 0.9);
  std::normal_distribution<double> jitter(0, 1.0 / 255);  // one sensor step
  std::vector<Eigen::VectorXd> pose_sensors;
  const std::vector<Eigen::Vector3d> pose_targets = {{0, 0, 0}, {1.2, 0, 0.3}, {0, 1.4, 0}, {0.5, 0.5, 1.0}};
  for (int p = 0; p < 4; ++p) {
    Eigen::VectorXd s(N);
    for (int i = 0; i < N; ++i) s[i] = u(rng);
    pose_sensors.push_back(s);
  }
  std::vector<CalibrationSample> samples;
  for (int p = 0; p < 4; ++p)
    for (int k = 0; k < 50; ++k) {
      Eigen::VectorXd s = pose_sensors[p];
      for (int i = 0; i < N; ++i) s[i] += jitter(rng);
      samples.push_back({s, pose_targets[p], {}});
    }
  EXPECT_THROW(fitCalibration(N, names(J), wide(J), {samples[0], samples[50], samples[100]}, 0.0), CalibrationError);
  const GloveCalibration cal = fitCalibration(N, names(J), wide(J), samples);
  ASSERT_TRUE(cal.W().allFinite());
  for (int p = 0; p < 4; ++p)
    EXPECT_LT((cal.apply(pose_sensors[p]) - pose_targets[p]).cwiseAbs().maxCoeff(), 0.02) << "pose " << p;
}

TEST(GloveCalibration, FitRefusesBadSamples) {
  std::vector<CalibrationSample> samples = {{Eigen::Vector2d(0.1, 0.2), Eigen::Vector2d(0, 0), {}}};
  EXPECT_THROW(fitCalibration(3, names(2), wide(2), samples), CalibrationError);  // 2 sensor values, 3 expected
  EXPECT_THROW(fitCalibration(2, names(3), wide(3), samples), CalibrationError);  // 2 joints, 3 expected
  samples[0].constrained = {true};
  EXPECT_THROW(fitCalibration(2, names(2), wide(2), samples), CalibrationError);  // mask size
  samples[0].constrained = {};
  samples[0].sensors[1] = INFINITY;
  EXPECT_THROW(fitCalibration(2, names(2), wide(2), samples), CalibrationError);
  samples[0].sensors[1] = 0.2;
  EXPECT_THROW(fitCalibration(2, names(2), wide(2), samples, -1.0), CalibrationError);
}

TEST(GloveCalibration, YamlRoundTripIsExact) {
  const int N = 4, J = 3;
  GloveCalibration cal(N, {"WRJ1", "FFJ2", "THJ0"}, {{-0.524, 0.175}, {0, 1.571}, {-1.571, 0}});
  Eigen::MatrixXd W(J, N);
  W << 0.1, -2.5e-7, 3.0 / 7, 1e10,  //
      -0.3333333333333333, 0, 5, 6,  //
      7, 8, -9, 1.0 / 3;
  cal.setMap(W, Eigen::Vector3d(0.2, -0.1, 1.0 / 9));
  cal.residual_rms = Eigen::Vector3d(0.012, 0.0, 1.0 / 11);
  cal.fit_samples = {300, 0, 1};
  cal.lambda = 1e-4;
  cal.created = "2024-05-01T12:00:00Z";
  cal.note = "left glove #2: \"Alice\", after a re-strap\nsecond line";
  const std::string path = tempPath("cal.yaml");
  saveCalibration(path, cal);
  const GloveCalibration back = loadCalibration(path);
  EXPECT_EQ(back.sensors(), N);
  EXPECT_EQ(back.jointNames(), cal.jointNames());
  for (int j = 0; j < J; ++j) {
    EXPECT_EQ(back.ranges()[j].lo, cal.ranges()[j].lo);
    EXPECT_EQ(back.ranges()[j].hi, cal.ranges()[j].hi);
  }
  EXPECT_EQ(back.W(), cal.W());  // bit for bit
  EXPECT_EQ(back.b(), cal.b());
  EXPECT_EQ(back.residual_rms, cal.residual_rms);
  EXPECT_EQ(back.fit_samples, cal.fit_samples);
  EXPECT_EQ(back.lambda, cal.lambda);
  EXPECT_EQ(back.created, cal.created);
  EXPECT_EQ(back.note, cal.note);
  EXPECT_THROW(saveCalibration("/nonexistent/dir/cal.yaml", cal), CalibrationError);
}

TEST(GloveCalibration, MalformedFilesNameTheFileAndTheProblem) {
  ASSERT_EQ(loadError(kGood), "");  // the base file is valid
  const std::string prefix = tempPath("bad_cal.yaml") + ": ";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {replaceLine(kGood, "W", ""), "W: missing"},
      {replaceLine(kGood, "version", ""), "version: missing"},
      {replaceLine(kGood, "version", "version: 2\n"), "version: unknown version 2 (this build reads 1)"},
      {replaceLine(kGood, "W", "W: [[1, 2], [3, 4], [5, 6]]\n"), "W: expected 2 entries, got 3"},
      {replaceLine(kGood, "W", "W: [[1, 2], [3]]\n"), "W[1]: expected 2 entries, got 1"},
      {replaceLine(kGood, "W", "W: [[1, .nan], [3, 4]]\n"), "W[0][1]: not finite"},
      {replaceLine(kGood, "W", "W: [[1, x], [3, 4]]\n"), "W[0][1]: expected a number, got 'x'"},
      {replaceLine(kGood, "b", "b: [1, .inf]\n"), "b[1]: not finite"},
      {replaceLine(kGood, "b", "b: [1]\n"), "b: expected 2 entries, got 1"},
      {replaceLine(kGood, "sensors", "sensors: 2.5\n"), "sensors: expected an integer, got '2.5'"},
      {replaceLine(kGood, "sensors", "sensors: 0\n"), "sensors: must be >= 1"},
      {replaceLine(kGood, "joints", "joints: [A, A]\n"), "joints: joint 'A' listed twice"},
      {replaceLine(kGood, "joints", "joints: []\n"), "joints: expected a non-empty list of joint names"},
      {replaceLine(kGood, "ranges", "ranges: [[1, -1], [0, 2]]\n"), "ranges[0]: lower limit above upper limit"},
      {replaceLine(kGood, "residual_rms", "residual_rms: [0.1, -0.1]\n"), "residual_rms: negative entry"},
      {replaceLine(kGood, "fit_samples", "fit_samples: [1]\n"), "fit_samples: expected 2 entries, got 1"},
      {replaceLine(kGood, "created", ""), "created: missing"},
      {kGood + "wieght: 1\n", "wieght: unknown key"},
      {"{{{", "not valid YAML"},
      {"- 1\n- 2\n", "expected a map of keys"},
  };
  for (const auto& [text, problem] : cases) {
    const std::string e = loadError(text);
    EXPECT_EQ(e.rfind(prefix, 0), 0u) << "message does not start with the file: " << e;
    EXPECT_NE(e.find(problem), std::string::npos) << "expected '" << problem << "' in: " << e;
  }
  try {
    loadCalibration("/nonexistent/cal.yaml");
    FAIL() << "no error";
  } catch (const CalibrationError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("/nonexistent/cal.yaml: cannot open", 0), 0u) << e.what();
  }
}

// A calibration path comes from a parameter or a service request: only a regular file of
// bounded size is read, and anything else is one error naming the file, without blocking.
TEST(GloveCalibration, OnlyRegularFilesOfBoundedSizeAreRead) {
  using test::errorWithin;
  const std::string fifo = test::makeFifo(tempPath("cal_fifo.yaml"));
  std::string e = errorWithin<CalibrationError>([&] { loadCalibration(fifo); }, fifo);
  EXPECT_EQ(e, fifo + ": not a regular file (a FIFO)");
  e = errorWithin<CalibrationError>([&] { readCalibrationText(fifo); }, fifo);  // the node's metadata read
  EXPECT_EQ(e, fifo + ": not a regular file (a FIFO)");
  e = errorWithin<CalibrationError>([&] { loadCalibration(scratchDir()); }, fifo);
  EXPECT_EQ(e, scratchDir() + ": not a regular file (a directory)");
  e = errorWithin<CalibrationError>([&] { loadCalibration("/dev/zero"); }, fifo);
  EXPECT_EQ(e, "/dev/zero: not a regular file (a character device)");

  const std::string big = test::makeSparseFile(tempPath("big_cal.yaml"), kMaxCalibrationFileBytes + 1);
  e = errorWithin<CalibrationError>([&] { loadCalibration(big); }, fifo);
  EXPECT_EQ(e.rfind(big + ": ", 0), 0u) << e;
  EXPECT_NE(e.find("over the limit of 1 MB"), std::string::npos) << e;
  // A valid file right at the limit still loads (comments fill it up).
  std::string padded = kGood;
  while (padded.size() < kMaxCalibrationFileBytes) padded += std::string(std::min<std::size_t>(
      99, kMaxCalibrationFileBytes - padded.size() - 1), '#') + "\n";
  ASSERT_EQ(padded.size(), kMaxCalibrationFileBytes);
  EXPECT_EQ(loadError(padded), "");
}

TEST(GloveCalibration, ParseNamesTheFileItWasReadFrom) {
  const GloveCalibration cal = parseCalibration("mem.yaml", kGood);
  EXPECT_EQ(cal.sensors(), 2);
  try {
    parseCalibration("mem.yaml", "{{{");
    FAIL() << "no error";
  } catch (const CalibrationError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("mem.yaml: not valid YAML", 0), 0u) << e.what();
  }
}
