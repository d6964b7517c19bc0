// PoolGroup without ROS: a pool in a group commands exactly what it commands alone, the
// verdicts stay per pool, one command covers every cylinder in pool order, a stale state
// exhausts every cylinder of the group, valve indices come once every pool has them, and a
// cylinder in two pools is refused. NameColumns: the cached resolution follows the names.
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>

#include <gtest/gtest.h>

#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/pool_group.h"

using namespace adroit::pneumatics;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kAtm = constants::kAtmosphere;
const std::vector<std::string> kModel = {"A_ARJ0_flex", "A_FFJ2_flex", "A_FFJ2_ext", "A_MFJ2_flex", "A_MFJ2_ext"};
const std::vector<std::string> kFF = {"A_FFJ2_flex", "A_FFJ2_ext"}, kMF = {"A_MFJ2_ext", "A_MFJ2_flex"};

std::unique_ptr<CylinderPool> makePool(const std::vector<std::string>& names, const std::string& controller = "ilqg",
                                       const std::vector<std::string>& model = kModel) {
  const CylinderSpec s = cylinderSpec("M9");
  std::vector<PoolCylinder> cylinders;
  for (const auto& n : names) cylinders.push_back({n, s.bore_area, s.dead_volume, ParametricParams{}});
  PoolOptions o;
  o.controller = controller;
  o.ilqg.horizon = 40;  // quick; the horizon is not what is tested here
  return std::make_unique<CylinderPool>(cylinders, model, o);
}

PoolGroup makeGroup(const std::string& controller_ff = "ilqg", const std::string& controller_mf = "pidf") {
  std::vector<std::unique_ptr<CylinderPool>> pools;
  pools.push_back(makePool(kFF, controller_ff));
  pools.push_back(makePool(kMF, controller_mf));
  return PoolGroup(std::move(pools));
}

// A state of every model cylinder by name, in an order other than the model's.
const std::vector<std::string> kStateOrder = {"A_MFJ2_ext", "A_FFJ2_flex", "A_ARJ0_flex", "A_MFJ2_flex", "A_FFJ2_ext"};

std::vector<double> pressures(double t) {
  std::vector<double> p;
  for (std::size_t j = 0; j < kStateOrder.size(); ++j) p.push_back(kAtm + 80e3 + 30e3 * std::sin(7 * t + j));
  return p;
}

// 20 steps of 10 ms for every model cylinder but the arm's, moving with t.
std::vector<double> forces(double t) {
  std::vector<double> f;
  for (int k = 0; k < 20; ++k)
    for (int j = 0; j < 4; ++j) f.push_back(5.0 + 3.0 * std::sin(t + 0.01 * k + j));
  return f;
}
const std::vector<std::string> kReferenceNames = {"A_FFJ2_flex", "A_MFJ2_flex", "A_FFJ2_ext", "A_MFJ2_ext"};

}  // namespace

TEST(NameColumns, ResolvesAndFollowsChangedNames) {
  NameColumns columns(kModel);
  const Columns& a = columns.resolve({"A_MFJ2_ext", "A_NOPE", "A_FFJ2_flex"});
  EXPECT_EQ(a.known, (std::vector<int>{4, -1, 1}));
  EXPECT_EQ(a.first_unknown, 1);
  EXPECT_EQ(a.first_duplicate, -1);
  // The same names again: the same resolution.
  EXPECT_EQ(&columns.resolve({"A_MFJ2_ext", "A_NOPE", "A_FFJ2_flex"}), &a);
  EXPECT_EQ(a.known, (std::vector<int>{4, -1, 1}));
  // Other names, however alike, are resolved afresh.
  const Columns& b = columns.resolve({"A_MFJ2_ext", "A_FFJ2_flex", "A_MFJ2_ext"});
  EXPECT_EQ(b.known, (std::vector<int>{4, 1, 4}));
  EXPECT_EQ(b.first_unknown, -1);
  EXPECT_EQ(b.first_duplicate, 2);
  EXPECT_EQ(columns.resolve({}).size(), 0u);
  EXPECT_EQ(columns.modelOrder().known, (std::vector<int>{0, 1, 2, 3, 4}));
  EXPECT_EQ(columns.find("A_FFJ2_ext"), 2);
  EXPECT_EQ(columns.find("A_NOPE"), -1);
}

TEST(PoolGroup, ConstructionRefusesOverlapsAndMixedModels) {
  std::vector<std::unique_ptr<CylinderPool>> overlap;
  overlap.push_back(makePool(kFF));
  overlap.push_back(makePool({"A_MFJ2_flex", "A_FFJ2_ext"}));
  try {
    PoolGroup group(std::move(overlap));
    FAIL() << "a cylinder in two pools was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("A_FFJ2_ext"), std::string::npos) << e.what();
  }
  std::vector<std::unique_ptr<CylinderPool>> mixed;
  mixed.push_back(makePool(kFF));
  mixed.push_back(makePool({"A_MFJ2_flex"}, "ilqg", {"A_MFJ2_flex", "A_FFJ2_flex", "A_FFJ2_ext"}));
  EXPECT_THROW(PoolGroup(std::move(mixed)), std::invalid_argument);
  EXPECT_THROW(PoolGroup({}), std::invalid_argument);
}

