// Every scene compiles in MuJoCo 2.2.2 without warnings, has the expected sizes and names,
// simulates without runtime warnings, and bad input fails with one clear line.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>

#include "adroit_core/model_tables.h"
#include "adroit_core/run_program.h"
#include "adroit_description/cylinders.h"
#include "test_helpers.h"

using adroit_test::expectedScenes;
using adroit_test::loadScene;

TEST(Scenes, ListMatchesTheIssue) {
  const auto names = adroit::description::sceneNames(adroit_test::shareDir());
  std::set<std::string> got(names.begin(), names.end());
  for (const auto& s : expectedScenes()) EXPECT_TRUE(got.count(s.name)) << s.name;
}

TEST(Scenes, EveryVariantLoadsCleanWithExpectedCounts) {
  for (const auto& facts : expectedScenes()) {
    for (bool planning : {false, true}) {
      SCOPED_TRACE(facts.name + (planning ? " (planning)" : ""));
      auto loaded = loadScene(facts.name, planning);
      EXPECT_TRUE(loaded.warning.empty()) << loaded.warning;
      const mjModel* m = loaded.model.get();
      const int dof = facts.arm ? 28 : 24;
      const int cylinders = facts.arm ? 48 : 40;
      const int object_nv = facts.object_qpos == 7 ? 6 : facts.object_qpos;
      EXPECT_EQ(m->nq, dof + facts.object_qpos + (facts.free_base ? 7 : 0));
      EXPECT_EQ(m->nv, dof + object_nv + (facts.free_base ? 6 : 0));
      EXPECT_EQ(m->nmocap, facts.free_base ? 1 : 0);
      EXPECT_EQ(m->neq, facts.free_base ? 1 : 0);
      EXPECT_EQ(m->nu, cylinders);
      EXPECT_EQ(m->ntendon, cylinders + 4);  // + the four DIP-PIP couplers
      EXPECT_DOUBLE_EQ(m->opt.timestep, 0.002);
    }
  }
}

TEST(Scenes, NamesOfJointsTendonsSensorsAndSites) {
  auto loaded = loadScene("arm_hand");
  adroit::ModelTables t(loaded.model.get());
  for (const auto& j : adroit_test::handJoints()) {
    EXPECT_TRUE(t.joints.contains(j)) << j;
    EXPECT_TRUE(t.sensors.contains("JP_" + j)) << j;
    EXPECT_TRUE(t.sensors.contains("JV_" + j)) << j;
  }
  for (const char* j : {"ARJ3", "ARJ2", "ARJ1", "ARJ0"}) EXPECT_TRUE(t.joints.contains(j)) << j;
  // Every independently actuated joint has an antagonistic pair; the DIPs (J0) have none.
  int pairs = 0;
  for (const auto& j : t.joints.names()) {
    const bool coupled = j.size() == 4 && j[1] == 'F' && j[3] == '0' && j[0] != 'T';
    const bool has_flex = t.tendons.contains("T_" + j + "_flex");
    const bool has_ext = t.tendons.contains("T_" + j + "_ext");
    EXPECT_EQ(has_flex, !coupled) << j;
    EXPECT_EQ(has_ext, !coupled) << j;
    if (has_flex && has_ext) {
      ++pairs;
      for (const char* prefix : {"TL_", "TV_", "AF_"}) {
        EXPECT_TRUE(t.sensors.contains(prefix + j + "_flex")) << prefix << j;
      }
      EXPECT_TRUE(t.actuators.contains("A_" + j + "_ext")) << j;
    }
  }
  EXPECT_EQ(pairs, 24);  // 20 hand + 4 arm
  for (const char* f : {"ff", "mf", "rf", "lf", "th"}) {
    EXPECT_TRUE(t.sites.contains(std::string("S_") + f + "tip")) << f;
    EXPECT_TRUE(t.sensors.contains(std::string("ST_") + f + "tip")) << f;
  }
  EXPECT_TRUE(t.sensors.contains("ST_palm"));
  for (const char* f : {"FF", "MF", "RF", "LF"}) EXPECT_TRUE(t.tendons.contains(std::string("T_") + f + "J1c"));
}

