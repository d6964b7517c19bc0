// SimulatedRobot on the generated ADROIT scenes: state save/restore and resets are exact,
// safety (e-stop, watchdog, faults) and command validation behave as specified, and the
// pneumatic mode settles where the plant's steady-state equation says.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "adroit_driver/simulated_robot.h"
#include "adroit_pneumatics/flow.h"

namespace adroit::driver {
namespace {

constexpr double kAtm = 101325.0;

SimConfig config(const std::string& scene, ActuationMode mode = ActuationMode::kPneumatic, bool realism = true) {
  SimConfig c;
  c.model_path = std::string(ADROIT_MJCF_DIR) + "/" + scene + ".xml";
  c.mode = mode;
  c.sensors.enabled = realism;
  return c;
}

void commandAll(SimulatedRobot& robot, double value) {
  const std::size_t n = robot.cylinderNames().size();
  std::vector<std::uint16_t> index(n);
  for (std::size_t i = 0; i < n; ++i) index[i] = static_cast<std::uint16_t>(i);
  const auto r = robot.config().mode == ActuationMode::kPneumatic
                     ? robot.commandValves({}, index, std::vector<double>(n, value))
                     : robot.commandForces({}, index, std::vector<double>(n, value));
  ASSERT_TRUE(r.applied || robot.safety().safe_state) << r.error;
}

// Runs `steps` steps re-sending `volts` every 5 ms (a 200 Hz controller).
void drive(SimulatedRobot& robot, double value, int steps) {
  for (int k = 0; k < steps; ++k) {
    if (k % 2 == 0) commandAll(robot, value);
    robot.step();
  }
}

std::vector<double> qpos(const SimulatedRobot& r) { return {r.data()->qpos, r.data()->qpos + r.model()->nq}; }
std::vector<double> qvel(const SimulatedRobot& r) { return {r.data()->qvel, r.data()->qvel + r.model()->nv}; }

TEST(SimulatedRobot, LoadsTheArmHandSceneWithAnObject) {
  SimulatedRobot robot(config("ball"));
  EXPECT_EQ(robot.cylinderNames().size(), 48u);
  EXPECT_EQ(robot.jointNames().size(), 28u);
  EXPECT_TRUE(robot.hasObject());
  EXPECT_EQ(robot.touchNames().size(), 17u);
  // A_ARJ2_flex: the shoulder's bundle of five M24 units, one cylinder of the summed bore area.
  EXPECT_EQ(robot.cylinders()[2].type, "M24x5");
  EXPECT_NEAR(robot.plant()->spec(2).bore_diameter, 0.024 * std::sqrt(5.0), 1e-6);
}

TEST(SimulatedRobot, BadConfigurationAndModelsGiveOneClearError) {
  SimConfig c = config("hand");
  c.watchdog_timeout = 0.5;
  try {
    SimulatedRobot robot(c);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("~watchdog_timeout"), std::string::npos) << e.what();
  }
  const std::string bad = ::testing::TempDir() + "/broken_model.xml";
  std::ofstream(bad) << "<mujoco><worldbody><geom type='sphere'/></worldbody>";
  SimConfig broken = config("hand");
  broken.model_path = bad;
  try {
    SimulatedRobot robot(broken);
    FAIL();
  } catch (const ModelLoadError& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
  }
  c = config("hand");
  c.initial_keyframe = "nope";
  EXPECT_THROW(SimulatedRobot robot(c), std::invalid_argument);
}

TEST(SimulatedRobot, RestoringAStateReplaysExactlyIncludingPressuresAndSensors) {
  SimulatedRobot robot(config("ball"));
  drive(robot, 2.0, 150);
  const SimState saved = robot.state();
  auto record = [&robot] {
    std::vector<double> out;
    for (int k = 0; k < 100; ++k) {
      commandAll(robot, k < 50 ? 3.0 : -1.0);
      robot.step();
      const auto q = qpos(robot);
      out.insert(out.end(), q.begin(), q.end());
      const auto& p = robot.plant()->pressure();
      out.insert(out.end(), p.begin(), p.end());
      const auto& s = robot.sensed();
      out.insert(out.end(), s.joint_position.begin(), s.joint_position.end());
      out.insert(out.end(), s.pressure.begin(), s.pressure.end());
    }
    return out;
  };
  const auto first = record();
  const double clock_before = robot.clock();
  robot.setState(saved);
  EXPECT_EQ(robot.clock(), clock_before);  // time never goes back
  const auto second = record();
  ASSERT_EQ(first.size(), second.size());
  for (std::size_t i = 0; i < first.size(); ++i) ASSERT_EQ(first[i], second[i]) << "element " << i;
}

TEST(SimulatedRobot, ResetToKeyframeAndToStateRestoreExactly) {
  SimulatedRobot robot(config("ball", ActuationMode::kPneumatic, false));
  std::string error;
  ASSERT_TRUE(robot.resetToKeyframe("rest", &error)) << error;
  const auto q0 = qpos(robot);
  EXPECT_EQ(q0[7], 0.3);  // FFJ2 in the rest keyframe of the generated model
  drive(robot, 2.5, 200);
  ASSERT_NE(qpos(robot), q0);
  ASSERT_TRUE(robot.resetToKeyframe("rest", &error));
  EXPECT_EQ(qpos(robot), q0);
  for (double v : qvel(robot)) EXPECT_EQ(v, 0.0);
  for (double p : robot.plant()->pressure()) EXPECT_EQ(p, kAtm);

  // Full state: positions, velocities, pressures, object.
  std::vector<double> q = q0, v(robot.model()->nv, 0.0), p(48);
  for (std::size_t i = 0; i < 7; ++i) q[i] += 0.01 * i;
  q[28] = 0.05;  // object x
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = 0.001 * i;
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = 150e3 + 1e3 * i;
  const double clock = robot.clock();
  ASSERT_TRUE(robot.resetToState(q, v, p, &error)) << error;
  EXPECT_EQ(qpos(robot), q);
  EXPECT_EQ(qvel(robot), v);
  EXPECT_EQ(robot.plant()->pressure(), p);
  EXPECT_EQ(robot.sensed().pressure, p);  // sensors restarted on the new state
  EXPECT_EQ(robot.sensed().object[0], 0.05);
  EXPECT_EQ(robot.clock(), clock);

  EXPECT_FALSE(robot.resetToKeyframe("nope", &error));
  EXPECT_NE(error.find("rest"), std::string::npos) << error;  // lists the known ones
  EXPECT_FALSE(robot.resetToState({1.0, 2.0}, {}, {}, &error));
  EXPECT_FALSE(robot.resetToState({}, {}, std::vector<double>(48, std::nan("")), &error));
  // A huge pressure is named shortly (%g), not in 309 digits.
  EXPECT_FALSE(robot.resetToState({}, {}, std::vector<double>(48, 1e308), &error));
  EXPECT_NE(error.find("1e+308"), std::string::npos) << error;
  EXPECT_LT(error.size(), 80u) << error;
}

TEST(SimulatedRobot, SetObjectPoseTakesWorldFrameVelocities) {
  SimulatedRobot robot(config("ball", ActuationMode::kPneumatic, false));
  std::string error;
  const double s = std::sqrt(0.5);
  ASSERT_TRUE(robot.setObjectPose({0.1, -0.2, 0.3}, {s, 0, 0, s}, {0.5, 0, 0}, {0, 0, 2.0}, &error)) << error;
  const auto& o = robot.sensed().object;
  EXPECT_NEAR(o[0], 0.1, 1e-12);
  EXPECT_NEAR(o[3], s, 1e-12);
  EXPECT_NEAR(o[6], s, 1e-12);
  EXPECT_NEAR(o[7], 0.5, 1e-12);   // linear: world frame
  EXPECT_NEAR(o[12], 2.0, 1e-12);  // angular about z: same axis in the body frame (rotation about z)
  EXPECT_FALSE(robot.setObjectPose({0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0}, {0, 0, 0}, &error));
  SimulatedRobot hand(config("hand"));
  EXPECT_FALSE(hand.setObjectPose({0, 0, 0}, {1, 0, 0, 0}, {0, 0, 0}, {0, 0, 0}, &error));
}

// Thesis 3.7: supply exhausted and every valve open to exhaust; pressures reach atmosphere.
// Returns, per cylinder, the time after the e-stop at which it stays within 5 kPa of it.
std::vector<double> estopExhaustTimes(SimulatedRobot& robot) {
  drive(robot, 5.0, 500);  // 1 s at full supply
  for (double p : robot.plant()->pressure()) EXPECT_GT(p, 350e3);
  robot.estop();
  const double t0 = robot.clock();
  std::vector<double> settled(robot.cylinders().size(), -1.0);
  while (robot.clock() < t0 + 1.5) {
    robot.step();
    for (double v : robot.appliedCommand()) EXPECT_EQ(v, -5.0);
    const auto& p = robot.plant()->pressure();
    for (std::size_t i = 0; i < p.size(); ++i) {
      const bool near = std::abs(p[i] - kAtm) <= 5e3;
      if (!near) settled[i] = -1.0;
      else if (settled[i] < 0) settled[i] = robot.clock() - t0;
    }
  }
  EXPECT_LT(robot.plant()->supplyPressure(), kAtm + 5e3);
  return settled;
}

TEST(SimulatedRobot, EstopExhaustsEveryHandCylinderWithin200ms) {
  SimulatedRobot robot(config("hand", ActuationMode::kPneumatic, false));
  const auto settled = estopExhaustTimes(robot);
  for (std::size_t i = 0; i < settled.size(); ++i) {
    EXPECT_GE(settled[i], 0.0) << robot.cylinderNames()[i];
    EXPECT_LE(settled[i], 0.2 + 1e-9) << robot.cylinderNames()[i];
  }
}

// Arm-hand: the vent path of every cylinder, the arm's M24/M40/M24x5 included, is fast enough
// (no gravity: no cylinder carries a load). With gravity a cylinder that holds the arm up
// cannot be at atmosphere before the arm has come down onto its limits: the chamber is
// compressed while the arm lowers, so those only have to reach atmosphere.
TEST(SimulatedRobot, EstopExhaustsArmHandCylindersWithin200msUnlessHoldingTheArm) {
  for (const bool gravity : {false, true}) {
    SimulatedRobot robot(config("arm_hand", ActuationMode::kPneumatic, false));
    // The robot steps its own model, so zero gravity here is zero gravity in the simulation.
    if (!gravity) const_cast<mjModel*>(robot.model())->opt.gravity[2] = 0.0;
    const auto settled = estopExhaustTimes(robot);
    int late = 0;
    for (std::size_t i = 0; i < settled.size(); ++i) {
      const std::string& name = robot.cylinderNames()[i];
      EXPECT_GE(settled[i], 0.0) << name << (gravity ? " (gravity)" : " (no gravity)");
      const bool arm = name.rfind("A_ARJ", 0) == 0;
      if (!gravity || !arm) {
        EXPECT_LE(settled[i], 0.2 + 1e-9) << name << (gravity ? " (gravity)" : " (no gravity)");
      }
      late += settled[i] > 0.2 ? 1 : 0;
    }
    if (gravity) std::printf("arm cylinders still holding the arm after 200 ms: %d\n", late);
  }
}

TEST(SimulatedRobot, EstopLatchesIgnoresCommandsAndRefusesReleaseWhileHeld) {
  SimulatedRobot robot(config("hand"));
  drive(robot, 1.0, 10);
  robot.setEstopInput(true);
  EXPECT_TRUE(robot.safety().safe_state);
  const auto ignored = robot.counters().ignored_while_safe;
  commandAll(robot, 4.0);
  robot.step();
  EXPECT_EQ(robot.counters().ignored_while_safe, ignored + 1);
  for (double v : robot.appliedCommand()) EXPECT_EQ(v, -5.0);
  std::string why;
  EXPECT_FALSE(robot.release(&why));
  EXPECT_NE(why.find("held"), std::string::npos);
  robot.setEstopInput(false);
  EXPECT_TRUE(robot.safety().safe_state);  // still latched until released
  EXPECT_TRUE(robot.release(&why)) << why;
  EXPECT_FALSE(robot.safety().safe_state);
  EXPECT_FALSE(robot.safety().watchdog_armed);
  commandAll(robot, 4.0);
  robot.step();
  for (double v : robot.appliedCommand()) EXPECT_EQ(v, 4.0);
}

TEST(SimulatedRobot, WatchdogEntersSafeStateWithinOneControlPeriodOfTheTimeout) {
  for (double timeout : {0.01, 0.05, 0.2}) {
    SimConfig c = config("hand");
    c.watchdog_timeout = timeout;
    SimulatedRobot robot(c);
    for (int k = 0; k < 100; ++k) robot.step();
    EXPECT_FALSE(robot.safety().safe_state) << "not armed before the first command";
    commandAll(robot, 1.0);
    const double last_command = robot.clock();
    while (!robot.safety().safe_state && robot.clock() < last_command + 1.0) robot.step();
    ASSERT_TRUE(robot.safety().watchdog_latched);
    // The step that observed the trip acted with the safe command.
    for (double v : robot.appliedCommand()) EXPECT_EQ(v, -5.0);
    const double entered = robot.clock() - robot.timestep();  // start of that step
    EXPECT_GE(entered - last_command, timeout - 1e-9) << timeout;
    EXPECT_LE(entered - last_command, timeout + 0.005) << timeout;  // one 200 Hz control period
  }
}

// The watchdog's margin: the age the stalest command reached, over the steps since it was
// last taken; nothing before the first command or while safe.
TEST(SimulatedRobot, CommandAgeMaxIsTheWatchdogsMarginSinceItWasTaken) {
  SimulatedRobot robot(config("hand"));
  for (int k = 0; k < 10; ++k) robot.step();
  EXPECT_EQ(robot.takeCommandAgeMax(), 0.0);  // not armed
  const double dt = robot.timestep();
  commandAll(robot, 1.0);
  for (int k = 0; k < 10; ++k) robot.step();  // observed at the start of each step: 0, dt, ..., 9 dt
  EXPECT_NEAR(robot.takeCommandAgeMax(), 9 * dt, 1e-9);
  commandAll(robot, 1.0);
  for (int k = 0; k < 3; ++k) robot.step();
  EXPECT_NEAR(robot.takeCommandAgeMax(), 2 * dt, 1e-9);  // taken: counted afresh
  robot.estop();
  for (int k = 0; k < 30; ++k) robot.step();
  EXPECT_EQ(robot.takeCommandAgeMax(), 0.0);  // safe: the watchdog does not watch
}

TEST(SimulatedRobot, WatchdogWatchesEveryCommandedCylinder) {
  SimulatedRobot robot(config("hand"));
  robot.commandValves({"A_FFJ3_flex"}, {}, {1.0});
  for (int k = 0; k < 40; ++k) {  // only A_THJ0_flex keeps being commanded
    robot.commandValves({"A_THJ0_flex"}, {}, {1.0});
    robot.step();
  }
  EXPECT_TRUE(robot.safety().watchdog_latched);
}

TEST(SimulatedRobot, BadCommandsAreRejectedCountedAndChangeNothing) {
  SimulatedRobot robot(config("hand"));
  commandAll(robot, 1.0);
  const auto before = robot.counters();
  EXPECT_FALSE(robot.commandValves({}, {0, 1}, {1.0, std::nan("")}).applied);
  EXPECT_FALSE(robot.commandValves({}, {0}, {INFINITY}).applied);
  EXPECT_FALSE(robot.commandValves({}, {0, 1}, {1.0}).applied);
  EXPECT_FALSE(robot.commandValves({"A_NOPE_flex"}, {}, {1.0}).applied);
  EXPECT_FALSE(robot.commandValves({}, {40}, {1.0}).applied);
  EXPECT_FALSE(robot.commandValves({}, {0}, {7.0}).applied);
  EXPECT_FALSE(robot.commandForces({}, {0}, {1.0}).applied);  // wrong mode
  const auto& after = robot.counters();
  EXPECT_EQ(after.rejected_not_finite, before.rejected_not_finite + 2);
  EXPECT_EQ(after.rejected_addressing, before.rejected_addressing + 1);
  EXPECT_EQ(after.rejected_name, before.rejected_name + 2);
  EXPECT_EQ(after.rejected_range, before.rejected_range + 1);
  EXPECT_EQ(after.rejected_wrong_mode, before.rejected_wrong_mode + 1);
  robot.step();
  for (double v : robot.appliedCommand()) EXPECT_EQ(v, 1.0);
  EXPECT_FALSE(robot.safety().safe_state);
}

// check*() then apply*() (a threaded caller) does what command*() does, counts included.
TEST(SimulatedRobot, CheckThenApplyIsTheSameAsCommand) {
  SimulatedRobot split(config("hand")), whole(config("hand"));
  const std::vector<std::vector<double>> commands = {{1.0, 2.0}, {1.0, std::nan("")}, {1.0, 7.0}, {1.0}};
  for (const auto& volts : commands) {
    const std::vector<std::uint16_t> index = {3, 5};
    const CommandResult a = split.applyValves(split.checkValves({}, index, volts));
    const CommandResult b = whole.commandValves({}, index, volts);
    EXPECT_EQ(a.verdict, b.verdict);
    EXPECT_EQ(a.applied, b.applied);
    EXPECT_EQ(a.error, b.error);
  }
  EXPECT_EQ(split.applyForces(split.checkForces({"A_FFJ3_flex"}, {}, {1.0})).applied, false);  // wrong mode
  whole.commandForces({"A_FFJ3_flex"}, {}, {1.0});
  const Counters &cs = split.counters(), &cw = whole.counters();
  EXPECT_EQ(cs.accepted, cw.accepted);
  EXPECT_EQ(cs.rejected_not_finite, cw.rejected_not_finite);
  EXPECT_EQ(cs.rejected_range, cw.rejected_range);
  EXPECT_EQ(cs.rejected_addressing, cw.rejected_addressing);
  EXPECT_EQ(cs.rejected_wrong_mode, 1u);
  EXPECT_EQ(cw.rejected_wrong_mode, 1u);
  split.step();
  whole.step();
  EXPECT_EQ(split.appliedCommand(), whole.appliedCommand());
  EXPECT_EQ(split.appliedCommand()[5], 2.0);

  SimulatedRobot force(config("hand", ActuationMode::kForce));
  const CommandResult clamped = force.applyForces(force.checkForces({"A_FFJ3_flex"}, {}, {1e4}));
  EXPECT_TRUE(clamped.applied);
  EXPECT_EQ(clamped.verdict, CommandVerdict::kClamped);
  EXPECT_FALSE(force.applyValves(force.checkValves({"A_FFJ3_flex"}, {}, {1.0})).applied);
  EXPECT_EQ(force.counters().rejected_wrong_mode, 1u);
  EXPECT_EQ(force.counters().clamped, 1u);
}

TEST(SimulatedRobot, ForceModeAppliesPullOnlyTensionsWithTheSlackMinimum) {
  SimulatedRobot robot(config("hand", ActuationMode::kForce, false));
  const double min_tension = robot.config().min_tension;
  const auto r = robot.commandForces({"A_FFJ3_flex", "A_FFJ3_ext", "A_FFJ2_flex"}, {}, {10.0, 0.0, 500.0});
  ASSERT_TRUE(r.applied);
  EXPECT_EQ(r.verdict, CommandVerdict::kClamped);
  robot.step();
  auto index = [&robot](const std::string& name) {
    const auto& names = robot.cylinderNames();
    return std::find(names.begin(), names.end(), name) - names.begin();
  };
  const auto flex = index("A_FFJ3_flex"), ext = index("A_FFJ3_ext"), flex2 = index("A_FFJ2_flex");
  EXPECT_EQ(robot.truth().tension[flex], 10.0);
  EXPECT_EQ(robot.truth().tension[ext], min_tension);
  EXPECT_EQ(robot.truth().tension[flex2], robot.cylinders()[flex2].max_tension);
  EXPECT_FALSE(robot.commandForces({"A_FFJ3_flex"}, {}, {-1.0}).applied);
  EXPECT_FALSE(robot.commandValves({"A_FFJ3_flex"}, {}, {1.0}).applied);
  robot.estop();
  robot.step();
  for (double t : robot.truth().tension) EXPECT_EQ(t, min_tension);
}

// Steady state of a chamber that has stopped moving: a_in phi(P_s, p) = (a_ex + a_leak) phi(p, P_r)
// (pneumatics notes, 5.3.3), solved here by bisection with the reference flow function.
double steadyStatePressure(const pneumatics::CylinderSpec& spec, double volts, double supply) {
  const double a_in = spec.valve.inlet(volts), a_out = spec.valve.exhaust(volts) + spec.leak_area;
  double lo = kAtm, hi = supply;
  for (int it = 0; it < 200; ++it) {
    const double p = 0.5 * (lo + hi);
    const double net = a_in * pneumatics::flowPhi(supply, p) - a_out * pneumatics::flowPhi(p, kAtm);
    (net > 0 ? lo : hi) = p;
  }
  return 0.5 * (lo + hi);
}

TEST(SimulatedRobot, ConstantValveCommandReachesThePlantSteadyStatePressure) {
  SimulatedRobot robot(config("hand", ActuationMode::kPneumatic, false));
  const double volts = 0.1;  // partly open: the steady state lies between room and supply
  drive(robot, volts, 2000);  // 4 s
  const auto& p = robot.plant()->pressure();
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double expected = steadyStatePressure(robot.plant()->spec(i), volts, robot.plant()->supplyPressure());
    ASSERT_GT(expected, kAtm + 20e3) << "test point must lie inside the range";
    ASSERT_LT(expected, robot.plant()->supplyPressure() - 20e3);
    EXPECT_NEAR(p[i], expected, 2e3) << robot.cylinderNames()[i] << " travel " << robot.truth().length[i]
                                     << " rate " << robot.truth().length_rate[i];
  }
}

