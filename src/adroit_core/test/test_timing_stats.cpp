#include <gtest/gtest.h>

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
