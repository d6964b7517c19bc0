// Command validation: addressing, NaN/Inf, range (reject for volts, clamp above for forces).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "adroit_core/mujoco_model.h"
#include "adroit_driver/command_check.h"

namespace adroit::driver {
namespace {

const char* kTwoActuators = R"(
<mujoco>
  <worldbody><body><joint name="j" type="hinge"/><geom size="0.1"/></body></worldbody>
  <actuator><motor name="a0" joint="j"/><motor name="a1" joint="j"/></actuator>
</mujoco>)";

class CommandCheck : public ::testing::Test {
 protected:
  void SetUp() override {
    model_ = loadModelString(kTwoActuators).model;
    names_ = NameIndex(model_.get(), mjOBJ_ACTUATOR);
    volts_.lower = {-5, -5};
    volts_.upper = {5, 5};
    force_.lower = {0, 0};
    force_.upper = {30, 100};
    force_.clamp_above = true;
  }
  ModelPtr model_;
  NameIndex names_;
  ValueLimits volts_, force_;
};

TEST_F(CommandCheck, AcceptsByNameAndByIndexInAnyOrderAndSubsets) {
  auto c = checkCommand(names_, {"a1", "a0"}, {}, {1.0, -2.0}, volts_);
  ASSERT_EQ(c.verdict, CommandVerdict::kAccepted) << c.error;
  EXPECT_EQ(c.actuator, (std::vector<int>{1, 0}));
  EXPECT_EQ(c.value, (std::vector<double>{1.0, -2.0}));
  c = checkCommand(names_, {}, {1}, {4.5}, volts_);
  ASSERT_EQ(c.verdict, CommandVerdict::kAccepted);
  EXPECT_EQ(c.actuator, (std::vector<int>{1}));
}

TEST_F(CommandCheck, RejectsBadAddressing) {
  EXPECT_EQ(checkCommand(names_, {"a0"}, {0}, {1.0}, volts_).verdict, CommandVerdict::kBadAddressing);
  EXPECT_EQ(checkCommand(names_, {}, {}, {1.0}, volts_).verdict, CommandVerdict::kBadAddressing);
  EXPECT_EQ(checkCommand(names_, {"a0", "a1"}, {}, {1.0}, volts_).verdict, CommandVerdict::kBadAddressing);
  EXPECT_EQ(checkCommand(names_, {}, {}, {}, volts_).verdict, CommandVerdict::kEmpty);
  EXPECT_EQ(checkCommand(names_, {"a0", "a0"}, {}, {1.0, 1.0}, volts_).verdict, CommandVerdict::kDuplicate);
}

TEST_F(CommandCheck, RejectsUnknownNamesAndIndices) {
  const auto c = checkCommand(names_, {"a0", "nope"}, {}, {1.0, 1.0}, volts_);
  EXPECT_EQ(c.verdict, CommandVerdict::kUnknownName);
  EXPECT_NE(c.error.find("nope"), std::string::npos);
  EXPECT_EQ(checkCommand(names_, {}, {2}, {1.0}, volts_).verdict, CommandVerdict::kIndexOutOfRange);
}

TEST_F(CommandCheck, RejectsNonFiniteValues) {
  EXPECT_EQ(checkCommand(names_, {}, {0, 1}, {1.0, std::nan("")}, volts_).verdict, CommandVerdict::kNotFinite);
  EXPECT_EQ(checkCommand(names_, {}, {0}, {std::numeric_limits<double>::infinity()}, force_).verdict,
            CommandVerdict::kNotFinite);
}

TEST_F(CommandCheck, VoltsOutOfRangeAreRejectedNotClamped) {
  EXPECT_EQ(checkCommand(names_, {}, {0}, {5.01}, volts_).verdict, CommandVerdict::kOutOfRange);
  EXPECT_EQ(checkCommand(names_, {}, {0}, {-5.01}, volts_).verdict, CommandVerdict::kOutOfRange);
  EXPECT_EQ(checkCommand(names_, {}, {0}, {5.0}, volts_).verdict, CommandVerdict::kAccepted);
}

// A rejected value reaches a throttled log line: it must stay one short line.
TEST_F(CommandCheck, AHugeValueIsNamedShortly) {
  const auto c = checkCommand(names_, {}, {0}, {1e308}, volts_);
  ASSERT_EQ(c.verdict, CommandVerdict::kOutOfRange);
  EXPECT_NE(c.error.find("1e+308"), std::string::npos) << c.error;
  EXPECT_NE(c.error.find("[-5, 5]"), std::string::npos) << c.error;
  EXPECT_LT(c.error.size(), 80u) << c.error;
}

TEST_F(CommandCheck, ForcesAboveMaximumAreClampedPerActuatorNegativeRejected) {
  const auto c = checkCommand(names_, {}, {0, 1}, {45.0, 45.0}, force_);
  ASSERT_EQ(c.verdict, CommandVerdict::kClamped);
  EXPECT_EQ(c.value, (std::vector<double>{30.0, 45.0}));
  EXPECT_EQ(checkCommand(names_, {}, {0}, {-0.1}, force_).verdict, CommandVerdict::kOutOfRange);
}

}  // namespace
}  // namespace adroit::driver
