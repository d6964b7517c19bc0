#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>


#include <cstdio>
#include <fstream>

#include "adroit_core/mujoco_model.h"

namespace {

const char* kPendulum = R"(
<mujoco>
  <worldbody>
    <body name="link" pos="0 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05"/>
    </body>
  </worldbody>
</mujoco>)";

TEST(MujocoModel, LoadsFromStringAndSteps) {
  auto loaded = adroit::loadModelString(kPendulum);
  ASSERT_TRUE(loaded.model);
  EXPECT_EQ(loaded.model->nq, 1);
  EXPECT_TRUE(loaded.warning.empty()) << loaded.warning;
  auto data = adroit::makeData(loaded.model.get());
  data->qpos[0] = 0.5;
  for (int i = 0; i < 100; ++i) mj_step(loaded.model.get(), data.get());
  EXPECT_NE(data->qpos[0], 0.5);  // gravity moved the pendulum
  EXPECT_EQ(adroit::warningCount(data.get()), 0);
}

TEST(MujocoModel, MalformedStringQuotesMujocoMessage) {
  try {
    adroit::loadModelString("<mujoco><worldbody><body><geom type='sphere'/></body></worldbody>");
    FAIL() << "expected ModelLoadError";
  } catch (const adroit::ModelLoadError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("<string>"), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << "message must be one line: " << what;
    EXPECT_GT(what.size(), std::string("cannot load model '<string>': ").size()) << what;
  }
}

TEST(MujocoModel, MissingFileNamesThePath) {
  const std::string path = "/nonexistent/dir/model.xml";
  try {
    adroit::loadModelFile(path);
    FAIL() << "expected ModelLoadError";
  } catch (const adroit::ModelLoadError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

TEST(MujocoModel, AFifoOrDeviceIsRefusedBeforeMujocoReadsIt) {
  const std::string fifo = ::testing::TempDir() + "/model_fifo_" + std::to_string(getpid()) + ".xml";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& path : {fifo, std::string("/dev/zero")}) {
    try {
      adroit::loadModelFile(path);
      ADD_FAILURE() << path << " was loaded";
    } catch (const adroit::ModelLoadError& e) {
      EXPECT_NE(std::string(e.what()).find("cannot load model: " + path + ": not a regular file"), std::string::npos)
          << e.what();
    }
  }
  unlink(fifo.c_str());
}

TEST(MujocoModel, LoadsFromFile) {
  char path[] = "/tmp/adroit_core_test_XXXXXX.xml";
  int fd = mkstemps(path, 4);
  ASSERT_GE(fd, 0);
  close(fd);
  { std::ofstream(path) << kPendulum; }
  auto loaded = adroit::loadModelFile(path);
  std::remove(path);
  EXPECT_EQ(loaded.model->njnt, 1);
}

TEST(MujocoModel, CopiesAreIndependent) {
  auto loaded = adroit::loadModelString(kPendulum);
  auto data = adroit::makeData(loaded.model.get());
  data->qpos[0] = 0.3;
  auto copy = adroit::copyData(loaded.model.get(), data.get());
  mj_step(loaded.model.get(), copy.get());
  EXPECT_EQ(data->qpos[0], 0.3);
  EXPECT_DOUBLE_EQ(copy->time, loaded.model->opt.timestep);
  auto model_copy = adroit::copyModel(loaded.model.get());
  model_copy->opt.timestep = 0.01;
  EXPECT_NE(loaded.model->opt.timestep, 0.01);
}

TEST(MujocoModel, CountsRuntimeWarnings) {
  auto loaded = adroit::loadModelString(kPendulum);
  auto data = adroit::makeData(loaded.model.get());
  data->qvel[0] = std::numeric_limits<double>::quiet_NaN();
  mj_step(loaded.model.get(), data.get());
  EXPECT_GT(adroit::warningCount(data.get()), 0);
  EXPECT_NE(adroit::warningSummary(data.get()).find("badqvel"), std::string::npos)
      << adroit::warningSummary(data.get());
}

}  // namespace
