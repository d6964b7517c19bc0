// CylinderPool without ROS: reference and state validation (shape, names, stamps against
// the pool's clock), fail-safe exhaust, valve indices, the hand-over between threads,
// closed-loop force tracking against a plant, and the default pool split of the real model.
#include <array>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include <gtest/gtest.h>

#include "adroit_description/scenes.h"
#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/pool.h"

using namespace adroit::pneumatics;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kAtm = constants::kAtmosphere;
const std::vector<std::string> kModel = {"A_ARJ0_flex", "A_FFJ2_flex", "A_FFJ2_ext", "A_MFJ2_flex", "A_MFJ2_ext"};

PoolCylinder m9(const std::string& name) {
  const CylinderSpec s = cylinderSpec("M9");
  return {name, s.bore_area, s.dead_volume, ParametricParams{}};
}

CylinderPool makePool(const std::string& controller = "ilqg", double reference_timeout = 0.2) {
  PoolOptions o;
  o.controller = controller;
  o.reference_timeout = reference_timeout;
  o.ilqg.horizon = 40;  // keeps the test quick; the horizon length is not what is tested here
  return CylinderPool({m9("A_FFJ2_flex"), m9("A_FFJ2_ext")}, kModel, o);
}

// State for all model cylinders in model order; the pool's two at pressure p.
void feedState(CylinderPool& pool, double now, double p) {
  const std::vector<double> pressure(kModel.size(), p), length(kModel.size(), 0.01), rate(kModel.size(), 0.0);
  ASSERT_TRUE(pool.setState(now, now, {}, pressure, length, rate, 620e3).ok());
}

Verdict constantReference(CylinderPool& pool, double now, double f_flex, double f_ext) {
  // 10 steps of 10 ms; also names a cylinder of another pool.
  std::vector<double> force;
  for (int k = 0; k < 10; ++k) force.insert(force.end(), {f_flex, 3.0, f_ext});
  return pool.setReference(now, now, 0.01, 10, {"A_FFJ2_flex", "A_MFJ2_flex", "A_FFJ2_ext"}, force);
}

bool allExhaust(const std::vector<double>& u) {
  for (double x : u)
    if (x != -5.0) return false;
  return true;
}

}  // namespace

TEST(Pool, ConstructionRejectsBadConfiguration) {
  PoolOptions o;
  EXPECT_THROW(CylinderPool({m9("A_XXJ9_flex")}, kModel, o), std::invalid_argument);
  EXPECT_THROW(CylinderPool({m9("A_FFJ2_flex"), m9("A_FFJ2_flex")}, kModel, o), std::invalid_argument);
  EXPECT_THROW(CylinderPool({}, kModel, o), std::invalid_argument);
  o.controller = "pid";
  try {
    CylinderPool({m9("A_FFJ2_flex")}, kModel, o);
    FAIL() << "controller 'pid' accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("controller"), std::string::npos) << e.what();
  }
}

TEST(Pool, ExhaustsWithoutReferenceOrState) {
  CylinderPool pool = makePool();
  EXPECT_TRUE(allExhaust(pool.update(0.0)));  // nothing yet
  feedState(pool, 0.0, kAtm);
  EXPECT_TRUE(allExhaust(pool.update(0.005)));  // state but no reference
  EXPECT_EQ(pool.exhausting(), 2u);
  CylinderPool pool2 = makePool();
  ASSERT_TRUE(constantReference(pool2, 0.0, 5.0, 5.0).ok());
  EXPECT_TRUE(allExhaust(pool2.update(0.005)));  // reference but no state
}

