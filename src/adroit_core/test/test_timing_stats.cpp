#include <gtest/gtest.h>

#include <cmath>
#include <thread>

#include "adroit_core/timing_stats.h"

TEST(TimingStats, SummaryOfKnownSeries) {
  adroit::SampleStats s;
  // 1..100 in scrambled order: median 50 (nearest rank), p99 99.
  for (int i = 0; i < 100; ++i) s.add((i * 37) % 100 + 1);
  const auto sum = s.summary();
  EXPECT_EQ(sum.count, 100u);
  EXPECT_EQ(sum.min, 1);
  EXPECT_EQ(sum.max, 100);
  EXPECT_EQ(sum.median, 50);
  EXPECT_EQ(sum.p99, 99);
  EXPECT_DOUBLE_EQ(sum.mean, 50.5);
  EXPECT_EQ(s.samples().front(), 1);  // arrival order kept
  EXPECT_EQ(s.samples()[1], 38);
}

TEST(TimingStats, EdgeCases) {
  EXPECT_EQ(adroit::SampleStats().summary().count, 0u);
  EXPECT_EQ(adroit::percentile({}, 50), 0);
  EXPECT_EQ(adroit::percentile({7}, 99), 7);
  EXPECT_EQ(adroit::percentile({3, 1, 2}, 0), 1);
  EXPECT_EQ(adroit::percentile({3, 1, 2}, 100), 3);
}

TEST(TimingStats, StopwatchMeasuresSleep) {
  adroit::Stopwatch w;
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const double t = w.elapsed();
  EXPECT_GE(t, 0.020);
  EXPECT_LT(t, 0.5);
}

TEST(TimingStats, FormatsScaled) {
  adroit::Summary s{3, 0.001, 0.002, 0.002, 0.003, 0.004};
  EXPECT_EQ(adroit::formatSummary(s, 1e3, "ms"), "min 1 / median 2 / p99 3 / max 4 ms");
}

TEST(TimingStats, ResultLinePassesOnlyOnTheRightSideOfTheTarget) {
  EXPECT_EQ(adroit::resultLine("pkg", "lag_p99", 0.5, "ms", "<=", 1.0), "RESULT pkg/lag_p99 0.5 ms target <= 1 PASS");
  EXPECT_EQ(adroit::resultLine("pkg", "x", 1.0, "s", "<=", 1.0), "RESULT pkg/x 1 s target <= 1 PASS");
  EXPECT_NE(adroit::resultLine("pkg", "x", 1.0, "s", "<", 1.0).find("FAIL"), std::string::npos);
  EXPECT_NE(adroit::resultLine("pkg", "x", 2.0, "", ">=", 3.0).find("FAIL"), std::string::npos);
  EXPECT_NE(adroit::resultLine("pkg", "x", 4.0, "", ">", 3.0).find("PASS"), std::string::npos);
  EXPECT_NE(adroit::resultLine("pkg", "x", 4.0, "", "==", 4.0).find("FAIL"), std::string::npos);  // unknown op
  EXPECT_NE(adroit::resultLine("pkg", "x", std::nan(""), "", "<=", 4.0).find("FAIL"), std::string::npos);
}