TEST(SimulatedRobot, BadPhysicsIsAFaultThatIsNotSilentlyErased) {
  SimulatedRobot robot(config("hand", ActuationMode::kPneumatic, false));
  drive(robot, 1.0, 20);
  SimState s = robot.state();
  s.qvel[3] = 1e11;  // beyond mjMAXVAL: MuJoCo's own check would reset the data
  robot.setState(s);
  robot.step();
  EXPECT_TRUE(robot.safety().fault_latched);
  EXPECT_TRUE(robot.safety().safe_state);
  EXPECT_EQ(robot.counters().faults, 1u);
  EXPECT_NE(robot.safety().fault.find("qvel"), std::string::npos) << robot.safety().fault;
  EXPECT_EQ(qvel(robot)[3], 1e11);  // the evidence is still there
  EXPECT_EQ(qpos(robot), s.qpos);
  std::string why;
  EXPECT_FALSE(robot.release(&why));
  EXPECT_NE(why.find("fault"), std::string::npos);
  ASSERT_TRUE(robot.resetToKeyframe("home", &why));
  robot.step();
  EXPECT_FALSE(robot.safety().fault_persists);
  EXPECT_TRUE(robot.release(&why)) << why;
}

// --- issue 10: absurd but finite states, safety events, NaN in the plant, never-commanded
// cylinders, non-finite sensed values.

