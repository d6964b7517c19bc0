// The calibration file of the hardware driver (can_calibration.h): a round trip through YAML
// is exact, what is not listed is the identity, and every kind of bad file is refused with one
// line naming the file, the key path and the value.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <fcntl.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <future>
#include <memory>
#include <thread>
#include <string>
#include <vector>

#include "adroit_core/mujoco_model.h"
#include "adroit_driver/can_calibration.h"

namespace adroit::driver::can {
namespace {

struct Names {
  std::vector<std::string> joints, cylinders;
};

// The arm_hand model's 1-DOF joints and cylinders, as CanRobot names them.
const Names& armHand() {
  static const Names names = [] {
    Names n;
    const LoadedModel loaded = loadModelFile(std::string(ADROIT_MJCF_DIR) + "/arm_hand.xml");
    const mjModel* m = loaded.model.get();
    for (int j = 0; j < m->njnt; ++j)
      if (m->jnt_type[j] == mjJNT_HINGE || m->jnt_type[j] == mjJNT_SLIDE)
        n.joints.push_back(mj_id2name(m, mjOBJ_JOINT, j));
    for (int a = 0; a < m->nu; ++a) n.cylinders.push_back(mj_id2name(m, mjOBJ_ACTUATOR, a));
    return n;
  }();
  return names;
}

class Calibrations : public ::testing::Test {
 protected:
  void SetUp() override {
    char pattern[] = "/tmp/adroit_calibration_XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    dir_ = pattern;
  }
  void TearDown() override {
    for (const auto& f : files_) std::remove(f.c_str());
    rmdir(dir_.c_str());
  }
  std::string write(const std::string& text, const std::string& name = "calibration.yaml") {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    files_.push_back(path);
    return path;
  }
  Calibration load(const std::string& path) { return loadCalibration(path, armHand().joints, armHand().cylinders); }
  // The one-line error loading `text` gives ("" if it loads).
  std::string error(const std::string& text) {
    const std::string path = write(text);
    try {
      load(path);
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      EXPECT_EQ(what.rfind("calibration " + path + ": ", 0), 0u) << what;
      return what.substr(("calibration " + path + ": ").size());
    }
    return "";
  }