TEST(Scenes, ActuatorsArePullOnlyCylinders) {
  auto loaded = loadScene("arm_hand");
  const mjModel* m = loaded.model.get();
  const auto cylinders = adroit::description::cylinderTable(m);
  ASSERT_EQ(cylinders.size(), 48u);
  std::map<std::string, int> types;
  for (const auto& c : cylinders) {
    types[c.type]++;
    EXPECT_EQ(m->actuator_ctrlrange[2 * c.actuator], 0.0) << c.name << " must be pull-only";
    EXPECT_GT(c.max_tension, 0) << c.name;
    // Max tension is the supply pressure (about 620 kPa abs, thesis fig. 5.9) over the bore.
    EXPECT_NEAR(c.max_tension, (620e3 - 101325.0) * c.bore_area, 1.0) << c.name;
  }
  // Thesis 3.5.2: 36 M9 finger cylinders and 4 M16 wrist cylinders in the hand.
  EXPECT_EQ(types["M9"], 36);
  EXPECT_EQ(types["M16"], 4);
  for (const auto& c : cylinders) {
    if (c.type == "M9") {
      EXPECT_DOUBLE_EQ(c.bore_diameter, 0.009);
      EXPECT_DOUBLE_EQ(c.stroke, 0.0375);
    }
    if (c.type == "M16") {
      EXPECT_DOUBLE_EQ(c.bore_diameter, 0.016);
      EXPECT_DOUBLE_EQ(c.stroke, 0.050);
    }
  }
}

TEST(Scenes, PlanningVariantHasTable61SpringsAndArmature) {
  auto sim = loadScene("arm_hand", false);
  auto plan = loadScene("arm_hand", true);
  adroit::ModelTables t(plan.model.get());
  auto stiffness = [&](const char* j) { return plan.model->jnt_stiffness[t.joints.at(j)]; };
  auto armature = [&](const mjModel* m, const char* j) { return m->dof_armature[m->jnt_dofadr[t.joints.at(j)]]; };
  // Thesis Table 6.1.
  EXPECT_DOUBLE_EQ(stiffness("FFJ3"), 0.20);
  EXPECT_DOUBLE_EQ(stiffness("FFJ1"), 0.10);
  EXPECT_DOUBLE_EQ(stiffness("FFJ0"), 0.15);
  EXPECT_DOUBLE_EQ(stiffness("LFJ4"), 0.15);
  EXPECT_DOUBLE_EQ(stiffness("ARJ2"), 0.0);
  EXPECT_DOUBLE_EQ(armature(plan.model.get(), "ARJ2"), 2.40);
  EXPECT_DOUBLE_EQ(armature(plan.model.get(), "ARJ3"), 0.60);
  EXPECT_DOUBLE_EQ(armature(plan.model.get(), "THJ0"), 0.06);
  EXPECT_DOUBLE_EQ(sim.model->jnt_stiffness[t.joints.at("FFJ3")], 0.0);
  EXPECT_LT(armature(sim.model.get(), "THJ0"), 0.01);
}

// No planning model has joint friction loss (a constraint row per joint in every step of the
// planner's derivatives), while the simulated joints keep theirs; the keypad's planning
// fingers are light and unsprung (typing), never lighter than the physical joints.
TEST(Scenes, PlanningVariantsHaveNoFrictionLossAndTheKeypadLightFingers) {
  for (const auto& facts : expectedScenes()) {
    SCOPED_TRACE(facts.name);
    auto sim = loadScene(facts.name, false), plan = loadScene(facts.name, true);
    double sim_loss = 0;
    for (int i = 0; i < plan.model->nv; ++i) EXPECT_EQ(plan.model->dof_frictionloss[i], 0.0) << "dof " << i;
    for (int i = 0; i < sim.model->nv; ++i) sim_loss += sim.model->dof_frictionloss[i];
    EXPECT_GT(sim_loss, 0.0);
  }
  auto sim = loadScene("keypad", false), plan = loadScene("keypad", true);
  adroit::ModelTables t(plan.model.get());
  for (const char* j : {"FFJ3", "FFJ1", "MFJ2", "RFJ0", "THJ0", "WRJ0"}) {
    SCOPED_TRACE(j);
    const int dof = plan.model->jnt_dofadr[t.joints.at(j)];
    EXPECT_DOUBLE_EQ(plan.model->jnt_stiffness[t.joints.at(j)], 0.0);
    EXPECT_DOUBLE_EQ(plan.model->dof_armature[dof], std::max(0.003, sim.model->dof_armature[dof]));
  }
}