int jointIndex(const SimulatedRobot& robot, const std::string& name) {
  return mj_name2id(robot.model(), mjOBJ_JOINT, name.c_str());
}

// Refused states leave the robot as it was and stepping on faults nothing.
void expectUnchangedAndHealthy(SimulatedRobot& robot, const std::vector<double>& q, const std::vector<double>& v) {
  EXPECT_EQ(qpos(robot), q);
  EXPECT_EQ(qvel(robot), v);
  for (int k = 0; k < 50; ++k) robot.step();
  EXPECT_FALSE(robot.safety().fault_latched) << robot.safety().fault;
}

TEST(SimulatedRobot, ResetRefusesAbsurdButFiniteStatesNamingTheJoint) {
  SimulatedRobot robot(config("ball", ActuationMode::kPneumatic, false));
  const mjModel* m = robot.model();
  const auto q0 = qpos(robot), v0 = qvel(robot);
  const int object = jointIndex(robot, "object_root"), thj0 = jointIndex(robot, "THJ0"), arj2 = jointIndex(robot, "ARJ2");
  ASSERT_GE(object, 0);
  ASSERT_GE(thj0, 0);
  const int obj_q = m->jnt_qposadr[object], obj_v = m->jnt_dofadr[object];
  std::string error;
  auto refused = [&](std::vector<double> q, std::vector<double> v, const std::vector<std::string>& words) {
    error.clear();
    EXPECT_FALSE(robot.resetToState(q, v, {}, &error));
    for (const auto& w : words) EXPECT_NE(error.find(w), std::string::npos) << "'" << w << "' not in: " << error;
  };
  std::vector<double> q = q0;
  q[obj_q] = 1e300;  // the object, far away
  refused(q, {}, {"object_root", "1e+300", "max_reset_distance"});
  q = q0;
  q[obj_q + 2] = 10.5;
  refused(q, {}, {"object_root", "10.5"});
  q = q0;
  for (int k = 3; k < 7; ++k) q[obj_q + k] *= 2.0;  // quaternion of norm 2
  refused(q, {}, {"object_root", "quaternion", "norm 2"});
  q = q0;
  q[obj_q + 3] += 1e-5;  // norm 1 + 1e-5: beyond the tolerance
  refused(q, {}, {"object_root", "quaternion"});
  q = q0;
  q[m->jnt_qposadr[thj0]] = 0.3;  // THJ0's range is [-1.571, 0]: 0.24 beyond it is allowed
  refused(q, {}, {"THJ0", "0.3", "range"});
  q = q0;
  q[m->jnt_qposadr[arj2]] = 1e300;
  refused(q, {}, {"ARJ2", "1e+300"});
  q = q0;
  const double arj2_width = m->jnt_range[2 * arj2 + 1] - m->jnt_range[2 * arj2];
  const double margin = robot.config().reset_range_margin;
  q[m->jnt_qposadr[arj2]] = m->jnt_range[2 * arj2] - (margin + 0.01) * arj2_width;  // just beyond the margin
  refused(q, {}, {"ARJ2", "range"});
  std::vector<double> v(m->nv, 0.0);
  v[m->jnt_dofadr[arj2]] = 1e6;
  refused({}, v, {"ARJ2", "1e+06", "max_reset_velocity"});
  v.assign(m->nv, 0.0);
  v[obj_v + 4] = -51.0;  // object spinning
  refused({}, v, {"object_root", "-51"});
  expectUnchangedAndHealthy(robot, q0, v0);

  // Within the bounds, including the edges: accepted.
  ASSERT_TRUE(robot.resetToKeyframe("rest", &error));
  const auto rest = qpos(robot);
  q = rest;
  q[m->jnt_qposadr[thj0]] = 0.0;
  q[m->jnt_qposadr[arj2]] = m->jnt_range[2 * arj2] - (margin - 0.01) * arj2_width;  // within the margin
  q[obj_q + 3] += 5e-7;  // within the quaternion tolerance
  v.assign(m->nv, 0.0);
  v[m->jnt_dofadr[arj2]] = 50.0;
  EXPECT_TRUE(robot.resetToState(q, v, {}, &error)) << error;

  // A tighter configured bound applies.
  SimConfig c = config("ball", ActuationMode::kPneumatic, false);
  c.max_reset_velocity = 1.0;
  c.reset_range_margin = 0.0;
  SimulatedRobot strict(c);
  v.assign(m->nv, 0.0);
  v[m->jnt_dofadr[arj2]] = 1.5;
  EXPECT_FALSE(strict.resetToState({}, v, {}, &error));
  EXPECT_NE(error.find("ARJ2"), std::string::npos) << error;
  q = rest;
  q[m->jnt_qposadr[thj0]] = 1e-9;
  EXPECT_FALSE(strict.resetToState(q, {}, {}, &error));
  EXPECT_NE(error.find("THJ0"), std::string::npos) << error;
  c.max_reset_distance = -1.0;
  EXPECT_THROW(SimulatedRobot bad(c), std::invalid_argument);
}

