// Eq. 10.1 on the real teleop model: u = k J_tendon (q - q_glove) drives the simulated hand
// to the glove's pose (closed loop in MuJoCo, the tensions as the cylinders' force controls),
// pulls only with the tendons that shorten towards the target, and refuses bad input.
#include <adroit_teleop/tendon_mapping.h>
#include <gtest/gtest.h>

#include <cmath>

using namespace adroit;
using namespace adroit::teleop;

namespace {

ModelPtr teleopModel() { return loadModelFile(std::string(ADROIT_MJCF_DIR) + "/teleop_tube.xml").model; }

std::vector<std::string> hingeJoints(const mjModel* m) {
  std::vector<std::string> names;
  for (int j = 0; j < m->njnt; ++j)
    if (m->jnt_type[j] == mjJNT_HINGE) names.push_back(mj_id2name(m, mjOBJ_JOINT, j));
  return names;
}

int index(const std::vector<std::string>& names, const std::string& name) {
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<int>(i);
  return -1;
}

TEST(TendonMapping, AtTheTargetEveryTendonHoldsItsMinimum) {
  ModelPtr model = teleopModel();
  const auto joints = hingeJoints(model.get());
  TendonMapping mapping(std::move(model), joints, MappingGains{});
  std::vector<double> q(joints.size(), 0.2), zero(joints.size(), 0.0), tensions;
  ASSERT_TRUE(mapping.compute(q, zero, q, tensions));
  ASSERT_EQ(tensions.size(), mapping.actuatorNames().size());
  for (double t : tensions) EXPECT_DOUBLE_EQ(t, MappingGains{}.min_tension);
}

TEST(TendonMapping, OnlyTheTendonsThatPullTowardsTheTargetPull) {
  ModelPtr model = teleopModel();
  const auto joints = hingeJoints(model.get());
  TendonMapping mapping(std::move(model), joints, MappingGains{});
  std::vector<double> q(joints.size(), 0.0), zero(joints.size(), 0.0), target = q, tensions;
  target[index(joints, "FFJ2")] = 0.8;  // the glove flexes the index knuckle
  ASSERT_TRUE(mapping.compute(q, zero, target, tensions));
  const auto& names = mapping.actuatorNames();
  const double flex = tensions[index(names, "A_FFJ2_flex")], ext = tensions[index(names, "A_FFJ2_ext")];
  EXPECT_GT(flex, 1.0);                               // the flexor pulls
  EXPECT_DOUBLE_EQ(ext, MappingGains{}.min_tension);  // the extensor goes slack (at its minimum)
  // Other joints' tendons that do not cross FFJ2 stay at their minimum.
  EXPECT_DOUBLE_EQ(tensions[index(names, "A_MFJ2_flex")], MappingGains{}.min_tension);
  EXPECT_DOUBLE_EQ(tensions[index(names, "A_WRJ0_flex")], MappingGains{}.min_tension);
}

// The closed loop the teleop node runs, in MuJoCo at 200 Hz: the hand reaches a glove pose.
TEST(TendonMapping, TheSimulatedHandReachesTheGlovePose) {
  ModelPtr model = teleopModel();
  const mjModel* m = model.get();
  ModelPtr sim = copyModel(m);
  DataPtr d = makeData(sim.get());
  mj_resetDataKeyframe(sim.get(), d.get(), mj_name2id(sim.get(), mjOBJ_KEY, "home"));
  const auto joints = hingeJoints(m);
  MappingGains gains;  // as config/teleop.yaml: the wrist carries the whole hand
  gains.scale["WRJ"] = 8.0;
  TendonMapping mapping(copyModel(m), joints, gains);
  std::vector<double> target(joints.size(), 0.0), q(joints.size()), qdot(joints.size()), tensions;
  // RFJ0 follows RFJ1 through the model's DIP-PIP coupling (J0 = 1.142 J1), as a glove's DIP
  // sensor (or the calibration) says.
  const std::map<std::string, double> pose = {{"FFJ2", 0.8}, {"MFJ2", 0.6}, {"RFJ1", 0.7}, {"RFJ0", 0.8},
                                              {"LFJ3", -0.2}, {"THJ4", 0.5}, {"WRJ0", 0.3}};
  for (const auto& [name, value] : pose) target[index(joints, name)] = value;
  std::vector<int> qadr, vadr;
  for (const auto& name : joints) {
    const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    qadr.push_back(m->jnt_qposadr[j]);
    vadr.push_back(m->jnt_dofadr[j]);
  }
  for (int step = 0; step < 1500; ++step) {  // 3 s
    if (step % 2 == 0) {  // the teleop node's 200 Hz (the joint_states path)
      for (std::size_t i = 0; i < joints.size(); ++i) {
        q[i] = d->qpos[qadr[i]];
        qdot[i] = d->qvel[vadr[i]];
      }
      ASSERT_TRUE(mapping.compute(q, qdot, target, tensions));
      for (int a = 0; a < m->nu; ++a) d->ctrl[a] = tensions[a];
    }
    mj_step(sim.get(), d.get());
  }
  // Within 0.1 rad: a proportional law leaves a steady error where gravity loads a joint (the
  // wrist holding the hand: ~0.4 Nm on 8 x 3000 N/m x (18 mm)^2 = 7.8 Nm/rad, 0.05 rad).
  for (const auto& [name, value] : pose) {
    const int i = index(joints, name);
    EXPECT_NEAR(d->qpos[qadr[i]], value, 0.1) << name;
  }
  EXPECT_NEAR(d->qpos[qadr[index(joints, "MFJ3")]], 0.0, 0.1);  // a joint at rest stays near rest
}

TEST(TendonMapping, BadInputIsRefused) {
  const auto joints = hingeJoints(teleopModel().get());
  EXPECT_THROW(TendonMapping(teleopModel(), {"FFJ2", "NOPE"}, MappingGains{}), std::invalid_argument);
  EXPECT_THROW(TendonMapping(teleopModel(), {"hand_base"}, MappingGains{}), std::invalid_argument);  // free joint
  MappingGains negative;
  negative.stiffness = -1;
  EXPECT_THROW(TendonMapping(teleopModel(), joints, negative), std::invalid_argument);
  TendonMapping mapping(teleopModel(), joints, MappingGains{});
  std::vector<double> q(joints.size(), 0.0), tensions;
  EXPECT_FALSE(mapping.compute(std::vector<double>(3, 0.0), q, q, tensions));  // wrong size
  std::vector<double> bad = q;
  bad[2] = NAN;
  EXPECT_FALSE(mapping.compute(q, q, bad, tensions));
  EXPECT_TRUE(tensions.empty());  // nothing written on refusal
}

}  // namespace
