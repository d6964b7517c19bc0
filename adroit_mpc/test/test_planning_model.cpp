// Planning settings on the real bottle scene, and contact pruning against the unpruned
// variant once the bottle has landed in the hand.
#include <adroit_description/scenes.h>
#include <adroit_mpc/planning_model.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <functional>
#include <string>
#include <tuple>
#include <vector>

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
  s.explicit_pairs = false;  // the description's 18 pairs alone (ExplicitPairs... below)
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

// The simulated world's object changes as the planning model's does (mpc_success --object-mass,
// --object-scale), with the derived constants: the world's total mass follows the object's.
TEST(PlanningModel, ObjectScalingOfTheSimulatedWorldMatchesThePlanningModels) {
  PlanningModelSettings s;
  s.object_mass = 0.5;
  s.object_size_scale = 1.2;
  auto planning = loadPlanningModel(bottleFile(), s);
  const std::string world_file = adroit::description::sceneFile(descriptionShareDir(), "bottle", false);
  auto base = adroit::loadModelFile(world_file).model;
  auto world = adroit::loadModelFile(world_file).model;
  ASSERT_TRUE(scaleObjectBody(world.get(), 0.5, 1.2));
  const int body = mj_name2id(world.get(), mjOBJ_BODY, "object");
  const int geom = mj_name2id(world.get(), mjOBJ_GEOM, "C_object");
  const int plan_body = mj_name2id(planning.get(), mjOBJ_BODY, "object");
  const int plan_geom = mj_name2id(planning.get(), mjOBJ_GEOM, "C_object");
  EXPECT_DOUBLE_EQ(world->body_mass[body], planning->body_mass[plan_body]);
  for (int k = 0; k < 3; ++k) {
    EXPECT_DOUBLE_EQ(world->geom_size[3 * geom + k], planning->geom_size[3 * plan_geom + k]) << k;
    EXPECT_DOUBLE_EQ(world->body_inertia[3 * body + k], planning->body_inertia[3 * plan_body + k]) << k;
  }
  EXPECT_NEAR(world->body_subtreemass[0] - base->body_subtreemass[0], 0.5 - base->body_mass[body], 1e-12);
  auto hand = adroit::loadModelFile(adroit::description::sceneFile(descriptionShareDir(), "hand", false)).model;
  EXPECT_FALSE(scaleObjectBody(hand.get(), 0.5, 1.0));  // no object: nothing changed
  EXPECT_THROW(scaleObjectBody(world.get(), -1, 1.0), std::invalid_argument);
  EXPECT_THROW(scaleObjectBody(world.get(), 0, 0.0), std::invalid_argument);
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

// A model path from a parameter is read only if it is a regular file: a FIFO would block the
// MPC node's start for good, /dev/zero read without end.
TEST(PlanningModel, ModelTextOnlyFromARegularFile) {
  const std::string fifo = ::testing::TempDir() + "/model_fifo_" + std::to_string(getpid()) + ".xml";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& path : {fifo, std::string("/dev/zero")}) {
    try {
      readModelText(path);
      ADD_FAILURE() << path << " was read";
    } catch (const adroit::ModelLoadError& e) {
      EXPECT_EQ(std::string(e.what()), "cannot read model file " + path + ": not a regular file (" +
                                           (path == fifo ? "a FIFO" : "a character device") + ")");
    }
  }
  unlink(fifo.c_str());
  EXPECT_NE(readModelText(bottleFile()).find("<mujoco"), std::string::npos);
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

namespace {

struct ContactKey {
  int geom_low, geom_high, dim;
  double dist, friction, solref, solimp, margin;
};

// The contacts of the last collision pass, each by its geoms (in either order) and the
// parameters MuJoCo gave it, sorted so two passes compare regardless of their order.
std::vector<ContactKey> contacts(const mjData* d) {
  std::vector<ContactKey> out;
  for (int c = 0; c < d->ncon; ++c) {
    const mjContact& k = d->contact[c];
    out.push_back({std::min(k.geom1, k.geom2), std::max(k.geom1, k.geom2), k.dim, k.dist, k.friction[0],
                   k.solref[0], k.solimp[2], k.includemargin});
  }
  std::sort(out.begin(), out.end(), [](const ContactKey& a, const ContactKey& b) {
    return std::tie(a.geom_low, a.geom_high, a.dist) < std::tie(b.geom_low, b.geom_high, b.dist);
  });
  return out;
}

// The same rollout on both models (ctrl from `control(t, ctrl)`): every step's contacts are the
// same ones with the same parameters, and the trajectories agree. Returns the contacts seen.
int expectSameRollout(const mjModel* dynamic, const mjModel* paired, const char* key, double seconds,
                      const std::function<void(double, mjtNum*)>& control) {
  adroit::DataPtr a = adroit::makeData(dynamic), b = adroit::makeData(paired);
  const int k = mj_name2id(dynamic, mjOBJ_KEY, key);
  EXPECT_GE(k, 0);
  mj_resetDataKeyframe(dynamic, a.get(), k);
  mj_resetDataKeyframe(paired, b.get(), k);
  int seen = 0;
  while (a->time < seconds) {
    control(a->time, a->ctrl);
    mju_copy(b->ctrl, a->ctrl, dynamic->nu);
    mj_step(dynamic, a.get());
    mj_step(paired, b.get());
    const auto ca = contacts(a.get()), cb = contacts(b.get());
    EXPECT_EQ(ca.size(), cb.size()) << "at t " << a->time;
    if (ca.size() != cb.size()) return seen;
    for (std::size_t c = 0; c < ca.size(); ++c) {
      EXPECT_EQ(ca[c].geom_low, cb[c].geom_low);
      EXPECT_EQ(ca[c].geom_high, cb[c].geom_high);
      EXPECT_EQ(ca[c].dim, cb[c].dim);
      EXPECT_NEAR(ca[c].dist, cb[c].dist, 1e-9);
      EXPECT_DOUBLE_EQ(ca[c].friction, cb[c].friction);
      EXPECT_DOUBLE_EQ(ca[c].solref, cb[c].solref);
      EXPECT_DOUBLE_EQ(ca[c].solimp, cb[c].solimp);
      EXPECT_DOUBLE_EQ(ca[c].margin, cb[c].margin);
    }
    seen += static_cast<int>(ca.size());
    for (int i = 0; i < dynamic->nq; ++i) EXPECT_NEAR(a->qpos[i], b->qpos[i], 1e-7) << "qpos " << i << " at t " << a->time;
  }
  return seen;
}

}  // namespace

TEST(PlanningModel, ExplicitPairsCollideAsTheDynamicFilterDoes) {
  // Typing's contact settings on the keypad: the first finger curls onto its keys, the thumb
  // towards the fingers, the palm is pressed down into the keypad.
  PlanningModelSettings s;
  s.timestep = 0.01;
  s.contact_margin = s.contact_softness = 0.001;
  s.explicit_pairs = false;
  const std::string keypad = adroit::description::sceneFile(descriptionShareDir(), "keypad", true);
  auto dynamic = loadPlanningModel(keypad, s);
  s.explicit_pairs = true;
  auto paired = loadPlanningModel(keypad, s);
  EXPECT_EQ(dynamic->opt.collision, mjCOL_ALL);
  EXPECT_EQ(paired->opt.collision, mjCOL_PAIR);
  EXPECT_GT(paired->npair, dynamic->npair);
  const auto flexing = [&](double t, mjtNum* ctrl) {
    for (int a = 0; a < dynamic->nu; ++a) {
      const std::string name = mj_id2name(dynamic.get(), mjOBJ_ACTUATOR, a);
      const bool flex = name.find("_flex") != std::string::npos;
      const bool pushes = name.find("FF") != std::string::npos || name.find("TH") != std::string::npos ||
                          name.find("WRJ1") != std::string::npos;
      ctrl[a] = flex && pushes ? std::min(40.0, 200 * t) : 0.3;
    }
  };
  EXPECT_GT(expectSameRollout(dynamic.get(), paired.get(), "rest", 1.0, flexing), 20);

  // The bottle falling into the hand with the object tasks' settings.
  s = PlanningModelSettings{};
  s.timestep = 0.02;
  s.explicit_pairs = false;
  auto bottle_dynamic = loadPlanningModel(bottleFile(), s);
  s.explicit_pairs = true;
  auto bottle_paired = loadPlanningModel(bottleFile(), s);
  EXPECT_GT(expectSameRollout(bottle_dynamic.get(), bottle_paired.get(), "rest", 1.0,
                              [&](double, mjtNum* ctrl) { std::fill(ctrl, ctrl + bottle_dynamic->nu, 0.3); }),
            20);
}

TEST(PlanningModel, ExplicitPairsKeepExcludesAndTheWorld) {
  // Three balls dropped onto a floor, two of them overlapping from the start: an <exclude> keeps
  // that pair apart, the third touches both; a pendulum on the world lies on the floor too
  // (the parent filter spares the world). Same contacts both ways.
  const std::string xml = R"(
<mujoco><option timestep="0.005"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="a" pos="0 0 0.1"><freejoint/><geom name="ga" size="0.05"/></body>
    <body name="b" pos="0.06 0 0.1"><freejoint/><geom name="gb" size="0.05"/></body>
    <body name="c" pos="0.03 0 0.25"><freejoint/><geom name="gc" size="0.05"/></body>
    <body name="arm" pos="0.4 0 0.05"><joint type="hinge" axis="0 1 0"/><geom name="rod" type="capsule" fromto="0 0 0 0.1 0 0" size="0.02"/></body>
  </worldbody>
  <contact><exclude body1="a" body2="b"/></contact>
</mujoco>)";
  adroit::LoadedModel dynamic = adroit::loadModelString(xml);
  int pairs = 0;
  adroit::LoadedModel paired = adroit::loadModelString(explicitContactPairsXml(xml, dynamic.model.get(), &pairs));
  paired.model->opt.collision = mjCOL_PAIR;
  // floor-a, floor-b, floor-c, floor-rod, a-c, b-c, a-rod, b-rod, c-rod; not a-b.
  EXPECT_EQ(pairs, 9);
  adroit::DataPtr a = adroit::makeData(dynamic.model.get()), b = adroit::makeData(paired.model.get());
  int seen = 0;
  for (int step = 0; step < 200; ++step) {
    mj_step(dynamic.model.get(), a.get());
    mj_step(paired.model.get(), b.get());
    const auto ca = contacts(a.get()), cb = contacts(b.get());
    ASSERT_EQ(ca.size(), cb.size()) << "step " << step;
    for (std::size_t c = 0; c < ca.size(); ++c) {
      EXPECT_EQ(ca[c].geom_low, cb[c].geom_low);
      EXPECT_EQ(ca[c].geom_high, cb[c].geom_high);
    }
    seen += static_cast<int>(ca.size());
  }
  EXPECT_GT(seen, 200);
  // A model whose colliding geoms are not all named cannot be written as pairs.
  const std::string unnamed = R"(<mujoco><worldbody><geom type="plane" size="1 1 0.1"/>
    <body pos="0 0 0.1"><freejoint/><geom size="0.05"/></body></worldbody></mujoco>)";
  EXPECT_EQ(explicitContactPairsXml(unnamed, adroit::loadModelString(unnamed).model.get()), "");
}