TEST(Scenes, SimulatesWithoutRuntimeWarnings) {
  for (const auto& facts : expectedScenes()) {
    SCOPED_TRACE(facts.name);
    auto loaded = loadScene(facts.name);
    const mjModel* m = loaded.model.get();
    adroit::DataPtr d = adroit::makeData(m);
    const int key = mj_name2id(m, mjOBJ_KEY, "home");
    ASSERT_GE(key, 0);
    mj_resetDataKeyframe(m, d.get(), key);
    for (int i = 0; i < 1000; ++i) mj_step(m, d.get());  // 2 s, zero tension
    EXPECT_EQ(adroit::warningCount(d.get()), 0) << adroit::warningSummary(d.get());
    for (int i = 0; i < m->nq; ++i) ASSERT_TRUE(std::isfinite(d->qpos[i]));
  }
}

TEST(Scenes, KeypadKeysAreSpringLoaded) {
  auto loaded = loadScene("keypad");
  const mjModel* m = loaded.model.get();
  adroit::DataPtr d = adroit::makeData(m);
  const int key = mj_name2id(m, mjOBJ_JOINT, "KEY_5");
  ASSERT_GE(key, 0);
  const int depth_id = mj_name2id(m, mjOBJ_NUMERIC, "keypad_press_depth");
  ASSERT_GE(depth_id, 0);
  const double press_depth = m->numeric_data[m->numeric_adr[depth_id]];
  const int dof = m->jnt_dofadr[key];
  // Push the key down with 2 N: it bottoms out, deeper than the press depth.
  for (int i = 0; i < 500; ++i) {
    d->qfrc_applied[dof] = -2.0;
    mj_step(m, d.get());
  }
  EXPECT_LT(d->qpos[m->jnt_qposadr[key]], -press_depth);
  // A light touch (0.2 N, below the spring preload) does not register.
  for (int i = 0; i < 500; ++i) {
    d->qfrc_applied[dof] = -0.2;
    mj_step(m, d.get());
  }
  EXPECT_GT(d->qpos[m->jnt_qposadr[key]], -press_depth);
  // Released, the spring returns it to the top.
  for (int i = 0; i < 500; ++i) {
    d->qfrc_applied[dof] = 0;
    mj_step(m, d.get());
  }
  EXPECT_GT(d->qpos[m->jnt_qposadr[key]], -0.0005);
}

// Thesis 9.2.3: the mocap body moves the hand's base through a soft weld; contacts keep
// priority over it.
TEST(Scenes, TeleopBaseFollowsItsMocapBody) {
  auto loaded = loadScene("teleop_ball");
  const mjModel* m = loaded.model.get();
  adroit::DataPtr d = adroit::makeData(m);
  mj_resetDataKeyframe(m, d.get(), mj_name2id(m, mjOBJ_KEY, "home"));
  const int base = mj_name2id(m, mjOBJ_BODY, "forearm");
  const int target = mj_name2id(m, mjOBJ_BODY, "hand_base_target");
  ASSERT_GE(base, 0);
  ASSERT_GE(target, 0);
  const int mocap = m->body_mocapid[target];
  ASSERT_GE(mocap, 0);
  const double start[3] = {d->mocap_pos[3 * mocap], d->mocap_pos[3 * mocap + 1], d->mocap_pos[3 * mocap + 2]};
  auto distance = [&](const double* a, const double* b) {
    return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
  };
  for (int i = 0; i < 500; ++i) mj_step(m, d.get());  // 1 s held: the 5 kg hand sags a little
  EXPECT_LT(distance(d->xpos + 3 * base, start), 0.01);
  // The operator moves 10 cm up and 5 cm sideways over 0.2 s: the base arrives within 1 cm.
  const double goal[3] = {start[0] + 0.05, start[1], start[2] + 0.10};
  for (int i = 1; i <= 100; ++i) {
    for (int k = 0; k < 3; ++k) d->mocap_pos[3 * mocap + k] = start[k] + (goal[k] - start[k]) * i / 100.0;
    mj_step(m, d.get());
  }
  for (int i = 0; i < 150; ++i) mj_step(m, d.get());
  EXPECT_LT(distance(d->xpos + 3 * base, goal), 0.01);
  // Pushed 10 cm into the table, the hand stops on it: contacts win over the weld.
  const double into_table[3] = {start[0], start[1], -0.10};
  for (int k = 0; k < 3; ++k) d->mocap_pos[3 * mocap + k] = into_table[k];
  for (int i = 0; i < 500; ++i) mj_step(m, d.get());
  double lowest = 1e9;
  for (int b = 1; b < m->nbody; ++b)
    if (m->body_rootid[b] == base) lowest = std::min(lowest, d->xpos[3 * b + 2]);
  EXPECT_GT(lowest, -0.01) << "a hand body went through the table top (z = 0)";
  EXPECT_EQ(adroit::warningCount(d.get()), 0) << adroit::warningSummary(d.get());
}

