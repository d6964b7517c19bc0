// The typing task's state machine and costs on the real keypad model: key joints pushed in
// mjData, mj_forward, observe() -> key / error / done events, release hysteresis, auto-correct
// through backspace, the finger heat map, the smooth-step schedule.
#include <gtest/gtest.h>

#include <adroit_core/mujoco_model.h>
#include <adroit_description/scenes.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "adroit_mpc/planner.h"
#include "adroit_mpc/planning_model.h"
#include "adroit_mpc/task.h"
#include "adroit_mpc/task_params.h"
#include "adroit_mpc/type_task.h"

namespace {

using adroit_mpc::TaskEvent;
using adroit_mpc::TypeTask;

class Typing : public ::testing::Test {
 protected:
  void SetUp() override {
    model = adroit::loadModelFile(adroit::description::sceneFile(adroit_mpc::descriptionShareDir(), "keypad", true)).model;
    data = adroit::makeData(model.get());
    m = model.get();
    task = std::make_unique<TypeTask>();
    task->bind(m, 5);
    const int rest = mj_name2id(m, mjOBJ_KEY, "rest");
    mju_copy(data->qpos, m->key_qpos + rest * m->nq, m->nq);
    mj_forward(m, data.get());
  }
  // Key joint to a depth [m below its top] and observe at time t.
  std::vector<TaskEvent> push(const std::string& label, double depth, double t) {
    data->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, ("KEY_" + label).c_str())]] = -depth;
    mj_forward(m, data.get());
    return task->observe(m, data.get(), t);
  }
  // A full press and release of one key; the events of the press.
  std::vector<TaskEvent> tap(const std::string& label, double t) {
    auto events = push(label, 0.0058, t);
    EXPECT_TRUE(push(label, 0.0, t + 0.05).empty());
    return events;
  }
  double cost(double t) {
    auto scratch = task->makeScratch(m);
    return task->terminalCost(m, data.get(), t, *scratch);
  }

  adroit::ModelPtr model;
  adroit::DataPtr data;
  const mjModel* m = nullptr;
  std::unique_ptr<TypeTask> task;
};

TEST_F(Typing, SetSequenceAcceptsDigitsOnly) {
  std::string why;
  EXPECT_FALSE(task->setSequence("12a", &why));
  EXPECT_NE(why.find("'a' at position 3 is not a digit"), std::string::npos) << why;
  EXPECT_FALSE(task->setSequence("1 2", &why));
  EXPECT_FALSE(task->setSequence(std::string(TypeTask::kMaxSequence + 1, '1'), &why));
  EXPECT_NE(why.find("longer"), std::string::npos) << why;
  EXPECT_EQ(task->sequence(), "");  // nothing taken
  EXPECT_TRUE(task->setSequence("0123456789", &why)) << why;
  EXPECT_EQ(task->error(m, data.get()), 10);
}

TEST_F(Typing, PressesRegisterAtThePressDepthOnce) {
  std::string why;
  ASSERT_TRUE(task->setSequence("12", &why));
  EXPECT_EQ(task->currentTarget(), "1");
  EXPECT_EQ(task->nextTarget(), "2");
  EXPECT_TRUE(push("1", 0.0050, 0.0).empty());  // 5 mm: not yet (registers at 5.5 mm)
  auto events = push("1", 0.0056, 0.01);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, "key");
  EXPECT_EQ(events[0].detail, "1");
  EXPECT_EQ(task->currentTarget(), "2");
  EXPECT_EQ(task->error(m, data.get()), 1);
  // Held, or lifted only to 4 mm (above the press depth, below the 3.5 mm release): no repeat.
  EXPECT_TRUE(push("1", 0.0058, 0.02).empty());
  EXPECT_TRUE(push("1", 0.0040, 0.03).empty());
  EXPECT_TRUE(push("1", 0.0058, 0.04).empty());
  EXPECT_EQ(task->currentTarget(), "2");
  // Released above 3.5 mm, pressed again: a second (wrong) press of 1.
  EXPECT_TRUE(push("1", 0.0030, 0.05).empty());
  events = push("1", 0.0058, 0.06);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind, "key");
  EXPECT_EQ(events[1].kind, "error");
  EXPECT_EQ(events[1].detail, "pressed 1 instead of 2");
}