// The generated scenes have neither ball joints nor unlimited hinges: a small model has.
TEST(SimulatedRobot, ResetChecksBallJointsAndUnlimitedHinges) {
  const std::string path = ::testing::TempDir() + "/reset_joints.xml";
  std::ofstream(path) << "<mujoco><worldbody>"
                         "<body><joint name='spin' type='hinge'/><geom size='0.1'/>"
                         "<body pos='0 0 1'><joint name='swivel' type='ball'/><geom size='0.1'/></body></body>"
                         "</worldbody></mujoco>";
  SimConfig c = config("hand", ActuationMode::kForce);
  c.model_path = path;
  c.initial_keyframe = "";
  SimulatedRobot robot(c);
  ASSERT_EQ(robot.model()->nq, 5);  // spin, then swivel's quaternion
  std::string error;
  EXPECT_TRUE(robot.resetToState({100.0, 1, 0, 0, 0}, {}, {}, &error)) << error;  // unlimited: any sane angle
  EXPECT_FALSE(robot.resetToState({1e300, 1, 0, 0, 0}, {}, {}, &error));
  EXPECT_NE(error.find("spin"), std::string::npos) << error;
  EXPECT_FALSE(robot.resetToState({0, 0.5, 0, 0, 0}, {}, {}, &error));
  EXPECT_NE(error.find("swivel"), std::string::npos) << error;
  EXPECT_NE(error.find("0.5"), std::string::npos) << error;
  EXPECT_FALSE(robot.resetToState({}, {0, 0, 0, 60}, {}, &error));
  EXPECT_NE(error.find("swivel"), std::string::npos) << error;
}