TEST(Pool, BadReferencesAreRejectedWithTheirReason) {
  CylinderPool pool = makePool();
  const std::vector<std::string> two = {"A_FFJ2_flex", "A_FFJ2_ext"};
  // (The node counts the verdicts by reason, one counter each, in its diagnostics.)
  std::array<int, static_cast<int>(RejectReason::kCount)> count{};
  auto check = [&](const Verdict& v) {
    ++count[static_cast<int>(v.reason)];
    EXPECT_FALSE(v.ignored);
    EXPECT_EQ(v.ok(), v.detail.empty());
    return v.reason;
  };
  EXPECT_EQ(check(pool.setReference(0, 0, 0.01, 2, two, {1, 2, kNaN, 4})), RejectReason::kNonFinite);
  EXPECT_EQ(check(pool.setReference(0, 0, 0.01, 2, two, {1, std::numeric_limits<double>::infinity(), 3, 4})),
            RejectReason::kNonFinite);
  EXPECT_EQ(check(pool.setReference(0, 0, 0.01, 2, two, {1, 2, 3})), RejectReason::kLength);
  EXPECT_EQ(check(pool.setReference(0, 0, 0.01, 0, two, {})), RejectReason::kLength);
  EXPECT_EQ(check(pool.setReference(0, 0, 0.01, 1, {"A_FFJ2_flex", "A_NOPE_ext"}, {1, 2})),
            RejectReason::kUnknownName);
  EXPECT_EQ(check(pool.setReference(0, 0, 0.01, 1, {"A_FFJ2_flex", "A_FFJ2_flex"}, {1, 2})),
            RejectReason::kDuplicateName);
  EXPECT_EQ(check(pool.setReference(0, 0, 0.0, 2, two, {1, 2, 3, 4})), RejectReason::kTiming);
  EXPECT_EQ(check(pool.setReference(0, kNaN, 0.01, 1, two, {1, 2})), RejectReason::kTiming);
  EXPECT_EQ(count[static_cast<int>(RejectReason::kNone)], 0);
  EXPECT_EQ(count[static_cast<int>(RejectReason::kNonFinite)], 2);
  EXPECT_EQ(count[static_cast<int>(RejectReason::kLength)], 2);
  // A reference for other pools only is valid but not ours.
  const Verdict other = pool.setReference(0, 0, 0.01, 1, {"A_MFJ2_flex"}, {1});
  EXPECT_TRUE(other.ok());
  EXPECT_TRUE(other.ignored);
  // Nothing of all that became a plan.
  feedState(pool, 0.0, kAtm);
  EXPECT_TRUE(allExhaust(pool.update(0.005)));
}

TEST(Pool, BadStatesAreRejectedAndChangeNothing) {
  CylinderPool pool = makePool();
  EXPECT_EQ(pool.setState(0, 0, {}, {kAtm, kAtm}, {}, {}, 620e3).reason, StateReject::kLength);  // 2 pressures, 5 cylinders
  EXPECT_EQ(pool.setState(0, 0, {"A_FFJ2_flex"}, {kNaN}, {}, {}, 620e3).reason, StateReject::kNonFinite);
  EXPECT_EQ(pool.setState(0, 0, {"A_FFJ2_flex"}, {kAtm}, {}, {}, kNaN).reason, StateReject::kNonFinite);
  // NaN in another pool's cylinder is not this pool's business.
  EXPECT_TRUE(pool.setState(0, 0, {"A_MFJ2_flex", "A_FFJ2_flex"}, {kNaN, kAtm}, {}, {}, 620e3).ok());
}

// A stamp far from the pool's clock: a wall-clock stamp while the pool runs on sim time, a
// stamp in the future, a reference already over. Before, each was accepted and its last
// sample held as a constant.
TEST(Pool, ReferencesStampedFarFromTheClockAreRejected) {
  CylinderPool pool = makePool();
  const double now = 100.0;  // sim time
  const double tol = pool.options().stamp_tolerance;
  const std::vector<std::string> one = {"A_FFJ2_flex"};
  const std::vector<double> ten(10, 5.0);
  EXPECT_EQ(pool.setReference(now, 1.7e9, 0.01, 10, one, ten).reason, RejectReason::kStampFuture);  // wall clock
  EXPECT_EQ(pool.setReference(now, now + 2 * tol, 0.01, 10, one, ten).reason, RejectReason::kStampFuture);
  // 10 samples of 10 ms that ended 0.5 s ago; a single sample 2 tolerances old.
  EXPECT_EQ(pool.setReference(now, now - 0.59, 0.01, 10, one, ten).reason, RejectReason::kStampPast);
  EXPECT_EQ(pool.setReference(now, now - 2 * tol, 0.01, 1, one, {5.0}).reason, RejectReason::kStampPast);
  // Sim-time stamps seen by a pool on wall time.
  EXPECT_EQ(pool.setReference(1.7e9, now, 0.01, 10, one, ten).reason, RejectReason::kStampPast);
  // None of them drives the cylinder.
  feedState(pool, now, kAtm);
  pool.update(now);
  EXPECT_EQ(pool.exhausting(), 2u);
  // Within the tolerance either way, and a long reference that started a while ago but
  // still runs, are fine.
  EXPECT_TRUE(pool.setReference(now, now + 0.5 * tol, 0.01, 10, one, ten).ok());
  EXPECT_TRUE(pool.setReference(now, now - 0.5 * tol, 0.01, 1, one, {5.0}).ok());
  EXPECT_TRUE(pool.setReference(now, now - 0.3, 0.01, 100, one, std::vector<double>(100, 5.0)).ok());
  feedState(pool, now + 0.005, kAtm);
  pool.update(now + 0.005);
  EXPECT_EQ(pool.exhausting(), 1u);  // A_FFJ2_flex is driven, A_FFJ2_ext has no plan
}