TEST_F(Typing, WrongKeyIsCorrectedWithBackspace) {
  std::string why;
  ASSERT_TRUE(task->setSequence("47", &why));
  ASSERT_EQ(tap("4", 0.1).size(), 1u);
  auto events = tap("8", 0.2);  // meant 7
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1].kind, "error");
  EXPECT_EQ(events[1].detail, "pressed 8 instead of 7");
  EXPECT_EQ(task->currentTarget(), "bs");
  EXPECT_EQ(task->nextTarget(), "7");
  EXPECT_EQ(task->error(m, data.get()), 2);  // one backspace + the 7
  events = tap("bs", 0.3);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].detail, "bs");
  EXPECT_EQ(task->currentTarget(), "7");
  events = tap("7", 0.4);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].detail, "7");
  EXPECT_EQ(events[1].kind, "done");
  EXPECT_EQ(events[1].detail, "47");
  EXPECT_EQ(task->error(m, data.get()), 0);
  EXPECT_EQ(task->currentTarget(), "");
}

// Keys right forgives a wrong key once backspaced; the press count keeps it: 4 8 bs 7 for "47"
// is every key right in four presses, one of them wrong (the backspace that removes it is not).
TEST_F(Typing, AWrongKeyFixedByBackspaceStaysAWrongPress) {
  std::string why;
  ASSERT_TRUE(task->setSequence("47", &why));
  tap("4", 0.1);
  tap("8", 0.2);
  tap("bs", 0.3);
  tap("7", 0.4);
  EXPECT_EQ(task->typedCorrectly(), 2);
  EXPECT_EQ(task->presses(), 4);
  EXPECT_EQ(task->wrongPresses(), 1);
  // A backspace that deletes a right key, and one on nothing typed, are wrong presses too.
  ASSERT_TRUE(task->setSequence("12", &why));
  EXPECT_EQ(task->presses(), 0);  // a new sequence counts afresh
  tap("bs", 0.5);
  tap("1", 0.6);
  tap("bs", 0.7);
  EXPECT_EQ(task->typedCorrectly(), 0);
  EXPECT_EQ(task->presses(), 3);
  EXPECT_EQ(task->wrongPresses(), 2);
  TypeTask copy;  // the planner's copy of the task carries the counts (copyParametersFrom)
  copy.bind(m, 5);
  copy.copyParametersFrom(*task);
  EXPECT_EQ(copy.presses(), 3);
  EXPECT_EQ(copy.wrongPresses(), 2);
}

TEST_F(Typing, TwoWrongKeysNeedTwoBackspaces) {
  std::string why;
  ASSERT_TRUE(task->setSequence("5", &why));
  tap("6", 0.1);
  tap("9", 0.2);
  EXPECT_EQ(task->pendingBackspaces(), 2);
  EXPECT_EQ(task->currentTarget(), "bs");
  EXPECT_EQ(task->nextTarget(), "bs");
  tap("bs", 0.3);
  EXPECT_EQ(task->currentTarget(), "bs");
  EXPECT_EQ(task->nextTarget(), "5");
  tap("bs", 0.4);
  EXPECT_EQ(task->currentTarget(), "5");
  EXPECT_EQ(task->error(m, data.get()), 1);
}

TEST_F(Typing, FingerHeatMapFromTheKeypadLayout) {
  // At the rest keyframe the fingertips sit at x -0.033 (ff), -0.011 (mf), 0.011 (rf),
  // 0.034 (lf); the key columns at x -0.022 (1 4 7 bs), 0 (2 5 8 0), 0.022 (3 6 9 ent).
  // Distinct fingers per column, least summed distance: ff, mf, rf (0.3026 m against 0.3086 m
  // for mf, rf, lf, worked out from the keyframe positions).
  const int ff = 0, mf = 1, rf = 2;
  for (const char* key : {"1", "4", "7", "bs"}) EXPECT_EQ(task->fingerOfKey(key), ff) << key;
  for (const char* key : {"2", "5", "8", "0"}) EXPECT_EQ(task->fingerOfKey(key), mf) << key;
  for (const char* key : {"3", "6", "9", "ent"}) EXPECT_EQ(task->fingerOfKey(key), rf) << key;
  EXPECT_EQ(task->keyLabels().size(), 12u);

  adroit_mpc::TaskParams p;
  p.strings["finger_assignment"] = "0:th, ent:lf";
  TypeTask overridden(p);
  overridden.bind(m, 0);
  EXPECT_EQ(overridden.fingerOfKey("0"), 4);
  EXPECT_EQ(overridden.fingerOfKey("ent"), 3);
  EXPECT_EQ(overridden.fingerOfKey("2"), mf);
  p.strings["finger_assignment"] = "star:th";
  TypeTask unknown_key(p);
  try {
    unknown_key.bind(m, 0);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no key 'star'"), std::string::npos) << e.what();
  }
}

