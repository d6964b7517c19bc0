// MpcRunner on a small planning model (a point mass on two rails, iLQG): when plans take
// over (emulated: state time + latency; real time: on publication), a diverged solve never
// published, the age rule, the control side equal to PlanPolicy's action / reference of the
// active plan, latency compensation from the running plan, task replacement and horizon
// changes, and no allocation on the control side.
#include <adroit_core/mujoco_model.h>
#include <adroit_mpc/latency_compensation.h>
#include <adroit_mpc/mpc_runner.h>
#include <gtest/gtest.h>

#include "goal_task.h"

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <string>
#include <vector>

// Allocations counted while `counting`. Not inlined: GCC 12 would pair an inlined malloc or
// free with the other operator and warn (a false -Wmismatched-new-delete: all four are ours).
static std::atomic<bool> counting{false};
static std::atomic<long> allocations{0};
__attribute__((noinline)) void* operator new(std::size_t size) {
  if (counting) allocations++;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
__attribute__((noinline)) void* operator new[](std::size_t size) {
  if (counting) allocations++;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
__attribute__((noinline)) void operator delete(void* p) noexcept { std::free(p); }
__attribute__((noinline)) void operator delete[](void* p) noexcept { std::free(p); }
__attribute__((noinline)) void operator delete(void* p, std::size_t) noexcept { std::free(p); }
__attribute__((noinline)) void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

using namespace adroit_mpc;

namespace {

using test::kPointMass;

// |q - goal|^2 + 0.1 |v|^2 + 0.01 |u|^2 (terminal x10), the label as an event when asked.
std::unique_ptr<test::GoalTask> goalTask(double gx, double gy, std::string label = "goal") {
  return std::make_unique<test::GoalTask>(std::vector<double>{gx, gy}, 1.0, 0.1, 0.01, std::move(label));
}

PlannerSettings smallSettings() {
  PlannerSettings s;
  s.horizon = 0.3;
  s.dt = 0.01;
  s.threads = 1;
  s.synergies = false;
  s.tension_step_weight = 0;  // the plans the task alone asks for (the goal's direction at knot 0)
  return s;
}

PlannerState pointState(double time, double x, double y, double vx = 0, double vy = 0) {
  PlannerState s;
  s.time = time;
  s.qpos = {x, y};
  s.qvel = {vx, vy};
  return s;
}

struct Fixture {
  explicit Fixture(RunnerSettings rs) {
    model = adroit::loadModelString(kPointMass).model;
    runner = std::make_unique<MpcRunner>(model.get(), makePlanner("ilqg"), goalTask(0.3, -0.2),
                                         smallSettings(), std::move(rs));
  }
  test::GoalTask& task() { return static_cast<test::GoalTask&>(runner->task()); }
  adroit::ModelPtr model;
  std::unique_ptr<MpcRunner> runner;
};

RunnerSettings emulated(double fixed_latency) {
  RunnerSettings rs;
  rs.timing = PlanTiming::kEmulated;
  rs.fixed_latency = fixed_latency;
  return rs;
}

}  // namespace

TEST(MpcRunner, EmulatedPlanTakesOverAtStateTimePlusLatency) {
  Fixture f(emulated(0.05));
  MpcRunner& r = *f.runner;
  const PlanOutcome first = r.planOnce(pointState(1.0, 0, 0));
  ASSERT_TRUE(first.published);
  EXPECT_EQ(first.latency, 0.05);
  EXPECT_EQ(first.activation, 1.0 + 0.05);
  EXPECT_FALSE(r.updatePolicy(1.0499));
  EXPECT_FALSE(r.hasPolicy());
  EXPECT_TRUE(r.updatePolicy(1.05));
  ASSERT_TRUE(r.hasPolicy());
  EXPECT_EQ(r.policySerial(), 1u);
  EXPECT_DOUBLE_EQ(r.policy().policy.t0, 1.0);  // planned from the state's time

  // The next plan waits for its time; the running one is acted on until then.
  PlanPolicy first_policy;
  first_policy = r.policy();
  const PlanOutcome second = r.planOnce(pointState(1.05, 0.01, -0.01, 0.2, -0.1));
  ASSERT_TRUE(second.published);
  EXPECT_EQ(second.activation, 1.05 + 0.05);
  EXPECT_FALSE(r.updatePolicy(1.08));
  EXPECT_EQ(r.policySerial(), 1u);
  const double q[2] = {0.02, -0.02}, v[2] = {0.2, -0.1};
  double u_runner[2], u_first[2];
  ASSERT_TRUE(r.action(1.08, q, v, nullptr, u_runner));
  first_policy.action(1.08, q, v, nullptr, u_first);
  EXPECT_EQ(u_runner[0], u_first[0]);
  EXPECT_EQ(u_runner[1], u_first[1]);
  EXPECT_TRUE(r.updatePolicy(second.activation));
  EXPECT_EQ(r.policySerial(), 2u);
  EXPECT_DOUBLE_EQ(r.policy().policy.t0, 1.05);
}

TEST(MpcRunner, EmulatedLatencyIsTheWallTimeWithoutAFixedOne) {
  Fixture f(emulated(-1));
  const PlanOutcome out = f.runner->planOnce(pointState(2.0, 0, 0));
  ASSERT_TRUE(out.published);
  EXPECT_GT(out.latency, 0.0);
  EXPECT_LT(out.latency, 5.0);
  EXPECT_EQ(out.activation, 2.0 + out.latency);
  EXPECT_EQ(f.runner->expectedLatency(), out.latency);
}

TEST(MpcRunner, WhileTheWorldWaitsAPlanTakesOverAtOnce) {
  Fixture f(emulated(0.05));
  const PlanOutcome out = f.runner->planOnce(pointState(1.0, 0, 0), true);
  ASSERT_TRUE(out.published);
  EXPECT_EQ(out.latency, 0.05);  // still recorded: how long planning takes
  EXPECT_TRUE(f.runner->updatePolicy(1.0));
  EXPECT_EQ(f.runner->policySerial(), 1u);
}

TEST(MpcRunner, RealTimeLatencyIsOnTheRobotsClockAndThePlanTakesOverOnPublication) {
  double robot_clock = 0;
  RunnerSettings rs;
  rs.clock = [&] { return robot_clock; };
  Fixture f(std::move(rs));
  robot_clock = 3.25;  // the robot's time when the plan is published
  const PlanOutcome out = f.runner->planOnce(pointState(3.0, 0, 0));
  ASSERT_TRUE(out.published);
  EXPECT_DOUBLE_EQ(out.latency, 0.25);
  EXPECT_DOUBLE_EQ(f.runner->expectedLatency(), 0.25);
  EXPECT_TRUE(f.runner->updatePolicy(-1e9));  // whatever the control side's clock says
  EXPECT_EQ(f.runner->published(), 1u);
  EXPECT_EQ(f.runner->solves(), 1u);
}

TEST(MpcRunner, RealTimeNeedsTheRobotsClock) {
  auto model = adroit::loadModelString(kPointMass).model;
  EXPECT_THROW(MpcRunner(model.get(), makePlanner("ilqg"), goalTask(0, 0), smallSettings(),
                         RunnerSettings{}),
               std::invalid_argument);
}

TEST(MpcRunner, ADivergedSolveIsNeverPublished) {
  Fixture f(emulated(0.0));
  MpcRunner& r = *f.runner;
  ASSERT_TRUE(r.planOnce(pointState(0, 0, 0)).published);
  ASSERT_TRUE(r.updatePolicy(0));
  const Eigen::VectorXd u0 = r.policy().policy.u[0];
  {
    std::lock_guard<std::mutex> lock(r.taskMutex());
    f.task().poison = true;
  }
  const PlanOutcome bad = r.planOnce(pointState(0.01, 0.1, 0));
  EXPECT_FALSE(bad.published);
  EXPECT_TRUE(bad.report.diverged);
  EXPECT_EQ(r.diverged(), 1u);
  EXPECT_EQ(r.published(), 1u);
  EXPECT_FALSE(r.updatePolicy(1e9));
  EXPECT_EQ(r.policySerial(), 1u);
  EXPECT_EQ(r.policy().policy.u[0], u0);  // the good plan is still the one acted on
  {
    std::lock_guard<std::mutex> lock(r.taskMutex());
    f.task().poison = false;
  }
  EXPECT_TRUE(r.planOnce(pointState(0.02, 0.1, 0)).published);  // recovers from the warm start
  EXPECT_TRUE(r.updatePolicy(1e9));
  EXPECT_EQ(r.policySerial(), 2u);
  const RunnerWindow w = r.takeWindow();
  EXPECT_EQ(w.solves, 3);
  EXPECT_EQ(r.takeWindow().solves, 0);  // a new window
}

TEST(MpcRunner, NoPolicyOlderThanItsHorizonIsActedOn) {
  Fixture f(emulated(0.0));
  MpcRunner& r = *f.runner;
  const double q[2] = {0, 0}, v[2] = {0, 0};
  double u[2];
  std::vector<double> ref(2 * 64);
  EXPECT_FALSE(r.usable(0));
  EXPECT_FALSE(r.action(0, q, v, nullptr, u));
  EXPECT_EQ(r.reference(0, q, v, nullptr, 64, ref.data()), 0);
  ASSERT_TRUE(r.planOnce(pointState(1.0, 0, 0)).published);
  r.updatePolicy(1.0);
  const adroit::TvlgPolicy& p = r.policy().policy;
  ASSERT_EQ(p.knots(), 30);
  const double horizon = p.knots() * p.dt;
  double age = 0;
  EXPECT_TRUE(r.usable(1.0 + horizon, &age));  // the rule includes its end
  EXPECT_NEAR(age, horizon, 1e-12);
  EXPECT_TRUE(r.action(1.0 + horizon, q, v, nullptr, u));
  EXPECT_FALSE(r.usable(1.0 + horizon + 1e-6, &age));
  EXPECT_FALSE(r.action(1.0 + horizon + 1e-6, q, v, nullptr, u));
  EXPECT_EQ(r.reference(1.0 + horizon + 1e-6, q, v, nullptr, 64, ref.data()), 0);
}

TEST(MpcRunner, ControlSideEqualsThePlanPolicyOfTheActivePlanWithTheFeedbackScale) {
  RunnerSettings rs = emulated(0.0);
  rs.feedback_scale = 0.5;
  Fixture f(std::move(rs));
  MpcRunner& r = *f.runner;
  ASSERT_TRUE(r.planOnce(pointState(0.5, 0.05, 0.02, 0.3, 0)).published);
  PlanPolicy expected;
  r.planner().policy(expected);  // the plan just published
  ASSERT_TRUE(r.updatePolicy(0.5));
  const double t = 0.537, q[2] = {0.08, 0.01}, v[2] = {0.25, -0.05};
  std::vector<double> got(2 * 64), want(2 * 64);
  const int n = r.reference(t, q, v, nullptr, 64, got.data());
  const int m = expected.reference(t, q, v, nullptr, 64, want.data(), 0.5);
  ASSERT_GT(n, 20);
  ASSERT_EQ(n, m);
  for (int i = 0; i < 2 * n; ++i) EXPECT_EQ(got[i], want[i]) << i;
  // The feedback is scaled: the same reference at full gains differs.
  std::vector<double> full(2 * 64);
  expected.reference(t, q, v, nullptr, 64, full.data(), 1.0);
  int differ = 0;
  for (int i = 0; i < 2 * n; ++i) differ += full[i] != got[i];
  EXPECT_GT(differ, 0);
  double u[2], u_want[2];
  ASSERT_TRUE(r.action(t, q, v, nullptr, u));
  expected.action(t, q, v, nullptr, u_want, 0.5);
  EXPECT_EQ(u[0], u_want[0]);
  EXPECT_EQ(u[1], u_want[1]);
  EXPECT_EQ(u[0], got[0]);  // sample 0 is the action
}

TEST(MpcRunner, CompensationPlansFromTheStateTheRunningPlanReachesAtTheLatency) {
  RunnerSettings rs = emulated(0.05);
  rs.latency_compensation = true;
  Fixture f(std::move(rs));
  MpcRunner& r = *f.runner;
  const PlanOutcome first = r.planOnce(pointState(1.0, 0, 0));
  ASSERT_TRUE(first.published);
  EXPECT_EQ(first.compensated, 0.0);  // nothing running yet
  PlanPolicy running;
  r.planner().policy(running);

  // The prediction on its own, from the same state under the running plan.
  auto model = adroit::loadModelString(kPointMass).model;
  StatePredictor predictor;
  predictor.initialize(model.get());
  const PlannerState measured = pointState(1.05, 0.01, -0.005, 0.3, -0.1);
  PlannerState predicted = measured;
  ASSERT_NEAR(predictor.predict(running, 1.0, 0.05, predicted), 0.05, 1e-12);

  const PlanOutcome second = r.planOnce(measured);
  ASSERT_TRUE(second.published);
  EXPECT_NEAR(second.compensated, 0.05, 1e-12);
  EXPECT_EQ(r.planState().time, predicted.time);
  EXPECT_EQ(r.planState().qpos, predicted.qpos);
  EXPECT_EQ(r.planState().qvel, predicted.qvel);
  EXPECT_EQ(second.activation, 1.05 + 0.05);  // takes over after the measured state, not the predicted one
  EXPECT_TRUE(r.updatePolicy(second.activation));
  EXPECT_EQ(r.policy().policy.t0, predicted.time);

  // Not while the world waits.
  const PlanOutcome waiting = r.planOnce(pointState(1.1, 0, 0), true);
  EXPECT_EQ(waiting.compensated, 0.0);
  EXPECT_EQ(r.planState().time, 1.1);
}

TEST(MpcRunner, AReplacedTaskIsObservedAndPlannedAndAHorizonChangeReinitialises) {
  std::vector<std::pair<double, std::string>> seen;
  RunnerSettings rs = emulated(0.0);
  rs.on_events = [&](double t, const std::vector<TaskEvent>& events) {
    for (const auto& e : events) seen.emplace_back(t, e.detail);
  };
  Fixture f(std::move(rs));
  MpcRunner& r = *f.runner;
  {
    std::lock_guard<std::mutex> lock(r.taskMutex());
    f.task().report = true;
  }
  r.planOnce(pointState(0.1, 0, 0));
  {
    std::lock_guard<std::mutex> lock(r.taskMutex());
    auto other = goalTask(-0.3, 0.2, "other");
    other->report = true;
    r.replaceTask(std::move(other));
    r.setHorizon(0.2);
    EXPECT_EQ(r.horizon(), 0.2);
  }
  EXPECT_EQ(r.planningHorizon(), 0.3);  // until the next plan
  for (int k = 0; k < 5; ++k) r.planOnce(pointState(0.2, 0, 0));
  ASSERT_EQ(seen.size(), 6u);
  EXPECT_EQ(seen[0], std::make_pair(0.1, std::string("goal")));
  EXPECT_EQ(seen[1], std::make_pair(0.2, std::string("other")));
  EXPECT_EQ(seen[5].second, "other");
  EXPECT_EQ(r.planningHorizon(), 0.2);
  r.updatePolicy(1e9);
  EXPECT_EQ(r.policy().policy.knots(), 20);
  // The new task's goal is planned for: the first control pushes towards -x, +y.
  EXPECT_LT(r.policy().policy.u[0][0], 0);
  EXPECT_GT(r.policy().policy.u[0][1], 0);
}

TEST(MpcRunner, TheControlSideAndARunningPlannerAllocateNothing) {
  Fixture f(emulated(0.0));
  MpcRunner& r = *f.runner;
  // Every slot of the exchange (and the planner) has held a plan of its final size.
  for (int k = 0; k < 6; ++k) {
    r.planOnce(pointState(0.01 * k, 0, 0));
    r.updatePolicy(1e9);
  }
  const double q[2] = {0.01, 0}, v[2] = {0, 0};
  double u[2];
  std::vector<double> ref(2 * 64);
  std::vector<PlannerState> states;
  for (int k = 0; k < 10; ++k) states.push_back(pointState(0.01 * k, 0, 0));
  allocations = 0;
  counting = true;
  int acted = 0;
  for (int k = 6; k < 10; ++k) {
    r.planOnce(states[k]);
    acted += r.updatePolicy(0.01 * k);
    double age = 0;
    acted += r.usable(0.01 * k, &age);
    acted += r.action(0.01 * k, q, v, nullptr, u);
    acted += r.reference(0.01 * k, q, v, nullptr, 64, ref.data()) > 0;
    r.recordPolicyAge(age);
  }
  counting = false;
  EXPECT_EQ(allocations.load(), 0);
  EXPECT_EQ(acted, 16);
}