TEST(SimulatedRobot, SetObjectPoseRefusesFarPositionsAndFastVelocities) {
  SimulatedRobot robot(config("ball", ActuationMode::kPneumatic, false));
  const auto q0 = qpos(robot), v0 = qvel(robot);
  std::string error;
  EXPECT_FALSE(robot.setObjectPose({1e300, 0, 0}, {1, 0, 0, 0}, {0, 0, 0}, {0, 0, 0}, &error));
  EXPECT_NE(error.find("1e+300"), std::string::npos) << error;
  EXPECT_FALSE(robot.setObjectPose({0, 0, 10.01}, {1, 0, 0, 0}, {0, 0, 0}, {0, 0, 0}, &error));
  EXPECT_FALSE(robot.setObjectPose({0, 0, 0.1}, {1, 0, 0, 0}, {0, 1e6, 0}, {0, 0, 0}, &error));
  EXPECT_NE(error.find("linear"), std::string::npos) << error;
  EXPECT_FALSE(robot.setObjectPose({0, 0, 0.1}, {1, 0, 0, 0}, {0, 0, 0}, {0, 0, -60}, &error));
  EXPECT_NE(error.find("angular"), std::string::npos) << error;
  expectUnchangedAndHealthy(robot, q0, v0);
  EXPECT_TRUE(robot.setObjectPose({0, 0, 0.1}, {1, 0, 0, 0}, {0, 0, 50}, {0, 50, 0}, &error)) << error;
}