TEST_F(Typing, StepScheduleFollowsKeyEvents) {
  adroit_mpc::TaskParams p;
  p.numbers = {{"key_period", 0.25}, {"min_lead", 0.1}};
  task = std::make_unique<TypeTask>(p);
  task->bind(m, 5);
  std::string why;
  ASSERT_TRUE(task->setSequence("123", &why));
  tap("1", 2.0);
  // Event at t = 2.0, observed up to 2.05: S_up from 2.0 to max(2.0 + 0.25, 2.05 + 0.1).
  auto step = task->currentStep();
  EXPECT_DOUBLE_EQ(step.a1, 2.0);
  EXPECT_DOUBLE_EQ(step.a2, 2.25);
  EXPECT_GT(step.up(2.1), 0.95);
  EXPECT_LT(step.up(2.6), 0.05);
  // A slow press: the switch to the next key stays ahead of the latest observation.
  push("2", 0.001, 3.0);
  EXPECT_DOUBLE_EQ(task->currentStep().a2, 3.1);
}

TEST_F(Typing, DefaultScheduleHoldsADueKeyOverTheWholeHorizon) {
  std::string why;
  ASSERT_TRUE(task->setSequence("123", &why));
  tap("1", 2.0);
  push("2", 0.001, 2.6);  // 2 is due and late: the plan must not hand over to 3 yet
  const double horizon = TypeTask::defaults().numbers.at("horizon");
  const auto step = task->currentStep();
  EXPECT_GT(step.up(2.6 + horizon), 0.95);
  EXPECT_EQ(task->currentTarget(), "2");
}

TEST_F(Typing, CostRewardsTheTargetKeyAndPenalisesOthers) {
  std::string why;
  ASSERT_TRUE(task->setSequence("5", &why));
  const double idle = cost(0.05);
  push("5", 0.006, 0.0);  // fully down (registers, but look at the cost first on a copy)
  auto fresh = std::make_unique<TypeTask>();
  fresh->bind(m, 5);
  ASSERT_TRUE(fresh->setSequence("5", &why));
  auto scratch = fresh->makeScratch(m);
  EXPECT_LT(fresh->terminalCost(m, data.get(), 0.05, *scratch), idle);
  push("5", 0.0, 0.01);
  push("9", 0.006, 0.0);  // a key that is not wanted
  mj_forward(m, data.get());
  EXPECT_GT(fresh->terminalCost(m, data.get(), 0.05, *scratch), idle);
}

// The key approach from above (approachFromAbove): over the key the target is its top; beside
// it the target rises towards hover_height (half of it at approach_radius), with the Jacobian
// of the lifted residual.
TEST_F(Typing, KeyApproachTargetRisesBesideTheKey) {
  const double height = 0.015, radius = 0.004;
  adroit_mpc::ResidualBuffer buf(m, 6);
  auto lifted = [&](const Eigen::Vector3d& r) {
    buf.dim = 3;
    buf.uses_q = false;
    buf.r.head<3>() = r;
    adroit_mpc::approachFromAbove(height, radius, buf);
    return Eigen::Vector3d(buf.r.head<3>());
  };
  EXPECT_NEAR(lifted({0, 0, 0.002})[2], 0.002, 1e-12);                 // over the key: unchanged
  EXPECT_NEAR(lifted({radius, 0, 0})[2], -height / 2, 1e-12);           // target half-way up
  EXPECT_NEAR(lifted({0, 0.05, 0})[2], -height, 2e-4);                  // far: hover height
  EXPECT_NEAR(lifted({0.003, -0.002, 0.001})[0], 0.003, 1e-12);         // x, y unchanged
  // A tip level with the key top but 8 mm beside it is further from its target than one
  // hovering at hover_height over that spot: it must come up before it goes over.
  EXPECT_GT(lifted({0.008, 0, 0}).norm(), 1.5 * lifted({0.008, 0, height}).norm());  // 14.4 against 8.5 mm
  // Jacobian against central differences along each column of a raw Jacobian.
  const Eigen::Vector3d r0(0.003, -0.005, 0.004);
  Eigen::MatrixXd raw = Eigen::MatrixXd::Zero(3, m->nv);
  for (int j = 0; j < m->nv; ++j)
    for (int i = 0; i < 3; ++i) raw(i, j) = std::sin(1.0 + 3 * j + i);
  buf.dim = 3;
  buf.uses_q = true;
  buf.r.head<3>() = r0;
  buf.jq.topRows(3) = raw;
  adroit_mpc::approachFromAbove(height, radius, buf);
  const Eigen::MatrixXd jq = buf.jq.topRows(3);
  const double h = 1e-7;
  for (int j = 0; j < m->nv; ++j) {
    const Eigen::Vector3d fd = (lifted(r0 + h * raw.col(j)) - lifted(r0 - h * raw.col(j))) / (2 * h);
    EXPECT_NEAR((fd - jq.col(j)).norm(), 0.0, 1e-6 * (1 + fd.norm())) << "column " << j;
  }
  // Radius 0: the old straight approach.
  buf.uses_q = false;
  buf.r.head<3>() = Eigen::Vector3d(0.008, 0, 0);
  adroit_mpc::approachFromAbove(height, 0.0, buf);
  EXPECT_EQ(buf.r[2], 0.0);
}