// The group runs the same pools on the same inputs: every command equals, to the bit, what
// the pool commands on its own, in pool order.
TEST(PoolGroup, EachPoolCommandsWhatItCommandsAlone) {
  PoolGroup group = makeGroup();
  const auto ff = makePool(kFF, "ilqg"), mf = makePool(kMF, "pidf");
  EXPECT_EQ(group.names(), (std::vector<std::string>{"A_FFJ2_flex", "A_FFJ2_ext", "A_MFJ2_ext", "A_MFJ2_flex"}));
  int driven = 0;
  for (int k = 0; k < 200; ++k) {
    const double t = 0.005 * k;
    const std::vector<double> p = pressures(t), length(kStateOrder.size(), 0.01), rate(kStateOrder.size(), 0.0);
    for (const StateVerdict& v : group.setState(t, t, kStateOrder, p, length, rate, 620e3)) ASSERT_TRUE(v.ok());
    ASSERT_TRUE(ff->setState(t, t, kStateOrder, p, length, rate, 620e3).ok());
    ASSERT_TRUE(mf->setState(t, t, kStateOrder, p, length, rate, 620e3).ok());
    if (k % 7 == 0) {
      for (const Verdict& v : group.setReference(t, t, 0.01, 20, kReferenceNames, forces(t))) ASSERT_TRUE(v.ok());
      ASSERT_TRUE(ff->setReference(t, t, 0.01, 20, kReferenceNames, forces(t)).ok());
      ASSERT_TRUE(mf->setReference(t, t, 0.01, 20, kReferenceNames, forces(t)).ok());
    }
    const std::vector<double> u = group.update(t + 0.001);
    std::vector<double> alone = ff->update(t + 0.001);
    const std::vector<double>& u_mf = mf->update(t + 0.001);
    alone.insert(alone.end(), u_mf.begin(), u_mf.end());
    ASSERT_EQ(u, alone) << "tick " << k;
    driven += u[0] != -5.0 && u[3] != -5.0;
  }
  EXPECT_GT(driven, 150);  // both controllers were driving, not exhausting
  EXPECT_EQ(group.pool(0).counters().ticks, 200u);
  EXPECT_EQ(group.pool(1).counters().ticks, 200u);
}

TEST(PoolGroup, VerdictsStayPerPool) {
  PoolGroup group = makeGroup();
  // NaN in a cylinder of the second pool rejects the state for that pool only.
  std::vector<double> p(kStateOrder.size(), kAtm);
  p[3] = kNaN;  // A_MFJ2_flex
  const auto& states = group.setState(0, 0, kStateOrder, p, {}, {}, 620e3);
  ASSERT_EQ(states.size(), 2u);
  EXPECT_TRUE(states[0].ok());
  EXPECT_EQ(states[1].reason, StateReject::kNonFinite);
  // A reference naming only the first pool's cylinders is the second's to ignore.
  const auto& refs = group.setReference(0, 0, 0.01, 1, kFF, {1.0, 2.0});
  EXPECT_TRUE(refs[0].ok() && !refs[0].ignored);
  EXPECT_TRUE(refs[1].ok() && refs[1].ignored);
  // What is wrong with the message itself is every pool's verdict.
  const auto& unknown = group.setReference(0, 0, 0.01, 1, {"A_FFJ2_flex", "A_NOPE"}, {1.0, 2.0});
  EXPECT_EQ(unknown[0].reason, RejectReason::kUnknownName);
  EXPECT_EQ(unknown[1].reason, RejectReason::kUnknownName);
  const auto& twice = group.setState(0, 0, {"A_FFJ2_flex", "A_ARJ0_flex", "A_FFJ2_flex"}, {kAtm, kAtm, kAtm}, {},
                                     {}, 620e3);
  EXPECT_EQ(twice[0].reason, StateReject::kDuplicateName);
  EXPECT_EQ(twice[1].reason, StateReject::kDuplicateName);
}

TEST(PoolGroup, StaleStateExhaustsEveryCylinder) {
  PoolGroup group = makeGroup("ilqg", "ilqg");
  const double timeout = group.pool(0).options().state_timeout;
  for (const StateVerdict& v : group.setState(0, 0, kStateOrder, pressures(0), {}, {}, 620e3)) ASSERT_TRUE(v.ok());
  for (const Verdict& v : group.setReference(0, 0, 0.01, 20, kReferenceNames, forces(0))) ASSERT_TRUE(v.ok());
  for (double x : group.update(0.5 * timeout)) EXPECT_NE(x, -5.0);  // driven
  // The reference is still valid, the state is old: every cylinder of every pool exhausts.
  EXPECT_EQ(group.update(1.5 * timeout), std::vector<double>(4, -5.0));
  EXPECT_EQ(group.pool(0).exhausting(), 2u);
  EXPECT_EQ(group.pool(1).exhausting(), 2u);
}

TEST(PoolGroup, ValveIndicesOnceEveryPoolHasThem) {
  PoolGroup group = makeGroup();
  // A state without the second pool's cylinders resolves the first pool only.
  group.setState(0, 0, {"A_FFJ2_ext", "A_FFJ2_flex"}, {kAtm, kAtm}, {}, {}, 620e3);
  EXPECT_TRUE(group.pool(0).valveIndicesResolved());
  EXPECT_FALSE(group.valveIndicesResolved());
  // The first pool keeps the order it resolved: the complete state must agree with it.
  const std::vector<std::string> order = {"A_FFJ2_ext", "A_FFJ2_flex", "A_MFJ2_flex", "A_ARJ0_flex", "A_MFJ2_ext"};
  for (const StateVerdict& v : group.setState(0, 0, order, std::vector<double>(5, kAtm), {}, {}, 620e3))
    ASSERT_TRUE(v.ok());
  ASSERT_TRUE(group.valveIndicesResolved());
  // names() order: A_FFJ2_flex, A_FFJ2_ext, A_MFJ2_ext, A_MFJ2_flex.
  EXPECT_EQ(group.valveIndices(), (std::vector<int>{1, 0, 4, 2}));
}
