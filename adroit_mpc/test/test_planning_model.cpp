// Planning settings on the real bottle scene, and contact pruning against the unpruned
// variant once the bottle has landed in the hand.
#include <adroit_description/scenes.h>
#include <adroit_mpc/planning_model.h>
#include <gtest/gtest.h>

using namespace adroit_mpc;

namespace {

std::string bottleFile() {
  return adroit::description::sceneFile(descriptionShareDir(), "bottle", true);
}

// Mean active contacts over the last `window` steps of `seconds` at zero tension.
double meanContactsAfterLanding(const mjModel* m, double seconds, double window) {
  adroit::DataPtr d = adroit::makeData(m);
  double sum = 0;
  int count = 0;
  while (d->time < seconds) {
    mj_step(m, d.get());
    if (d->time > seconds - window) {
      sum += activeContacts(d.get());
      ++count;
    }
  }
  return sum / count;
}

}  // namespace

TEST(PlanningModel, SettingsAreApplied) {
  PlanningModelSettings s;
  s.timestep = 0.005;
  s.contact_margin = 0.01;
  s.contact_softness = 0.005;
  s.solver_iterations = 7;
  auto m = loadPlanningModel(bottleFile(), s);
  EXPECT_EQ(m->opt.timestep, 0.005);
  EXPECT_EQ(m->opt.iterations, 7);
  EXPECT_TRUE(m->opt.disableflags & mjDSBL_SENSOR);
  const int object = mj_name2id(m.get(), mjOBJ_GEOM, "C_object");
  const int palm = mj_name2id(m.get(), mjOBJ_GEOM, "C_palm0");
  const int wrap = mj_name2id(m.get(), mjOBJ_GEOM, "W_FFJ3");
  ASSERT_GE(object, 0);
  ASSERT_GE(wrap, 0);
  EXPECT_EQ(m->geom_margin[object], 0.01);
  EXPECT_EQ(m->geom_margin[palm], 0.01);
  EXPECT_EQ(m->geom_solimp[mjNIMP * object + 2], 0.005);
  EXPECT_GE(m->geom_solref[mjNREF * object], 2 * 0.005);
  EXPECT_NE(m->geom_margin[wrap], 0.01);  // wrapping cylinders never collide: untouched
  ASSERT_EQ(m->npair, 18);
  for (int p = 0; p < m->npair; ++p) {
    EXPECT_EQ(m->pair_margin[p], 0.01);
    EXPECT_EQ(m->pair_solimp[mjNIMP * p + 2], 0.005);
  }
  // Sensors off: a step leaves sensordata untouched (the joint position sensors would not be 0).
  adroit::DataPtr d = adroit::makeData(m.get());
  mju_copy(d->qpos, m->key_qpos + m->nq * mj_name2id(m.get(), mjOBJ_KEY, "rest"), m->nq);
  mj_step(m.get(), d.get());
  for (int i = 0; i < m->nsensordata; ++i) ASSERT_EQ(d->sensordata[i], 0.0) << i;

  s.disable_sensors = false;
  auto with_sensors = loadPlanningModel(bottleFile(), s);
  adroit::DataPtr d2 = adroit::makeData(with_sensors.get());
  mju_copy(d2->qpos, d->qpos, m->nq);
  mj_forward(with_sensors.get(), d2.get());
  double sum = 0;
  for (int i = 0; i < m->nsensordata; ++i) sum += std::fabs(d2->sensordata[i]);
  EXPECT_GT(sum, 0.0);
}

TEST(PlanningModel, ObjectOverridesScaleMassAndSize) {
  PlanningModelSettings s;
  auto base = loadPlanningModel(bottleFile(), s);
  s.object_mass = 0.5;
  s.object_size_scale = 1.2;
  auto m = loadPlanningModel(bottleFile(), s);
  const int body = mj_name2id(m.get(), mjOBJ_BODY, "object");
  const int geom = mj_name2id(m.get(), mjOBJ_GEOM, "C_object");
  EXPECT_DOUBLE_EQ(m->body_mass[body], 0.5);
  EXPECT_NEAR(m->geom_size[3 * geom], 1.2 * base->geom_size[3 * geom], 1e-12);
  const double ratio = 0.5 / base->body_mass[body] * 1.2 * 1.2;
  EXPECT_NEAR(m->body_inertia[3 * body], ratio * base->body_inertia[3 * body], 1e-12);
}

TEST(PlanningModel, TendonForcesStartAtTheRobotsMinimumTension) {
  PlanningModelSettings s;
  s.min_tension = 0;
  auto physical = loadPlanningModel(bottleFile(), s);
  s.min_tension = 0.3;
  auto m = loadPlanningModel(bottleFile(), s);
  int tendons = 0;
  for (int a = 0; a < m->nu; ++a) {
    if (m->actuator_trntype[a] != mjTRN_TENDON) continue;
    ++tendons;
    ASSERT_LT(physical->actuator_ctrlrange[2 * a], 0.3) << a;  // the description's bound is below it
    EXPECT_EQ(m->actuator_ctrlrange[2 * a], 0.3) << a;
    EXPECT_EQ(m->actuator_ctrlrange[2 * a + 1], physical->actuator_ctrlrange[2 * a + 1]) << a;
  }
  EXPECT_GE(tendons, 20);
  s.min_tension = 1e4;  // above every upper bound
  EXPECT_THROW(loadPlanningModel(bottleFile(), s), std::invalid_argument);
  s.min_tension = -1;
  EXPECT_THROW(loadPlanningModel(bottleFile(), s), std::invalid_argument);
}

TEST(PlanningModel, BadSettingsAreRejectedWithTheirName) {
  PlanningModelSettings s;
  s.timestep = 0;
  try {
    loadPlanningModel(bottleFile(), s);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("timestep"), std::string::npos);
  }
  s = PlanningModelSettings{};
  s.object_mass = 1.0;
  EXPECT_THROW(loadPlanningModel(adroit::description::sceneFile(descriptionShareDir(), "hand", true), s),
               std::invalid_argument);  // no object in the hand scene
  EXPECT_THROW(unprunedXml("<mujoco/>"), std::invalid_argument);
}

TEST(PlanningModel, UnprunedVariantHasMoreContactsOnceTheBottleLanded) {
  PlanningModelSettings s;  // thesis table 6.3 dynamic manipulation: 5 ms, 0.01 m, 0.005 m
  auto pruned = loadPlanningModel(bottleFile(), s);
  auto unpruned = loadUnprunedPlanningModel(bottleFile(), s);
  EXPECT_EQ(unpruned->npair, 0);
  EXPECT_EQ(unpruned->nbody, pruned->nbody);
  int hand_geoms_colliding = 0;
  for (int g = 0; g < unpruned->ngeom; ++g)
    if (unpruned->geom_contype[g] == 1 && unpruned->geom_conaffinity[g] == 1 && unpruned->geom_condim[g] == 3)
      ++hand_geoms_colliding;
  EXPECT_GT(hand_geoms_colliding, 20);
  const double before = meanContactsAfterLanding(unpruned.get(), 0.8, 0.2);
  const double after = meanContactsAfterLanding(pruned.get(), 0.8, 0.2);
  EXPECT_GT(after, 0.0);  // the bottle rests on the hand
  EXPECT_GT(before, after + 1.0);
}