TEST_F(Typing, RepeatedKeyMustComeUpFirst) {
  std::string why;
  ASSERT_TRUE(task->setSequence("11", &why));
  push("1", 0.006, 0.0);  // first 1 registered and still held
  EXPECT_EQ(task->currentTarget(), "1");
  const double held_down = cost(0.05);
  data->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "KEY_1")]] = -0.004;  // partly up, still held
  mj_forward(m, data.get());
  EXPECT_LT(cost(0.05), held_down);
}

TEST_F(Typing, CopyParametersCarriesTheProgress) {
  auto planner_copy = task->clone();
  std::string why;
  ASSERT_TRUE(task->setSequence("36", &why));
  tap("3", 1.0);
  task->setWeight("w_press", 4.0);
  planner_copy->copyParametersFrom(*task);
  auto* copy = dynamic_cast<TypeTask*>(planner_copy.get());
  ASSERT_NE(copy, nullptr);
  EXPECT_EQ(copy->sequence(), "36");
  EXPECT_EQ(copy->currentTarget(), "6");
  EXPECT_EQ(copy->typedCorrectly(), 1);
  EXPECT_EQ(copy->weight("w_press"), 4.0);
  EXPECT_DOUBLE_EQ(copy->currentStep().a1, 1.0);
  EXPECT_EQ(copy->error(m, data.get()), 1);
  auto catcher = adroit_mpc::makeTask("catch", {});
  EXPECT_THROW(planner_copy->copyParametersFrom(*catcher), std::invalid_argument);
}

TEST_F(Typing, ObjectGoalsAreNotTaken) {
  std::string why;
  EXPECT_FALSE(task->setGoal({0, 0, 0}, Eigen::Quaterniond::Identity(), &why));
  EXPECT_NE(why.find("type"), std::string::npos);
  EXPECT_FALSE(task->release(&why));
}

// The keypad's planning model as the node loads it for typing (type.yaml's knot spacing).
adroit::ModelPtr typingPlanningModel() {
  adroit_mpc::PlanningModelSettings settings;
  settings.timestep = adroit_mpc::defaultTaskParams("type").numbers.at("planner_dt");
  settings.contact_margin = 0.001, settings.contact_softness = 0.001;  // as the node for typing
  return adroit_mpc::loadPlanningModel(
      adroit::description::sceneFile(adroit_mpc::descriptionShareDir(), "keypad", true), settings);
}

// The planner integrates the keypad at its knot spacing (type.yaml planner_dt, 10 ms). A key
// released from 5 mm down must come back up and settle, not oscillate with growing amplitude
// (explicit spring integration: unstable once omega * dt > 2), or every plan that touches a
// key predicts nonsense.
TEST(TypingPlanningModel, ReleasedKeyReturnsAtThePlannerStep) {
  auto model = typingPlanningModel();
  // The key alone: no contacts (the hand would sink onto the keys without tension).
  model->opt.disableflags |= mjDSBL_CONTACT;
  const mjModel* m = model.get();
  adroit::DataPtr d = adroit::makeData(m);
  mj_resetDataKeyframe(m, d.get(), mj_name2id(m, mjOBJ_KEY, "rest"));
  const int adr = m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "KEY_5")];
  d->qpos[adr] = -0.005;
  double highest = -1, last = 0;
  for (int i = 0; i < static_cast<int>(0.5 / m->opt.timestep); ++i) {
    mj_step(m, d.get());
    ASSERT_TRUE(std::isfinite(d->qpos[adr])) << "step " << i;
    highest = std::max(highest, d->qpos[adr]);
    last = d->qpos[adr];
  }
  EXPECT_LT(highest, 0.004) << "the key flew more than 4 mm above its top";
  EXPECT_GT(last, -0.0005) << "the key did not come back up";
  EXPECT_LT(last, 0.003);
}

