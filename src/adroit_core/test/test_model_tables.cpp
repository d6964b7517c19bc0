#include <gtest/gtest.h>

#include "adroit_core/model_tables.h"
#include "adroit_core/mujoco_model.h"

namespace {

const char* kTwoLinks = R"(
<mujoco>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" type="ball"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.04"/>
      <site name="s_upper" pos="0.05 0 -0.1"/>
      <body name="lower" pos="0 0 -0.3">
        <joint name="elbow" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03"/>
        <site name="s_lower" pos="0.05 0 -0.1"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <spatial name="flexor"><site site="s_upper"/><site site="s_lower"/></spatial>
  </tendon>
  <actuator>
    <motor name="pull" tendon="flexor"/>
  </actuator>
  <sensor>
    <jointpos name="elbow_pos" joint="elbow"/>
    <tendonpos name="flexor_len" tendon="flexor"/>
  </sensor>
</mujoco>)";

TEST(ModelTables, ResolvesEveryKind) {
  auto loaded = adroit::loadModelString(kTwoLinks);
  const mjModel* m = loaded.model.get();
  adroit::ModelTables t(m);
  EXPECT_EQ(t.joints.at("elbow"), 1);
  EXPECT_EQ(t.tendons.at("flexor"), 0);
  EXPECT_EQ(t.actuators.at("pull"), 0);
  EXPECT_EQ(t.sensors.at("flexor_len"), 1);
  EXPECT_EQ(t.sites.at("s_lower"), 1);
  EXPECT_EQ(t.bodies.at("lower"), 2);  // world is body 0
  EXPECT_EQ(t.joints.size(), 2);
  EXPECT_EQ(t.joints.name(0), "shoulder");
  // Ball joint takes 4 qpos and 3 dofs, so the elbow comes after them.
  EXPECT_EQ(adroit::jointQposAddress(m, t.joints.at("elbow")), 4);
  EXPECT_EQ(adroit::jointDofAddress(m, t.joints.at("elbow")), 3);
}

TEST(ModelTables, UnknownNameIsAClearError) {
  auto loaded = adroit::loadModelString(kTwoLinks);
  adroit::ModelTables t(loaded.model.get());
  EXPECT_FALSE(t.joints.find("wrist").has_value());
  try {
    t.joints.resolve({"elbow", "wrist"});
    FAIL() << "expected out_of_range";
  } catch (const std::out_of_range& e) {
    EXPECT_NE(std::string(e.what()).find("'wrist'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("joint"), std::string::npos) << e.what();
  }
}

}  // namespace