// MuJoCo's limits are soft: a joint pressing on its limit sits slightly beyond it. Whatever
// the simulation produced must be accepted back by a reset (a controller saving and
// restoring states).
TEST(SimulatedRobot, StatesTheSimulationProducesAreAcceptedBack) {
  SimulatedRobot robot(config("arm_hand", ActuationMode::kPneumatic, false));
  const mjModel* m = robot.model();
  // Every flexor at full supply, every extensor exhausted: fingers and wrist onto their
  // limits; then an e-stop lets the arm fall onto its limits under gravity.
  const auto& names = robot.cylinderNames();
  std::vector<double> volts(names.size());
  for (std::size_t i = 0; i < names.size(); ++i) volts[i] = names[i].find("_flex") != std::string::npos ? 5.0 : -5.0;
  double deepest = 0.0;  // beyond a limit, as a fraction of the joint's range
  std::string deepest_joint;
  auto penetration = [&] {
    for (int j = 0; j < m->njnt; ++j) {
      if (!m->jnt_limited[j]) continue;
      const double x = robot.data()->qpos[m->jnt_qposadr[j]], lo = m->jnt_range[2 * j], hi = m->jnt_range[2 * j + 1];
      const double beyond = std::max(lo - x, x - hi) / (hi - lo);
      if (beyond > deepest) {
        deepest = beyond;
        deepest_joint = mj_id2name(m, mjOBJ_JOINT, j);
      }
    }
  };
  for (int k = 0; k < 750; ++k) {
    if (k % 2 == 0) {
      ASSERT_TRUE(robot.commandValves(names, {}, volts).applied);
    }
    robot.step();
    penetration();
    if (k % 250 == 249) {  // a state saved while pressing on the limits is accepted back
      std::string error;
      SimulatedRobot copy(config("arm_hand", ActuationMode::kPneumatic, false));
      EXPECT_TRUE(copy.resetToState(qpos(robot), qvel(robot), {}, &error)) << error;
    }
  }
  robot.estop();
  for (int k = 0; k < 750; ++k) {
    robot.step();
    penetration();
  }
  std::printf("deepest limit penetration: %.3f of the range (%s)\n", deepest, deepest_joint.c_str());
  EXPECT_LE(deepest, robot.config().reset_range_margin) << deepest_joint;
  std::string error;
  EXPECT_TRUE(robot.resetToState(qpos(robot), qvel(robot), {}, &error)) << error;
}

TEST(SimulatedRobot, FaultsCountAsEventsNotAsSteps) {
  SimulatedRobot robot(config("hand", ActuationMode::kPneumatic, false));
  drive(robot, 1.0, 20);
  const auto events_before = robot.counters().safety_events;
  SimState s = robot.state();
  s.qvel[3] = 1e11;
  robot.setState(s);
  for (int k = 0; k < 100; ++k) robot.step();
  EXPECT_EQ(robot.counters().faults, 1u);          // one event ...
  EXPECT_EQ(robot.counters().faulted_steps, 100u);  // ... that lasted 100 steps
  EXPECT_EQ(robot.counters().safety_events, events_before + 1);
  const SafetyEvent& fault = robot.safetyEvents().fault;
  EXPECT_EQ(fault.cause, SafeCause::kFault);
  EXPECT_EQ(fault.fault, FaultSource::kQvel);
  EXPECT_EQ(fault.index, 3);
  EXPECT_EQ(fault.cylinder, -1);
  EXPECT_EQ(fault.sequence, robot.counters().safety_events);
  EXPECT_EQ(robot.safetyEvents().last.sequence, fault.sequence);
  const std::string joint = mj_id2name(robot.model(), mjOBJ_JOINT, robot.model()->dof_jntid[3]);
  EXPECT_NE(robot.safety().fault.find("qvel[3]"), std::string::npos) << robot.safety().fault;
  EXPECT_NE(robot.safety().fault.find(joint), std::string::npos) << robot.safety().fault;
  const std::string text = robot.describe(fault);
  EXPECT_NE(text.find("fault"), std::string::npos) << text;
  EXPECT_NE(text.find(joint), std::string::npos) << text;

  // Reset, release, fault again: a second event.
  std::string why;
  ASSERT_TRUE(robot.resetToKeyframe("home", &why));
  robot.step();
  ASSERT_TRUE(robot.release(&why)) << why;
  EXPECT_EQ(robot.safetyEvents().fault.sequence, fault.sequence) << "events survive a release";
  s = robot.state();
  s.qpos[5] = 1e11;
  robot.setState(s);
  for (int k = 0; k < 10; ++k) robot.step();
  EXPECT_EQ(robot.counters().faults, 2u);
  EXPECT_EQ(robot.counters().faulted_steps, 110u);
  EXPECT_EQ(robot.safetyEvents().fault.fault, FaultSource::kQpos);
  EXPECT_EQ(robot.safetyEvents().fault.index, 5);
  EXPECT_EQ(robot.counters().safety_events, events_before + 2);
}