// Height of the lowest of ff, mf, rf's fingertips (the fingers with keys) above the key tops.
double lowestTipAboveKeys(const mjModel* m, const mjData* d) {
  double key_top = -1e9;
  for (int g = 0; g < m->ngeom; ++g) {
    const char* name = mj_id2name(m, mjOBJ_GEOM, g);
    if (name && std::string(name).rfind("C_key_", 0) == 0) key_top = std::max(key_top, d->geom_xpos[3 * g + 2] + m->geom_size[3 * g + 2]);
  }
  double lowest = 1e9;
  for (const char* site : {"S_fftip", "S_mftip", "S_rftip"})
    lowest = std::min(lowest, d->site_xpos[3 * mj_name2id(m, mjOBJ_SITE, site) + 2]);
  return lowest - key_top;
}

// With no sequence the hand must not idle with its fingertips on the key tops: at the
// robot's minimum tension it sags onto the bottom row, within the contact margin, where
// position noise turns plans into jolts that tap keys (mpc_success --idle). Closed-loop iLQG
// from there lifts them off and types nothing.
TEST(TypingPlanningModel, IdleHandLiftsItsFingertipsOffTheKeys) {
  const adroit_mpc::TaskParams hints = adroit_mpc::defaultTaskParams("type");
  auto model = typingPlanningModel();
  const mjModel* m = model.get();
  adroit::DataPtr sim = adroit::makeData(m);
  mj_resetDataKeyframe(m, sim.get(), mj_name2id(m, mjOBJ_KEY, "rest"));
  for (int i = 0; i < m->nu; ++i) sim->ctrl[i] = m->actuator_ctrlrange[2 * i];
  while (sim->time < 1.0) mj_step(m, sim.get());
  ASSERT_LT(lowestTipAboveKeys(m, sim.get()), 0.004) << "the sagged hand should rest near the keys";

  TypeTask task;
  task.bind(m, 5);
  adroit_mpc::PlannerSettings settings;
  settings.horizon = hints.numbers.at("horizon");
  settings.dt = hints.numbers.at("planner_dt");
  settings.derivative_skip = static_cast<int>(hints.numbers.at("derivative_skip"));
  settings.threads = 2;
  auto planner = adroit_mpc::makePlanner("ilqg");
  planner->initialize(m, task, settings);
  adroit_mpc::PlanPolicy policy;
  adroit_mpc::PlannerState state;
  const double start = sim->time;
  int keys = 0;
  // 1 s: the tension step cost (PlannerSettings::tension_step_weight) lets the tendons rise
  // gradually, the lowest tip passes 5 mm after ~0.7 s (4.6 mm at 0.6 s, 5.9 mm at 1 s).
  while (sim->time < start + 1.0) {
    state.time = sim->time;
    state.qpos.assign(sim->qpos, sim->qpos + m->nq);
    state.qvel.assign(sim->qvel, sim->qvel + m->nv);
    state.act.assign(sim->act, sim->act + m->na);
    for (const auto& e : task.observe(m, sim.get(), sim->time)) keys += e.kind == "key";
    planner->setTask(task);
    planner->setState(state);
    ASSERT_FALSE(planner->optimize().diverged);
    planner->policy(policy);
    for (int k = 0; k < 2; ++k) {  // a plan every 20 ms, as the node in lockstep
      policy.action(sim->time, sim->qpos, sim->qvel, sim->act, sim->ctrl);
      mj_step(m, sim.get());
    }
  }
  EXPECT_EQ(keys, 0);
  EXPECT_GT(lowestTipAboveKeys(m, sim.get()), 0.005) << "an idle fingertip stayed on the keys";
}

TEST(TypingBinding, NeedsAKeypad) {
  auto hand = adroit::loadModelFile(adroit::description::sceneFile(adroit_mpc::descriptionShareDir(), "hand", true)).model;
  TypeTask task;
  try {
    task.bind(hand.get(), 0);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("key joints"), std::string::npos) << e.what();
  }
}

}  // namespace
