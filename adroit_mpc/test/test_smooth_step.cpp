// The smooth step of the typing costs against values worked out by hand from the thesis formula
//   S_up(t) = 0.5 ((t - a1) / sqrt((t - a1)^2 + b1^2) - (t - a2) / sqrt((t - a2)^2 + b2^2)).
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "adroit_mpc/smooth_step.h"

using adroit_mpc::SmoothStep;

namespace {
SmoothStep unitPulse() { return SmoothStep{0.0, 0.1, 1.0, 0.1}; }  // a1 = 0, a2 = 1, b = 0.1
}  // namespace

TEST(SmoothStep, FarBeforeAndAfterTheStepsIsOff) {
  const SmoothStep s = unitPulse();
  // t = -10: 0.5 (-10/sqrt(100.01) + 11/sqrt(121.01)) = 0.5 (-0.9999500 + 0.9999587) ~ 4.3e-6
  EXPECT_NEAR(s.up(-10), 0.0, 1e-5);
  EXPECT_NEAR(s.up(11), 0.0, 1e-5);
  EXPECT_NEAR(s.down(-10), 1.0, 1e-5);
}

TEST(SmoothStep, BetweenTheStepsIsOn) {
  const SmoothStep s = unitPulse();
  // t = 0.5: 0.5 (0.5/sqrt(0.26) + 0.5/sqrt(0.26)) = 0.5/0.5099020 = 0.9805807
  EXPECT_NEAR(s.up(0.5), 0.9805807, 1e-7);
  EXPECT_NEAR(s.down(0.5), 0.0194193, 1e-7);
}

TEST(SmoothStep, AtAStepLocationIsHalfOfTheOtherEdge) {
  const SmoothStep s = unitPulse();
  // t = a1 = 0: 0.5 (0 + 1/sqrt(1.01)) = 0.4975186
  EXPECT_NEAR(s.up(0.0), 0.4975186, 1e-7);
  EXPECT_NEAR(s.up(1.0), 0.4975186, 1e-7);
}

TEST(SmoothStep, EqualEdgesAreSymmetricAboutTheMiddle) {
  const SmoothStep s = unitPulse();
  for (double x : {0.05, 0.2, 0.4, 0.9, 3.0}) EXPECT_NEAR(s.up(0.0 + x), s.up(1.0 - x), 1e-12) << x;
}

TEST(SmoothStep, UpAndDownSumToOne) {
  const SmoothStep s{0.3, 0.02, 0.7, 0.08};
  for (double t = -1; t <= 2; t += 0.01) EXPECT_NEAR(s.up(t) + s.down(t), 1.0, 1e-15);
}

TEST(SmoothStep, SmootherEdgeRisesMoreSlowly) {
  const SmoothStep sharp{0.0, 0.01, 10.0, 0.01}, soft{0.0, 0.1, 10.0, 0.01};
  // t = 0.05: sharp 0.5 (0.05/sqrt(0.0026) + ~1) = 0.5 (0.98058 + 0.99999) = 0.99029;
  //           soft  0.5 (0.05/sqrt(0.0125) + ~1) = 0.5 (0.44721 + 0.99999) = 0.72360
  EXPECT_NEAR(sharp.up(0.05), 0.99029, 1e-5);
  EXPECT_NEAR(soft.up(0.05), 0.72360, 1e-5);
}

TEST(SmoothStep, ZeroSmoothnessIsRejected) {
  EXPECT_THROW((SmoothStep{0, 0.0, 1, 0.1}.validate()), std::invalid_argument);
  EXPECT_THROW((SmoothStep{0, 0.1, NAN, 0.1}.validate()), std::invalid_argument);
  EXPECT_NO_THROW(unitPulse().validate());
}