TEST(SimulatedRobot, EverySafetyEventHasASequenceNumberAndItsCause) {
  SimulatedRobot robot(config("hand"));
  const auto& names = robot.cylinderNames();
  const int ffj3 = std::find(names.begin(), names.end(), "A_FFJ3_flex") - names.begin();
  EXPECT_EQ(robot.safetyEvents().last.sequence, 0u);  // none yet
  EXPECT_EQ(robot.safetyEvents().last.cause, SafeCause::kNone);

  // 1: a watchdog trip; the stale cylinder is the cause, not the one still commanded.
  for (int k = 0; k < 5; ++k) robot.step();
  robot.commandValves({"A_FFJ3_flex"}, {}, {1.0});
  const double commanded_at = robot.clock();
  while (!robot.safety().safe_state && robot.clock() < 1.0) {
    robot.commandValves({"A_THJ0_flex"}, {}, {1.0});
    robot.step();
  }
  ASSERT_TRUE(robot.safety().watchdog_latched);
  const SafetyEvent trip = robot.safetyEvents().watchdog;
  EXPECT_EQ(trip.sequence, 1u);
  EXPECT_EQ(trip.cause, SafeCause::kWatchdog);
  EXPECT_EQ(trip.cylinder, ffj3);
  EXPECT_GE(trip.clock - commanded_at, robot.config().watchdog_timeout - 1e-9);
  EXPECT_LE(trip.clock - commanded_at, robot.config().watchdog_timeout + robot.timestep());
  EXPECT_NE(robot.describe(trip).find("A_FFJ3_flex"), std::string::npos) << robot.describe(trip);

  // 2: the software e-stop; 3: the e-stop input, even while latched.
  robot.estop();
  robot.setEstopInput(true);
  EXPECT_EQ(robot.safetyEvents().estop.sequence, 3u);
  EXPECT_EQ(robot.safetyEvents().last.cause, SafeCause::kEstop);
  EXPECT_EQ(robot.safetyEvents().watchdog.sequence, 1u);  // the latest of each kind is kept
  robot.setEstopInput(false);
  std::string why;
  ASSERT_TRUE(robot.release(&why)) << why;
  const Counters& c = robot.counters();
  EXPECT_EQ(c.safety_events, 3u);
  EXPECT_EQ(c.safety_events, c.estops + c.watchdog_trips + c.faults);
  EXPECT_EQ(robot.safetyEvents().last.sequence, 3u);
}

TEST(SimulatedRobot, NonFinitePlantOutputIsAFaultAndNeverReachesCtrl) {
  SimulatedRobot robot(config("hand"));  // sensor realism on
  drive(robot, 1.0, 50);
  const auto q_before = qpos(robot);
  SimState s = robot.state();
  s.plant.pressure[7] = std::nan("");  // what a diverging plant would give
  robot.setState(s);
  commandAll(robot, 1.0);
  robot.step();
  EXPECT_TRUE(robot.safety().fault_latched);
  EXPECT_TRUE(robot.safety().safe_state);
  EXPECT_TRUE(robot.safety().fault_persists);
  EXPECT_EQ(robot.safetyEvents().fault.fault, FaultSource::kPressure);
  EXPECT_EQ(robot.safetyEvents().fault.cylinder, 7);
  EXPECT_NE(robot.safety().fault.find(robot.cylinderNames()[7]), std::string::npos) << robot.safety().fault;
  EXPECT_EQ(qpos(robot), q_before) << "the step was refused";
  for (int k = 0; k < 20; ++k) {
    for (int a = 0; a < robot.model()->nu; ++a) ASSERT_TRUE(std::isfinite(robot.data()->ctrl[a])) << a;
    robot.step();
  }
  EXPECT_EQ(robot.counters().faults, 1u);
  EXPECT_FALSE(robot.sensedIsFinite());  // the NaN pressure reached the sensors: not to be published
  std::string why;
  EXPECT_FALSE(robot.release(&why));
  ASSERT_TRUE(robot.resetToKeyframe("home", &why));
  robot.step();
  EXPECT_TRUE(robot.release(&why)) << why;
  for (int k = 0; k < 20; ++k) robot.step();
  EXPECT_TRUE(robot.sensedIsFinite());
}