// A spent solve budget: each cylinder keeps commanding from the plan it has (finite, not the
// exhaust), and every solve it skips is counted; without a budget nothing is deferred.
TEST(Pool, ASpentSolveBudgetKeepsThePlansAndCountsTheDeferredSolves) {
  for (const double budget : {0.0, 1e-12}) {
    PoolOptions o;
    o.ilqg.horizon = 40;
    o.solve_budget = budget;
    CylinderPool pool({m9("A_FFJ2_flex"), m9("A_FFJ2_ext")}, kModel, o);
    ASSERT_TRUE(constantReference(pool, 0.0, 5.0, 5.0).ok());
    feedState(pool, 0.0, kAtm);
    pool.update(0.0);  // the first plans are solved whatever the budget
    EXPECT_EQ(pool.counters().solves_deferred, 0u);
    for (int k = 1; k <= 3; ++k) {
      feedState(pool, 0.005 * k, kAtm + 1e3 * k);
      const std::vector<double> u = pool.update(0.005 * k);
      EXPECT_EQ(pool.exhausting(), 0u);
      for (double x : u) EXPECT_TRUE(std::isfinite(x) && x > -5.0) << x;
    }
    EXPECT_EQ(pool.counters().solves_deferred, budget > 0 ? 6u : 0u) << "budget " << budget;
  }
  PoolOptions bad;
  bad.solve_budget = -1e-3;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

TEST(Pool, StampToleranceIsValidated) {
  PoolOptions o;
  o.stamp_tolerance = 0.0;
  try {
    o.validate();
    FAIL() << "stamp_tolerance 0 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("stamp_tolerance"), std::string::npos) << e.what();
  }
}

// Freshness is the state's header stamp, not the time it arrived.
TEST(Pool, StateFreshnessUsesTheStamp) {
  CylinderPool pool = makePool();
  const double timeout = pool.options().state_timeout;
  ASSERT_TRUE(constantReference(pool, 0.0, 5.0, 5.0).ok());
  const std::vector<double> p(kModel.size(), 200e3);
  // Measured at 0, delivered 0.6 timeouts later: accepted (still fresh on arrival) ...
  ASSERT_TRUE(pool.setState(0.6 * timeout, 0.0, {}, p, {}, {}, 620e3).ok());
  pool.update(0.6 * timeout);
  EXPECT_EQ(pool.exhausting(), 0u);
  // ... and stale one timeout after its stamp, however recently it arrived.
  pool.update(1.2 * timeout);
  EXPECT_EQ(pool.exhausting(), 2u);
  // Stale already on arrival, stamped in the future, or without a stamp: rejected.
  EXPECT_EQ(pool.setState(2 * timeout, 0.5 * timeout, {}, p, {}, {}, 620e3).reason, StateReject::kStale);
  EXPECT_EQ(pool.setState(0.0, 1.7e9, {}, p, {}, {}, 620e3).reason, StateReject::kStampFuture);
  EXPECT_EQ(pool.setState(0.0, kNaN, {}, p, {}, {}, 620e3).reason, StateReject::kNoStamp);
  pool.update(2 * timeout);
  EXPECT_EQ(pool.exhausting(), 2u);  // none of them counted as fresh
}

TEST(Pool, UnknownAndDuplicateStateNamesAreReported) {
  CylinderPool pool = makePool();
  // An unknown name is skipped (another model's cylinder) and reported; the rest is used.
  const StateVerdict unknown = pool.setState(0, 0, {"A_FFJ2_flex", "A_NOPE_ext", "A_FFJ2_ext"}, {kAtm, kAtm, kAtm},
                                             {}, {}, 620e3);
  EXPECT_TRUE(unknown.ok());
  EXPECT_TRUE(unknown.unknown_names);
  // (Same places for ours: the first state fixed the valve indices.)
  const StateVerdict clean =
      pool.setState(0, 0, {"A_FFJ2_flex", "A_MFJ2_flex", "A_FFJ2_ext"}, {kAtm, kAtm, kAtm}, {}, {}, 620e3);
  EXPECT_TRUE(clean.ok());
  EXPECT_FALSE(clean.unknown_names);
  // A repeated name is ambiguous: the whole message is rejected, ours or not.
  EXPECT_EQ(pool.setState(0, 0, {"A_FFJ2_flex", "A_FFJ2_flex"}, {kAtm, 300e3}, {}, {}, 620e3).reason,
            StateReject::kDuplicateName);
  EXPECT_EQ(pool.setState(0, 0, {"A_FFJ2_flex", "A_MFJ2_flex", "A_MFJ2_flex"}, {kAtm, kAtm, kAtm}, {}, {}, 620e3)
                .reason,
            StateReject::kDuplicateName);
}

TEST(Pool, ValveIndicesComeFromTheStateOrder) {
  CylinderPool pool = makePool();  // A_FFJ2_flex, A_FFJ2_ext
  // A state without all of ours does not fix them.
  ASSERT_TRUE(pool.setState(0, 0, {"A_FFJ2_flex"}, {kAtm}, {}, {}, 620e3).ok());
  EXPECT_FALSE(pool.valveIndicesResolved());
  const std::vector<std::string> order = {"A_MFJ2_ext", "A_FFJ2_ext", "A_ARJ0_flex", "A_FFJ2_flex"};
  ASSERT_TRUE(pool.setState(0, 0, order, {kAtm, kAtm, kAtm, kAtm}, {}, {}, 620e3).ok());
  ASSERT_TRUE(pool.valveIndicesResolved());
  EXPECT_EQ(pool.valveIndices(), (std::vector<int>{3, 1}));
  // The same order again is fine; another order would send commands to the wrong cylinders.
  EXPECT_TRUE(pool.setState(0, 0, order, {kAtm, kAtm, kAtm, kAtm}, {}, {}, 620e3).ok());
  EXPECT_EQ(pool.setState(0, 0, {"A_FFJ2_flex", "A_FFJ2_ext"}, {kAtm, kAtm}, {}, {}, 620e3).reason,
            StateReject::kNameOrder);
  EXPECT_EQ(pool.setState(0, 0, {}, std::vector<double>(kModel.size(), kAtm), {}, {}, 620e3).reason,
            StateReject::kNameOrder);  // unnamed = model order: ours at 1 and 2
  EXPECT_EQ(pool.valveIndices(), (std::vector<int>{3, 1}));
}

TEST(Handover, NewestValueWinsAndIsTakenOnce) {
  LatestValue<int> box(0);
  EXPECT_FALSE(box.take());
  box.back() = 1;
  box.publish();
  box.back() = 2;
  box.publish();
  ASSERT_TRUE(box.take());
  EXPECT_EQ(box.front(), 2);
  EXPECT_FALSE(box.take());
  EXPECT_EQ(box.front(), 2);  // stays the consumer's
  box.back() = 3;
  box.publish();
  ASSERT_TRUE(box.take());
  EXPECT_EQ(box.front(), 3);
  CommandSlot slot(emptyCommand(2));
  putCommand(slot, 1.5, {0.25, -5.0});
  ASSERT_TRUE(slot.take());
  EXPECT_EQ(slot.front().stamp, 1.5);
  EXPECT_EQ(slot.front().volts, (std::vector<double>{0.25, -5.0}));
}

TEST(Pool, KeepsLastPlanThroughBadReferencesUntilTimeout) {
  CylinderPool pool = makePool("ilqg", 0.2);
  feedState(pool, 0.0, kAtm);
  ASSERT_TRUE(constantReference(pool, 0.0, 8.0, 4.0).ok());
  double t = 0;
  int rejected = 0;
  for (; t < 0.15; t += 0.005) {
    feedState(pool, t, 150e3);
    const Verdict v = pool.setReference(t, t, 0.01, 1, {"A_FFJ2_flex", "A_FFJ2_ext"}, {kNaN, 1.0});  // rejected every tick
    rejected += v.reason == RejectReason::kNonFinite;
    const auto& u = pool.update(t);
    for (double x : u) {
      ASSERT_TRUE(std::isfinite(x));
      // Within the controller's limits, so not the -5 V exhaust: the plan is still in force.
      ASSERT_GE(x, -2.0);
      ASSERT_LE(x, 2.0);
    }
  }
  EXPECT_EQ(pool.exhausting(), 0u);
  EXPECT_GE(rejected, 30);
  for (; t < 0.3; t += 0.005) {
    feedState(pool, t, 150e3);
    pool.update(t);
  }
  EXPECT_TRUE(allExhaust(pool.update(t)));
  EXPECT_EQ(pool.counters().reference_timeouts, 2u);
  // A fresh reference brings the cylinders back.
  ASSERT_TRUE(constantReference(pool, t, 8.0, 4.0).ok());
  EXPECT_EQ(pool.update(t + 0.005).size(), 2u);
  EXPECT_EQ(pool.exhausting(), 0u);
}

TEST(Pool, StaleStateExhausts) {
  CylinderPool pool = makePool();
  feedState(pool, 0.0, 200e3);
  ASSERT_TRUE(constantReference(pool, 0.0, 5.0, 5.0).ok());
  pool.update(0.01);
  EXPECT_EQ(pool.exhausting(), 0u);
  pool.update(0.01 + pool.options().state_timeout + 0.01);  // reference still valid, state old
  EXPECT_EQ(pool.exhausting(), 2u);
}

TEST(Pool, ExtremeStateNeverGivesNonFiniteCommand) {
  for (const char* controller : {"ilqg", "pidf"}) {
    CylinderPool pool = makePool(controller);
    ASSERT_TRUE(constantReference(pool, 0.0, 5.0, 5.0).ok());
    for (double p : {1e300, -1e300, 0.0, 1e-300}) {
      ASSERT_TRUE(pool.setState(0.0, 0.0, {"A_FFJ2_flex", "A_FFJ2_ext"}, {p, p}, {1e300, 0}, {-1e300, 0}, 1e300).ok());
      for (double x : pool.update(0.005)) {
        EXPECT_TRUE(std::isfinite(x)) << controller << " p " << p;
        EXPECT_LE(std::abs(x), 5.0) << controller << " p " << p;
      }
    }
  }
}

// Force tracking: the iLQG pool against its own model as the plant (model-matched, so the
// force -> pressure conversion is what is tested), the PIDF pool against the thin-plate plant.
// The force is measured independently as (p - p_atm) * bore area.
TEST(Pool, TracksForceReferenceInClosedLoop) {
  for (const char* controller : {"ilqg", "pidf"}) {
    PoolOptions o;
    o.controller = controller;
    o.reference_timeout = 10.0;
    const CylinderSpec spec = cylinderSpec("M9");
    CylinderPool pool({m9("A_FFJ2_flex")}, kModel, o);
    PneumaticPlant plant({spec}, SupplyParams{}, 1, PlantOptions{});
    const ParametricModel model{ParametricParams{}};
    const double travel = 0.01, force = 12.0, dt = 0.005;
    double p = kAtm;
    ASSERT_TRUE(pool.setReference(0, 0, dt, 1, {"A_FFJ2_flex"}, {force}).ok());
    double t = 0;
    for (int k = 0; k < 400; ++k, t += dt) {
      const double p_meas = std::string(controller) == "ilqg" ? p : plant.pressure()[0];
      ASSERT_TRUE(pool.setState(t, t, {"A_FFJ2_flex"}, {p_meas}, {travel}, {0.0}, 620e3).ok());
      const double u = pool.update(t)[0];
      ParametricInputs in;
      in.volume = spec.dead_volume + spec.bore_area * travel;
      p = model.step(p, u, dt, in);
      plant.step(dt, &u, &travel, nullptr);
    }
    const double p_end = std::string(controller) == "ilqg" ? p : plant.pressure()[0];
    EXPECT_NEAR((p_end - kAtm) * spec.bore_area, force, 0.05 * force) << controller;
    const PoolWindow w = pool.takeWindow();
    EXPECT_GT(w.solve.count, 0u);
    EXPECT_EQ(w.tracking_samples, 400u);
  }
}

TEST(Pool, NegativeForceMeansAtmosphere) {
  PoolOptions o;
  o.controller = "pidf";
  CylinderPool pool({m9("A_FFJ2_flex")}, kModel, o);
  const Verdict v = pool.setReference(0, 0, 0.005, 1, {"A_FFJ2_flex"}, {-50.0});
  ASSERT_TRUE(v.ok());
  EXPECT_TRUE(v.clamped_negative);  // reported: the node counts it (references_clamped_negative)
  ASSERT_TRUE(pool.setState(0, 0, {"A_FFJ2_flex"}, {kAtm}, {0.01}, {0.0}, 620e3).ok());
  pool.update(0.0);
  // Tracking error is measured against the clamped reference: at atmosphere it is zero.
  EXPECT_NEAR(pool.takeWindow().pressure_rmse, 0.0, 1e-9);
  // Zero is not negative, and another pool's negative force is that pool's to report.
  EXPECT_FALSE(pool.setReference(0, 0, 0.005, 1, {"A_FFJ2_flex"}, {0.0}).clamped_negative);
  const Verdict other = pool.setReference(0, 0, 0.005, 1, {"A_FFJ2_flex", "A_MFJ2_flex"}, {1.0, -3.0});
  ASSERT_TRUE(other.ok());
  EXPECT_FALSE(other.clamped_negative);
}

TEST(PoolSplit, DefaultSplitOfTheArmHandModel) {
  const auto table = loadModelCylinders(adroit::description::sceneFile(ADROIT_DESCRIPTION_SHARE, "arm_hand"));
  std::vector<std::string> names;
  for (const auto& c : table) names.push_back(c.name);
  ASSERT_EQ(names.size(), 48u);
  const auto pools = defaultPoolSplit(names);
  ASSERT_EQ(pools.size(), 6u);
  std::set<std::string> all;
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(pools[i].size(), 8u) << i;
    for (const auto& n : pools[i]) {
      EXPECT_TRUE(all.insert(n).second) << n;
      EXPECT_EQ(n.rfind("A_ARJ", 0) == 0, i == 5) << n;  // arm cylinders only in the sixth
    }
  }
  EXPECT_EQ(all.size(), 48u);
  // Hand pools follow model order.
  std::vector<std::string> hand;
  for (const auto& n : names)
    if (n.rfind("A_ARJ", 0) != 0) hand.push_back(n);
  EXPECT_EQ(pools[0].front(), hand.front());
  EXPECT_EQ(pools[4].back(), hand.back());
  // Every cylinder type of the model gets a positive dead volume growing with the bore.
  for (const auto& c : table) EXPECT_GT(deadVolume(c.type, c.bore_diameter), 0.0) << c.name;
  EXPECT_GT(deadVolume("M40", 0.040), deadVolume("M24", 0.024));
  EXPECT_DOUBLE_EQ(deadVolume("M9", 0.009), cylinderSpec("M9").dead_volume);
}

TEST(PoolSplit, HandOnlyModelHasNoArmPool) {
  const auto pools = defaultPoolSplit({"a", "b", "c"}, 2);
  ASSERT_EQ(pools.size(), 2u);
  EXPECT_EQ(pools[1], std::vector<std::string>{"c"});
}