  // The whole one-line error loading `path` gives ("" if it loads).
  std::string errorAt(const std::string& path) {
    try {
      load(path);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  }

  std::string dir_;
  std::vector<std::string> files_;
};

void expectIdentity(const Affine& a) {
  EXPECT_EQ(a.gain, 1.0);
  EXPECT_EQ(a.offset, 0.0);
}

TEST_F(Calibrations, RoundTripIsExact) {
  const Names& n = armHand();
  ASSERT_EQ(n.joints.size(), 28u);
  ASSERT_EQ(n.cylinders.size(), 48u);
  Calibration c = identityCalibration(n.joints.size(), n.cylinders.size());
  for (std::size_t j = 0; j < c.joint.size(); ++j) c.joint[j] = {1.0 + 0.01 * j / 3.0, -0.3 + 0.021 * j};
  for (std::size_t i = 0; i < c.pressure.size(); ++i) {
    c.pressure[i] = {0.97 + i * 1e-3, -2e4 + 812.5 * i};
    c.length[i] = {1.1 - i / 700.0, 1e-4 * i / 7.0};
  }
  c.supply = {4.0 / 3.0, 4321.123456789};
  const std::string path = write(formatCalibration(c, n.joints, n.cylinders));
  const Calibration back = load(path);
  ASSERT_EQ(back.joint.size(), c.joint.size());
  for (std::size_t j = 0; j < c.joint.size(); ++j) {
    EXPECT_EQ(back.joint[j].gain, c.joint[j].gain) << n.joints[j];
    EXPECT_EQ(back.joint[j].offset, c.joint[j].offset) << n.joints[j];
  }
  for (std::size_t i = 0; i < c.pressure.size(); ++i) {
    EXPECT_EQ(back.pressure[i].gain, c.pressure[i].gain);
    EXPECT_EQ(back.pressure[i].offset, c.pressure[i].offset);
    EXPECT_EQ(back.length[i].gain, c.length[i].gain);
    EXPECT_EQ(back.length[i].offset, c.length[i].offset);
  }
  EXPECT_EQ(back.supply.gain, c.supply.gain);
  EXPECT_EQ(back.supply.offset, c.supply.offset);
  EXPECT_EQ(validateCalibration(back, n.joints, n.cylinders), "");
}

TEST_F(Calibrations, WhatIsNotListedIsTheIdentity) {
  const Calibration c = load(write("joints:\n  FFJ3: {offset: 0.1}\npressure:\n  A_FFJ3_flex: {gain: 1.5}\n"));
  const auto& n = armHand();
  const auto ffj3 = std::find(n.joints.begin(), n.joints.end(), "FFJ3") - n.joints.begin();
  const auto flex = std::find(n.cylinders.begin(), n.cylinders.end(), "A_FFJ3_flex") - n.cylinders.begin();
  EXPECT_EQ(c.joint[ffj3].offset, 0.1);
  EXPECT_EQ(c.joint[ffj3].gain, 1.0);
  EXPECT_EQ(c.pressure[flex].gain, 1.5);
  EXPECT_EQ(c.pressure[flex].offset, 0.0);
  for (std::size_t j = 0; j < c.joint.size(); ++j)
    if (static_cast<long>(j) != ffj3) expectIdentity(c.joint[j]);
  for (const auto& a : c.length) expectIdentity(a);
  expectIdentity(c.supply);
  // An empty file, and empty sections, are the identity too.
  for (const auto& a : load(write("")).joint) expectIdentity(a);
  for (const auto& a : load(write("version: 1\njoints:\nlength: {}\n")).length) expectIdentity(a);
}

TEST_F(Calibrations, TheShippedIdentityFileListsEverything) {
  const std::string here = __FILE__;
  const std::string path = here.substr(0, here.rfind('/')) + "/../config/calibration_identity.yaml";
  const Calibration c = load(path);
  for (const auto& a : c.joint) expectIdentity(a);
  for (const auto& a : c.pressure) expectIdentity(a);
  for (const auto& a : c.length) expectIdentity(a);
  expectIdentity(c.supply);
  std::ifstream file(path);
  const std::string text((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  for (const auto& j : armHand().joints) EXPECT_NE(text.find("\n  " + j + ":"), std::string::npos) << j;
  for (const auto& cyl : armHand().cylinders) EXPECT_NE(text.find("\n  " + cyl + ":"), std::string::npos) << cyl;
}

TEST_F(Calibrations, MissingOrUnparseableFileIsNamed) {
  const std::string missing = dir_ + "/absent.yaml";
  try {
    load(missing);
    FAIL() << "loaded a missing file";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "calibration " + missing + ": cannot open (No such file or directory)");
  }
  EXPECT_NE(error("joints: {FFJ3: {offset: 0.1}\n").find("not valid YAML (line"), std::string::npos);
  EXPECT_EQ(error("- 1\n- 2\n"), "the top level must be a map (joints, pressure, length, supply, version)");
}

TEST_F(Calibrations, UnknownKeysAndNamesAreRefused) {
  EXPECT_EQ(error("joint:\n  FFJ3: {offset: 0.1}\n"),
            "joint: unknown key (known: version, joints, pressure, length, supply)");
  EXPECT_EQ(error("joints:\n  FFJ9: {offset: 0.1}\n"), "joints.FFJ9: unknown joint (not in the model)");
  EXPECT_EQ(error("pressure:\n  A_FFJ9_flex: {gain: 1}\n"),
            "pressure.A_FFJ9_flex: unknown cylinder (not in the model)");
  EXPECT_EQ(error("length:\n  FFJ3: {gain: 1}\n"), "length.FFJ3: unknown cylinder (not in the model)");
  EXPECT_EQ(error("joints:\n  FFJ3: {ofset: 0.1}\n"), "joints.FFJ3.ofset: unknown key (an entry has offset and gain)");
  EXPECT_EQ(error("version: 2\n"), "version must be 1, got 2");
  EXPECT_EQ(error("joints: [1, 2]\n"), "joints must be a map of joint name -> {offset, gain}, got a list");
  EXPECT_EQ(error("supply: 3\n"), "supply must be a map {offset: <Pa>, gain: <g>}, got 3");
}

TEST_F(Calibrations, BadValuesAreRefusedWithTheirPathAndValue) {
  EXPECT_EQ(error("joints:\n  FFJ3: {offset: abc}\n"), "joints.FFJ3.offset must be a number, got abc");
  EXPECT_EQ(error("joints:\n  FFJ3: {gain: [1]}\n"), "joints.FFJ3.gain must be a number, got a list");
  EXPECT_EQ(error("length:\n  A_FFJ3_flex: {offset: .nan}\n"), "length.A_FFJ3_flex.offset must be finite, got .nan");
  EXPECT_EQ(error("supply: {gain: .inf}\n"), "supply.gain must be finite, got .inf");
  EXPECT_EQ(error("pressure:\n  A_FFJ3_flex: {gain: 7}\n"), "pressure.A_FFJ3_flex.gain must be in [0.5, 2], got 7");
  EXPECT_EQ(error("joints:\n  WRJ1: {gain: 0.4}\n"), "joints.WRJ1.gain must be in [0.5, 2], got 0.4");
  EXPECT_EQ(error("joints:\n  WRJ1: {offset: -0.6}\n"), "joints.WRJ1.offset must be within +-0.5 rad, got -0.6");
  EXPECT_EQ(error("pressure:\n  A_THJ0_ext: {offset: 60000}\n"),
            "pressure.A_THJ0_ext.offset must be within +-50000 Pa, got 60000");
  EXPECT_EQ(error("length:\n  A_ARJ3_flex: {offset: 0.03}\n"),
            "length.A_ARJ3_flex.offset must be within +-0.02 m, got 0.03");
  EXPECT_EQ(error("supply: {offset: -5e4, gain: 1}\n"), "");  // the bounds are inclusive
  EXPECT_EQ(error("supply: {offset: -5.1e4}\n"), "supply.offset must be within +-50000 Pa, got -5.1e4");
}

// The path comes from a parameter: only a regular file of sane size is read.
TEST_F(Calibrations, AFifoIsRefusedWithoutBlocking) {
  const std::string fifo = dir_ + "/calibration.fifo";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  files_.push_back(fifo);
  auto done = std::make_shared<std::promise<std::string>>();
  std::future<std::string> error = done->get_future();
  std::thread([this, fifo, done] { done->set_value(errorAt(fifo)); }).detach();
  if (error.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
    close(open(fifo.c_str(), O_WRONLY));  // a writer unblocks the reader, so the test can end
    error.wait();
    FAIL() << "loading a FIFO blocked";
  }
  EXPECT_EQ(error.get(), "calibration " + fifo + ": not a regular file (a FIFO)");
}

TEST_F(Calibrations, ADirectoryIsRefused) {
  EXPECT_EQ(errorAt(dir_), "calibration " + dir_ + ": not a regular file (a directory)");
}

TEST_F(Calibrations, AFileOverTheLimitIsRefusedNamingIt) {
  // Valid YAML (the identity followed by comments): only its size is wrong.
  const std::string padding(2 * 1024 * 1024, '#');
  const std::string path = write("version: 1\n" + padding + "\n");
  EXPECT_EQ(errorAt(path), "calibration " + path + ": 2 MB, over the limit of 1 MB");
}

TEST_F(Calibrations, ValidateChecksACalibrationBuiltInCode) {
  const Names& n = armHand();
  Calibration c = identityCalibration(n.joints.size(), n.cylinders.size());
  EXPECT_EQ(validateCalibration(c, n.joints, n.cylinders), "");
  c.length[3].gain = 3;
  EXPECT_NE(validateCalibration(c, n.joints, n.cylinders)
                .find("length." + n.cylinders[3] + ".gain must be in [0.5, 2], got 3"),
            std::string::npos);
  c = identityCalibration(2, n.cylinders.size());
  EXPECT_EQ(validateCalibration(c, n.joints, n.cylinders), "calibration has 2 joints, the model 28");
}

}  // namespace
}  // namespace adroit::driver::can
