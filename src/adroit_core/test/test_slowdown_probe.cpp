#include <gtest/gtest.h>

#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

#include "adroit_core/scheduling.h"
#include "adroit_core/slowdown_probe.h"

namespace {

TEST(FractionAbove, CountsOnlySamplesStrictlyAboveTheFactor) {
  adroit::SampleStats s;
  EXPECT_EQ(adroit::fractionAbove(s, 2.0), 0.0);
  for (double x : {1.0, 1.5, 2.0, 2.5, 9.0}) s.add(x);
  EXPECT_DOUBLE_EQ(adroit::fractionAbove(s, 2.0), 0.4);
  EXPECT_DOUBLE_EQ(adroit::fractionAbove(s, 0.5), 1.0);
}

// One sample per period, each relative to the fastest: the fastest is exactly 1, none below.
TEST(SlowdownProbe, SamplesEveryPeriodRelativeToTheFastest) {
  adroit::SlowdownProbe probe(1, 0.005);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  probe.stop();
  ASSERT_GT(probe.slowdowns().count(), 0u) << "SCHED_FIFO refused: " << probe.refusal();
  const adroit::Summary s = probe.slowdowns().summary();
  EXPECT_GE(s.count, 40u);  // 60 periods; a loaded machine may stretch a few
  EXPECT_LE(s.count, 62u);
  EXPECT_DOUBLE_EQ(s.min, 1.0);
}

// A brownout as the VMs here have them: a thread above the probe, on its core, that for 100 ms
// out of every 200 ms leaves it only 20 us of every 120 us. The ~50 us of work then takes
// several of those gaps: about half of the samples come out several times the fastest.
TEST(SlowdownProbe, SeesTheCoreTakenAwayForAWhile) {
  std::atomic<bool> run{true};
  std::string refused;
  std::thread hog([&] {
    if (!adroit::enterFifo(2, &refused)) return;
    const auto start = std::chrono::steady_clock::now();
    while (run.load()) {
      const auto phase = (std::chrono::steady_clock::now() - start) % std::chrono::milliseconds(200);
      if (phase >= std::chrono::milliseconds(100)) {
        std::this_thread::sleep_for(std::chrono::milliseconds(200) - phase);
        continue;
      }
      const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(100);
      while (std::chrono::steady_clock::now() < until) {
      }
      std::this_thread::sleep_for(std::chrono::microseconds(20));
    }
  });
  // Both on the same core, so the hog preempts the probe (the probe thread inherits this mask).
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(0, &one);
  cpu_set_t before;
  pthread_getaffinity_np(pthread_self(), sizeof before, &before);
  pthread_setaffinity_np(pthread_self(), sizeof one, &one);
  pthread_setaffinity_np(hog.native_handle(), sizeof one, &one);
  adroit::SlowdownProbe probe(1, 0.003);
  pthread_setaffinity_np(pthread_self(), sizeof before, &before);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  probe.stop();
  run = false;
  hog.join();
  EXPECT_EQ(refused, "") << "the brownout thread could not enter SCHED_FIFO";
  EXPECT_GT(probe.slowdowns().count(), 0u) << "SCHED_FIFO refused: " << probe.refusal();
  EXPECT_GT(adroit::fractionAbove(probe.slowdowns(), 2.0), 0.25);
  EXPECT_LT(adroit::fractionAbove(probe.slowdowns(), 2.0), 0.75);  // the calm half stays calm
}

}  // namespace