TEST(BadInput, UnknownSceneNamesTheKnownOnes) {
  try {
    adroit::description::sceneFile(adroit_test::shareDir(), "kitchen");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'kitchen'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("arm_hand"), std::string::npos);
  }
}

namespace {
struct CliRun {
  int status;
  std::string output;
};
CliRun runReport(std::vector<std::string> args) {
  args.insert(args.begin(), SCENE_REPORT_BIN);
  adroit::ProgramOptions options;
  options.timeout_s = 120;
  options.capture_output = true;
  options.merge_stderr = true;
  const auto run = adroit::runProgram(args, options);
  return {run.exit_code, run.output};
}
int lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }
}  // namespace

TEST(BadInput, ReportRefusesUnknownSceneWithOneLine) {
  const CliRun r = runReport({"--dir", adroit_test::shareDir(), "--scene", "kitchen"});
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(lines(r.output), 1) << r.output;
  EXPECT_NE(r.output.find("unknown scene 'kitchen'"), std::string::npos) << r.output;
}

TEST(BadInput, ReportQuotesMujocoOnMalformedOrMissingFile) {
  char dir[] = "/tmp/adroit_desc_test_XXXXXX";
  ASSERT_NE(mkdtemp(dir), nullptr);
  const std::string d(dir);
  std::filesystem::create_directories(d + "/mjcf");
  std::ofstream(d + "/scenes.txt") << "broken\nmissing\n";
  std::ofstream(d + "/mjcf/broken.xml") << "<mujoco><worldbody><body><geom type='sphere' size='x'/>";
  CliRun r = runReport({"--dir", d, "--scene", "broken"});
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(lines(r.output), 1) << r.output;
  EXPECT_NE(r.output.find(d + "/mjcf/broken.xml"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Error"), std::string::npos) << "MuJoCo's own message expected: " << r.output;
  r = runReport({"--dir", d, "--scene", "missing"});
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(lines(r.output), 1) << r.output;
  EXPECT_NE(r.output.find(d + "/mjcf/missing.xml"), std::string::npos) << r.output;
  r = runReport({"--seconds", "-1"});
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(lines(r.output), 1) << r.output;
  std::filesystem::remove_all(d);
}

TEST(Scenes, PackageShareDirSearchesThePrefixPaths) {
  // Two prefixes: the package's share directory with the marker is in the second one; a
  // ROS_PACKAGE_PATH entry holds the package directly (a source tree).
  const std::string root = std::string(::testing::TempDir()) + "/share_dir_test";
  for (const std::string dir : {root, root + "/a", root + "/b", root + "/b/share", root + "/b/share/pkgx", root + "/src",
                                root + "/src/pkgy"})
    ::mkdir(dir.c_str(), 0755);
  std::ofstream(root + "/b/share/pkgx/marker.txt") << "x";
  std::ofstream(root + "/src/pkgy/other.txt") << "y";
  ::setenv("CMAKE_PREFIX_PATH", (root + "/a::" + root + "/b").c_str(), 1);
  ::setenv("ROS_PACKAGE_PATH", (root + "/src").c_str(), 1);
  EXPECT_EQ(adroit::description::packageShareDir("pkgx", "marker.txt"), root + "/b/share/pkgx");
  EXPECT_EQ(adroit::description::packageShareDir("pkgy", "other.txt"), root + "/src/pkgy");
  try {
    adroit::description::packageShareDir("pkgx", "no_such_marker.txt");
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("CMAKE_PREFIX_PATH"), std::string::npos) << e.what();
  }
}
