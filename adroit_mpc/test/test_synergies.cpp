// Synergy map on the real hand model: the round trip through the pseudo-inverse, which
// actuators each synergy drives, and its effect on the fingers in simulation.
#include <adroit_core/model_tables.h>
#include <adroit_description/scenes.h>
#include <adroit_mpc/planning_model.h>
#include <adroit_mpc/synergies.h>
#include <gtest/gtest.h>

#include <random>

using adroit_mpc::Synergies;

namespace {

adroit::ModelPtr handModel() {
  return adroit::loadModelFile(adroit::description::sceneFile(adroit_mpc::descriptionShareDir(), "hand", true)).model;
}

}  // namespace

TEST(Synergies, ProjectOfMapIsIdentityWithZeroIndividualControls) {
  auto m = handModel();
  Synergies syn(m.get());
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-1, 1);
  std::vector<double> u(m->nu + Synergies::kCount, 0.0), ctrl(m->nu);
  double s_back[Synergies::kCount];
  for (int trial = 0; trial < 50; ++trial) {
    for (int k = 0; k < Synergies::kCount; ++k) u[m->nu + k] = trial == 0 ? 1.0 : uniform(rng);
    syn.apply(u.data(), ctrl.data());
    for (int i = 0; i < m->nu; ++i) {
      ASSERT_GE(ctrl[i], m->actuator_ctrlrange[2 * i]);
      ASSERT_LE(ctrl[i], m->actuator_ctrlrange[2 * i + 1]);
    }
    syn.project(ctrl.data(), s_back);
    for (int k = 0; k < Synergies::kCount; ++k) EXPECT_NEAR(s_back[k], u[m->nu + k], 1e-9) << "synergy " << k;
  }
}

TEST(Synergies, EachCurlDrivesOnlyItsFingersFlexionTendons) {
  auto m = handModel();
  adroit::ModelTables tables(m.get());
  Synergies syn(m.get());
  const char* fingers[4] = {"FF", "MF", "RF", "LF"};
  for (int f = 0; f < 4; ++f) {
    int driven = 0;
    for (int a = 0; a < m->nu; ++a) {
      const std::string& name = tables.actuators.name(a);
      const double entry = syn.map()(a, f);
      const bool own = name == "A_" + std::string(fingers[f]) + "J2_flex" ||
                       name == "A_" + std::string(fingers[f]) + "J1_flex" ||
                       name == "A_" + std::string(fingers[f]) + "J2_ext" ||
                       name == "A_" + std::string(fingers[f]) + "J1_ext";
      if (!own) {
        EXPECT_EQ(entry, 0.0) << "curl " << fingers[f] << " drives " << name;
        continue;
      }
      ++driven;
      const double range = m->actuator_ctrlrange[2 * a + 1] - m->actuator_ctrlrange[2 * a];
      const bool flexor = name.size() > 5 && name.substr(name.size() - 5) == "_flex";
      EXPECT_DOUBLE_EQ(entry, flexor ? range : -range) << name;
    }
    EXPECT_EQ(driven, 4) << fingers[f];
  }
}

TEST(Synergies, SpreadDrivesOnlyTheAbductionJointsAwayFromTheMiddle) {
  auto m = handModel();
  adroit::ModelTables tables(m.get());
  Synergies syn(m.get());
  for (int a = 0; a < m->nu; ++a) {
    const std::string& name = tables.actuators.name(a);
    const bool abduction = name.find("J3_") != std::string::npos && name.rfind("A_TH", 0) != 0;
    if (!abduction) EXPECT_EQ(syn.map()(a, 4), 0.0) << name;
    else EXPECT_NE(syn.map()(a, 4), 0.0) << name;
  }
  // In simulation: full spread for 0.5 s moves the index and little fingertips apart.
  adroit::DataPtr d = adroit::makeData(m.get());
  mj_forward(m.get(), d.get());
  const int ff = tables.sites.at("S_fftip"), lf = tables.sites.at("S_lftip");
  auto gap = [&] {
    double diff[3];
    mju_sub3(diff, d->site_xpos + 3 * ff, d->site_xpos + 3 * lf);
    return mju_norm3(diff);
  };
  const double before = gap();
  std::vector<double> u(m->nu + Synergies::kCount, 0.0);
  u[m->nu + 4] = 1.0;
  for (int i = 0; i < 250; ++i) {
    syn.apply(u.data(), d->ctrl);
    mj_step(m.get(), d.get());
  }
  EXPECT_GT(gap(), before + 0.01);
  // Full curl of the index finger flexes its MCP and PIP and leaves the middle finger where
  // it would be without any tension (gravity and the springs move it either way).
  auto run = [&](double curl) {
    mj_resetData(m.get(), d.get());
    std::fill(u.begin(), u.end(), 0.0);
    u[m->nu + 0] = curl;
    for (int i = 0; i < 250; ++i) {
      syn.apply(u.data(), d->ctrl);
      mj_step(m.get(), d.get());
    }
  };
  const int ffj2 = m->jnt_qposadr[tables.joints.at("FFJ2")], ffj1 = m->jnt_qposadr[tables.joints.at("FFJ1")];
  const int mfj2 = m->jnt_qposadr[tables.joints.at("MFJ2")];
  run(0.0);
  const double ffj2_relaxed = d->qpos[ffj2], mfj2_relaxed = d->qpos[mfj2];
  run(1.0);
  EXPECT_GT(d->qpos[ffj2], ffj2_relaxed + 0.3);
  EXPECT_GT(d->qpos[ffj1], 0.3);
  EXPECT_NEAR(d->qpos[mfj2], mfj2_relaxed, 0.02);
}

TEST(Synergies, ClampDerivativeMarksSaturatedActuators) {
  auto m = handModel();
  adroit::ModelTables tables(m.get());
  Synergies syn(m.get());
  std::vector<double> u(m->nu + Synergies::kCount, 0.0), ctrl(m->nu), dctrl(m->nu);
  u[m->nu + 0] = 0.5;  // curl FF: flexors at half range, extensors pushed below zero
  syn.apply(u.data(), ctrl.data(), dctrl.data());
  EXPECT_EQ(dctrl[tables.actuators.at("A_FFJ2_flex")], 1.0);
  EXPECT_EQ(dctrl[tables.actuators.at("A_FFJ2_ext")], 0.0);
  EXPECT_EQ(ctrl[tables.actuators.at("A_FFJ2_ext")], 0.0);
  EXPECT_EQ(dctrl[tables.actuators.at("A_MFJ2_ext")], 1.0);  // at its bound exactly: still free
}

TEST(Synergies, ModelWithoutFingersIsRejectedByName) {
  auto m = adroit::loadModelString(R"(<mujoco><compiler autolimits="true"/><worldbody><body><joint name="x" type="slide"/>
    <geom size="0.1"/></body></worldbody><actuator><motor joint="x" ctrlrange="-1 1"/></actuator></mujoco>)")
               .model;
  try {
    Synergies syn(m.get());
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("A_FFJ2_flex"), std::string::npos) << e.what();
  }
}