TEST(SimulatedRobot, NonFiniteCommandInARestoredStateIsAFaultAndActsAsTheSafeState) {
  for (const auto mode : {ActuationMode::kPneumatic, ActuationMode::kForce}) {
    SimulatedRobot robot(config("hand", mode));
    drive(robot, 2.0, 20);
    SimState s = robot.state();
    s.command[4] = std::nan("");  // commands are checked on arrival: only a state can carry this
    robot.setState(s);
    robot.step();
    EXPECT_TRUE(robot.safety().fault_latched) << modeName(mode);
    EXPECT_EQ(robot.safetyEvents().fault.fault, FaultSource::kCommand);
    EXPECT_EQ(robot.safetyEvents().fault.cylinder, 4);
    const double safe = mode == ActuationMode::kPneumatic ? -5.0 : robot.config().min_tension;
    for (double v : robot.appliedCommand()) EXPECT_EQ(v, safe) << modeName(mode);
    for (int a = 0; a < robot.model()->nu; ++a) EXPECT_TRUE(std::isfinite(robot.data()->ctrl[a]));
    // The safe state does not act on the command: the fault stops persisting, release
    // returns to the idle command.
    robot.step();
    EXPECT_FALSE(robot.safety().fault_persists);
    std::string why;
    EXPECT_TRUE(robot.release(&why)) << why;
    robot.step();
    EXPECT_TRUE(robot.sensedIsFinite());
  }
}

TEST(SimulatedRobot, CylindersNeverCommandedAreCountedUntilCommanded) {
  SimulatedRobot robot(config("hand"));
  const std::size_t n = robot.cylinderNames().size();
  EXPECT_EQ(robot.neverCommanded(), n);
  ASSERT_TRUE(robot.commandValves({"A_FFJ3_flex", "A_FFJ3_ext"}, {}, {1.0, 1.0}).applied);
  ASSERT_TRUE(robot.commandValves({"A_FFJ3_flex"}, {}, {1.0}).applied);  // again: counted once
  EXPECT_FALSE(robot.commandValves({"A_FFJ2_flex"}, {}, {9.0}).applied);  // rejected: not commanded
  EXPECT_EQ(robot.neverCommanded(), n - 2);
  std::vector<std::string> never;
  for (std::size_t i = 0; i < n; ++i)
    if (!robot.everCommanded(i)) never.push_back(robot.cylinderNames()[i]);
  EXPECT_EQ(never.size(), n - 2);
  EXPECT_EQ(std::count(never.begin(), never.end(), "A_FFJ3_flex"), 0);
  EXPECT_EQ(std::count(never.begin(), never.end(), "A_FFJ2_flex"), 1);
  robot.estop();
  EXPECT_FALSE(robot.commandValves({"A_FFJ2_flex"}, {}, {1.0}).applied);  // ignored while safe
  EXPECT_EQ(robot.neverCommanded(), n - 2);
  std::string why;
  ASSERT_TRUE(robot.release(&why));
  EXPECT_EQ(robot.neverCommanded(), n);  // the watchdog re-arms from scratch
}

TEST(SimulatedRobot, SensedValuesAreFiniteInNormalRunning) {
  for (const auto mode : {ActuationMode::kPneumatic, ActuationMode::kForce}) {
    SimulatedRobot robot(config("ball", mode));
    EXPECT_TRUE(robot.sensedIsFinite());
    drive(robot, mode == ActuationMode::kPneumatic ? 2.0 : 5.0, 100);
    EXPECT_TRUE(robot.sensedIsFinite()) << modeName(mode);
  }
}

// Teleop scenes (thesis 9.2.3): a motion-capture stream moves the hand's base through its
// mocap body, no faster than max_base_speed; bad targets are refused and change nothing.
TEST(SimulatedRobot, HandBaseFollowsItsTargetAtTheSpeedLimit) {
  SimConfig c = config("teleop_ball", ActuationMode::kForce, false);
  c.max_base_speed = 0.5;
  SimulatedRobot robot(c);
  ASSERT_TRUE(robot.hasFreeBase());
  EXPECT_STREQ(robot.baseFrame(), "forearm");
  std::string error;
  SimulatedRobot fixed(config("hand", ActuationMode::kForce, false));
  EXPECT_FALSE(fixed.hasFreeBase());
  EXPECT_FALSE(fixed.setBaseTarget({0, -0.5, 0.2}, {1, 0, 0, 0}, &error));
  EXPECT_NE(error.find("teleop"), std::string::npos) << error;

  const std::array<double, 7> start = robot.truth().base;
  const std::array<double, 4> q{start[3], start[4], start[5], start[6]};
  EXPECT_FALSE(robot.setBaseTarget({NAN, 0, 0}, q, &error));
  EXPECT_FALSE(robot.setBaseTarget({0, 0, 0.2}, {0, 0, 0, 0}, &error));
  EXPECT_FALSE(robot.setBaseTarget({0, 0, 11}, q, &error));
  EXPECT_NE(error.find("max_reset_distance"), std::string::npos) << error;
  for (int k = 0; k < 100; ++k) robot.step();  // 0.2 s: no target, the base stays (sags < 1 cm)
  EXPECT_NEAR(robot.truth().base[2], start[2], 0.01);

  // 10 cm up: at 0.5 m/s the mocap body needs 0.2 s; after 0.1 s the base is about half-way.
  ASSERT_TRUE(robot.setBaseTarget({start[0], start[1], start[2] + 0.10}, q, &error)) << error;
  for (int k = 0; k < 50; ++k) robot.step();
  EXPECT_LT(robot.truth().base[2], start[2] + 0.06);
  EXPECT_GT(robot.truth().base[2], start[2] + 0.02);
  for (int k = 0; k < 200; ++k) robot.step();
  EXPECT_NEAR(robot.truth().base[2], start[2] + 0.10, 0.01);
  EXPECT_NEAR(robot.truth().base[1], start[1], 0.01);
  EXPECT_EQ(robot.sensed().base, robot.truth().base);  // what tf world -> forearm publishes

  // A reset puts the mocap body back at the base: no target pulls it away afterwards.
  ASSERT_TRUE(robot.resetToKeyframe("home", &error)) << error;
  for (int k = 0; k < 100; ++k) robot.step();
  EXPECT_NEAR(robot.truth().base[2], start[2], 0.01);
}

}  // namespace
}  // namespace adroit::driver
