// Calibration poses: the shipped pose file fits the real hand model (names, ranges, the
// DIP-PIP coupling tendons, pinches whose fingertips meet), a calibration fitted on it
// reproduces the poses, and bad pose files are refused with the file and the problem named.
#include <adroit_core/mujoco_model.h>
#include <adroit_teleop/calibration.h>
#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <set>

#include "temp_dir.h"
#include "unreadable_files.h"

using namespace adroit::teleop;

namespace {

struct HandModel {
  adroit::LoadedModel loaded = adroit::loadModelFile(std::string(ADROIT_MJCF_DIR) + "/hand.xml");
  const mjModel* m = loaded.model.get();
};

const HandModel& hand() {
  static const HandModel model;
  return model;
}

// qpos of the model with the pose's targets (other joints at 0).
adroit::DataPtr poseData(const CalibrationPoseSet& set, const CalibrationPose& pose) {
  const mjModel* m = hand().m;
  adroit::DataPtr d = adroit::makeData(m);
  for (std::size_t j = 0; j < set.joints.size(); ++j) {
    const int id = mj_name2id(m, mjOBJ_JOINT, set.joints[j].c_str());
    d->qpos[m->jnt_qposadr[id]] = pose.targets[j];
  }
  mj_kinematics(m, d.get());
  return d;
}

double siteDistance(const mjModel* m, const mjData* d, const char* a, const char* b) {
  const int i = mj_name2id(m, mjOBJ_SITE, a), k = mj_name2id(m, mjOBJ_SITE, b);
  EXPECT_GE(i, 0) << a;
  EXPECT_GE(k, 0) << b;
  if (i < 0 || k < 0) return 1e9;
  return std::sqrt(std::pow(d->site_xpos[3 * i] - d->site_xpos[3 * k], 2) +
                   std::pow(d->site_xpos[3 * i + 1] - d->site_xpos[3 * k + 1], 2) +
                   std::pow(d->site_xpos[3 * i + 2] - d->site_xpos[3 * k + 2], 2));
}

const CalibrationPose& poseNamed(const CalibrationPoseSet& set, const std::string& name) {
  for (const auto& p : set.poses)
    if (p.name == name) return p;
  throw std::runtime_error("no pose " + name);
}

using adroit::teleop::test::scratchDir;

std::string posesPath() { return scratchDir() + "/poses.yaml"; }

std::string writeTemp(const std::string& text) {
  const std::string path = posesPath();
  std::ofstream(path) << text;
  return path;
}

const std::map<std::string, JointRange> kKnown = {
    {"FFJ2", {0, 1.571}}, {"FFJ1", {0, 1.571}}, {"WRJ1", {-0.524, 0.175}}, {"POS", {0.1, 0.5}}};

std::string poseError(const std::string& text) {
  try {
    loadCalibrationPoses(writeTemp(text), kKnown);
  } catch (const CalibrationError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(CalibrationPoses, ShippedFileMatchesTheHandModel) {
  const auto ranges = jointRangesFromModel(hand().m);
  const CalibrationPoseSet set = loadCalibrationPoses(POSE_FILE, ranges);
  // Every limited joint of the hand model, each once: the 24 ADROIT hand joints.
  EXPECT_EQ(set.joints.size(), 24u);
  EXPECT_EQ(std::set<std::string>(set.joints.begin(), set.joints.end()).size(), 24u);
  for (const auto& [name, range] : ranges)
    EXPECT_NE(std::find(set.joints.begin(), set.joints.end(), name), set.joints.end()) << name << " missing";
  EXPECT_GE(set.poses.size(), 8u);
  EXPECT_LE(set.poses.size(), 12u);
  // Inside the model's ranges, checked here against the model directly.
  const mjModel* m = hand().m;
  for (const CalibrationPose& pose : set.poses) {
    EXPECT_FALSE(pose.instruction.empty()) << pose.name;
    for (std::size_t j = 0; j < set.joints.size(); ++j) {
      const int id = mj_name2id(m, mjOBJ_JOINT, set.joints[j].c_str());
      ASSERT_GE(id, 0);
      EXPECT_GE(pose.targets[j], m->jnt_range[2 * id]) << pose.name << " " << set.joints[j];
      EXPECT_LE(pose.targets[j], m->jnt_range[2 * id + 1]) << pose.name << " " << set.joints[j];
    }
  }
}

TEST(CalibrationPoses, ShippedPosesRespectTheCouplingTendons) {
  // The model couples each finger's distal joint to its middle one with a fixed tendon whose
  // length (sum of coef * q) is limited; a pose outside those limits cannot be reached.
  const mjModel* m = hand().m;
  const CalibrationPoseSet set = loadCalibrationPoses(POSE_FILE, jointRangesFromModel(m));
  int coupled = 0;
  for (int t = 0; t < m->ntendon; ++t) {
    if (!m->tendon_limited[t]) continue;
    bool fixed = true;
    for (int w = m->tendon_adr[t]; w < m->tendon_adr[t] + m->tendon_num[t]; ++w)
      fixed = fixed && m->wrap_type[w] == mjWRAP_JOINT;
    if (!fixed) continue;
    ++coupled;
    for (const CalibrationPose& pose : set.poses) {
      const adroit::DataPtr d = poseData(set, pose);
      double length = 0;
      for (int w = m->tendon_adr[t]; w < m->tendon_adr[t] + m->tendon_num[t]; ++w)
        length += m->wrap_prm[w] * d->qpos[m->jnt_qposadr[m->wrap_objid[w]]];
      EXPECT_GE(length, m->tendon_range[2 * t]) << pose.name << " " << mj_id2name(m, mjOBJ_TENDON, t);
      EXPECT_LE(length, m->tendon_range[2 * t + 1]) << pose.name << " " << mj_id2name(m, mjOBJ_TENDON, t);
    }
  }
  EXPECT_EQ(coupled, 4);  // FF, MF, RF, LF
}

TEST(CalibrationPoses, PinchesBringTheFingertipsTogether) {
  const mjModel* m = hand().m;
  const CalibrationPoseSet set = loadCalibrationPoses(POSE_FILE, jointRangesFromModel(m));
  const std::vector<std::pair<std::string, const char*>> pinches = {
      {"pinch_index", "S_fftip"}, {"pinch_middle", "S_mftip"}, {"pinch_little", "S_lftip"}};
  for (const auto& [pose, tip] : pinches) {
    const adroit::DataPtr d = poseData(set, poseNamed(set, pose));
    EXPECT_LT(siteDistance(m, d.get(), "S_thtip", tip), 0.01) << pose;
  }
  // ...and the flat hand keeps them apart, so the check above can fail.
  const adroit::DataPtr flat = poseData(set, poseNamed(set, "flat"));
  EXPECT_GT(siteDistance(m, flat.get(), "S_thtip", "S_fftip"), 0.05);
}

TEST(CalibrationPoses, CalibrationFittedOnThePosesReproducesThem) {
  // A simulated 22-sensor glove: sensor i bends with one joint (gain 0.25 per rad, about 64
  // counts, of the order of a CyberGlove's resolution), two joints (FFJ0, MFJ0) have no sensor
  // of their own, every sensor also picks up a little of every joint (cross-talk), plus one
  // quantisation step of noise. Fifty samples per pose, as if each pose were held a moment.
  const CalibrationPoseSet set = loadCalibrationPoses(POSE_FILE, jointRangesFromModel(hand().m));
  const int N = 22, J = static_cast<int>(set.joints.size());
  std::mt19937 rng(17);
  std::normal_distribution<double> gauss(0, 1), step(0, 1.0 / 255);
  Eigen::MatrixXd A(N, J);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < J; ++j) A(i, j) = 0.02 * gauss(rng);
  int i = 0;
  for (int j = 0; j < J; ++j)
    if (set.joints[j] != "FFJ0" && set.joints[j] != "MFJ0") A(i++, j) += 0.25;
  ASSERT_EQ(i, N);
  // Offsets put every joint's mid-range at the middle of the sensor's range.
  Eigen::VectorXd mid(J);
  for (int j = 0; j < J; ++j) mid[j] = 0.5 * (set.ranges[j].lo + set.ranges[j].hi);
  const Eigen::VectorXd offset = Eigen::VectorXd::Constant(N, 0.5) - A * mid;
  std::vector<CalibrationSample> samples;
  std::vector<Eigen::VectorXd> mean_sensors;
  for (const CalibrationPose& pose : set.poses) {
    const Eigen::VectorXd s0 = A * pose.targets + offset;
    ASSERT_GT(s0.minCoeff(), 0.0);
    ASSERT_LE(s0.maxCoeff(), 1.0);
    mean_sensors.push_back(s0);
    for (int k = 0; k < 50; ++k) {
      Eigen::VectorXd s = s0;
      for (int n = 0; n < N; ++n) s[n] += step(rng);
      samples.push_back(poseSample(pose, s));
    }
  }
  const GloveCalibration cal = fitCalibration(N, set.joints, set.ranges, samples);
  for (std::size_t p = 0; p < set.poses.size(); ++p) {
    const Eigen::VectorXd q = cal.apply(mean_sensors[p]);
    for (int j = 0; j < J; ++j) {
      if (!set.poses[p].constrained[j]) continue;
      // Within 0.05 rad (3 degrees) of what was asked.
      EXPECT_NEAR(q[j], set.poses[p].targets[j], 0.05) << set.poses[p].name << " " << set.joints[j];
    }
  }
  for (int j = 0; j < J; ++j) {
    EXPECT_GT(cal.fit_samples[j], 0) << set.joints[j];
    EXPECT_LT(cal.residual_rms[j], 0.05) << set.joints[j];
  }
}

TEST(CalibrationPoses, BadPoseFilesAreRefused) {
  const std::string head = "version: 1\njoints: [FFJ2, FFJ1, WRJ1]\nposes:\n";
  EXPECT_EQ(poseError(head + "  - {name: a, targets: {FFJ2: 1.0}}\n"), "");  // the base is valid
  const std::string prefix = posesPath() + ": ";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {head + "  - {name: a, targets: {FFJ9: 1.0}}\n", "poses[0] (a).targets.FFJ9: unknown joint 'FFJ9'"},
      {head + "  - {name: a, targets: {POS: 0.2}}\n", "poses[0] (a).targets.POS: joint 'POS' is not in the pose set's joints"},
      {"version: 1\njoints: [FFJ2, XXJ1]\nposes:\n  - {name: a, targets: {}}\n", "joints: unknown joint 'XXJ1'"},
      {head + "  - {name: a, targets: {FFJ2: 2.0}}\n", "poses[0] (a).targets.FFJ2: 2 is outside the joint's range [0, 1.571]"},
      {head + "  - {name: a, targets: {FFJ2: x}}\n", "poses[0] (a).targets.FFJ2: expected a number"},
      {head + "  - {name: a, targets: {FFJ2: 1}, free: [FFJ2]}\n", "poses[0] (a).free: joint 'FFJ2' also has a target"},
      {head + "  - {name: a, targets: {}, free: [QQ]}\n", "poses[0] (a).free: unknown joint 'QQ'"},
      {head + "  - {name: a, targets: {}}\n  - {name: a, targets: {}}\n", "poses[1] (a): pose name used twice"},
      {head + "  - {name: a}\n", "poses[0] (a).targets: missing"},
      {head + "  - {name: a, targets: {}, hold: 2}\n", "poses[0] (a).hold: unknown key"},
      {head + "  - {targets: {}}\n", "poses[0].name: missing"},
      {"version: 1\njoints: [FFJ2]\nposes: []\n", "poses: expected a non-empty list of poses"},
      {"version: 3\njoints: [FFJ2]\nposes: []\n", "version: unknown version 3"},
      {"joints: [FFJ2]\nposes: []\n", "version: missing"},
      {"version: 1\njoints: [POS]\nposes:\n  - {name: a, targets: {}}\n",
       "poses[0] (a): joint 'POS' is not listed and 0 is outside its range [0.1, 0.5]"},
  };
  for (const auto& [text, problem] : cases) {
    const std::string e = poseError(text);
    EXPECT_EQ(e.rfind(prefix, 0), 0u) << "message does not start with the file: " << e;
    EXPECT_NE(e.find(problem), std::string::npos) << "expected '" << problem << "' in: " << e;
  }
}

// The pose file is a parameter (~poses, nominal_calibration --poses): read only when it is a
// regular file of bounded size, without blocking on a FIFO.
TEST(CalibrationPoses, OnlyRegularFilesOfBoundedSizeAreRead) {
  using test::errorWithin;
  const std::string fifo = test::makeFifo(scratchDir() + "/poses_fifo.yaml");
  const auto load = [](const std::string& path) { return [path] { loadCalibrationPoses(path, kKnown); }; };
  EXPECT_EQ(errorWithin<CalibrationError>(load(fifo), fifo), fifo + ": not a regular file (a FIFO)");
  EXPECT_EQ(errorWithin<CalibrationError>(load(scratchDir()), fifo), scratchDir() + ": not a regular file (a directory)");
  const std::string big = test::makeSparseFile(scratchDir() + "/big_poses.yaml", kMaxCalibrationFileBytes + 1);
  const std::string e = errorWithin<CalibrationError>(load(big), fifo);
  EXPECT_EQ(e.rfind(big + ": ", 0), 0u) << e;
  EXPECT_NE(e.find("over the limit of 1 MB"), std::string::npos) << e;
}

TEST(CalibrationPoses, FreeJointsAreLeftOutOfThePoseSamples) {
  const std::string path = writeTemp(
      "version: 1\njoints: [FFJ2, FFJ1, WRJ1]\nposes:\n"
      "  - {name: a, instruction: bend, targets: {FFJ2: 1.0}, free: [WRJ1]}\n");
  const CalibrationPoseSet set = loadCalibrationPoses(path, kKnown);
  ASSERT_EQ(set.poses.size(), 1u);
  const CalibrationPose& p = set.poses[0];
  EXPECT_EQ(p.instruction, "bend");
  EXPECT_EQ(p.targets, Eigen::Vector3d(1.0, 0.0, 0.0));
  EXPECT_EQ(p.constrained, (std::vector<bool>{true, true, false}));
  EXPECT_DOUBLE_EQ(set.ranges[2].lo, -0.524);
  const CalibrationSample s = poseSample(p, Eigen::Vector2d(0.3, 0.4));
  EXPECT_EQ(s.constrained, p.constrained);
  EXPECT_EQ(s.sensors, Eigen::Vector2d(0.3, 0.4));
}
