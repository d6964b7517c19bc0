// The generated MJCF agrees with the cylinder catalogue (config/cylinders.yaml, compiled in as
// adroit_description/cylinder_catalogue.h): for every tendon actuator of every scene and
// variant, the custom text names a catalogue type, the user data is that type's bore and
// stroke, and the control range is the supply pressure over the bore with the catalogue's
// atmospheric pressure.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "adroit_description/cylinder_catalogue.h"
#include "adroit_description/scenes.h"
#include "test_helpers.h"

namespace {

using adroit::description::findCylinderType;
using adroit::description::kAtmosphericPressure;
using adroit::description::kCylinderCatalogue;

constexpr double kSupply = 620e3;  // Pa absolute, the generator's supply pressure
constexpr double kDigits = 1e-9;   // the generator writes lengths with 9 decimals

std::string text(const mjModel* m, const std::string& name) {
  const int id = mj_name2id(m, mjOBJ_TEXT, name.c_str());
  if (id < 0) return "";
  return std::string(m->text_data + m->text_adr[id], m->text_size[id] > 0 ? m->text_size[id] - 1 : 0);
}

}  // namespace

TEST(Catalogue, IsWellFormed) {
  EXPECT_GT(kAtmosphericPressure, 90e3);  // sea level within weather and altitude
  EXPECT_LT(kAtmosphericPressure, 110e3);
  for (const auto& c : kCylinderCatalogue) {
    SCOPED_TRACE(std::string(c.type));
    EXPECT_EQ(findCylinderType(c.type), &c);
    EXPECT_GT(c.bore_diameter, 0);
    EXPECT_GT(c.stroke, 0);
    EXPECT_GT(c.dead_volume, 0);
    EXPECT_GT(c.leak_diameter, 0);
    EXPECT_GT(c.valve_scale, 0);
  }
  for (const char* type : {"M9", "M16", "M24", "M40"}) EXPECT_NE(findCylinderType(type), nullptr) << type;
  EXPECT_EQ(findCylinderType("M99"), nullptr);
}

TEST(Catalogue, EveryActuatorOfEverySceneMatchesIt) {
  const auto scenes = adroit::description::sceneNames(adroit_test::shareDir());
  ASSERT_FALSE(scenes.empty());
  for (const auto& scene : scenes) {
    for (bool planning : {false, true}) {
      SCOPED_TRACE(scene + (planning ? " (planning)" : ""));
      auto loaded = adroit_test::loadScene(scene, planning);
      const mjModel* m = loaded.model.get();
      ASSERT_EQ(m->nuser_actuator, 2);
      int checked = 0;
      for (int a = 0; a < m->nu; ++a) {
        if (m->actuator_trntype[a] != mjTRN_TENDON) continue;
        const std::string name = mj_id2name(m, mjOBJ_ACTUATOR, a);
        const std::string type = text(m, "cylinder_" + name);
        const auto* c = findCylinderType(type);
        ASSERT_NE(c, nullptr) << name << ": type '" << type << "' is not in the catalogue";
        EXPECT_NEAR(m->actuator_user[2 * a], c->bore_diameter, kDigits) << name << " bore";
        EXPECT_NEAR(m->actuator_user[2 * a + 1], c->stroke, kDigits) << name << " stroke";
        const double max_tension = (kSupply - kAtmosphericPressure) * M_PI * c->bore_diameter * c->bore_diameter / 4;
        EXPECT_NEAR(m->actuator_ctrlrange[2 * a + 1], max_tension, 1e-3) << name << " ctrl range";
        ++checked;
      }
      EXPECT_GE(checked, 40);  // 40 hand cylinders, 48 with the arm
    }
  }
}
