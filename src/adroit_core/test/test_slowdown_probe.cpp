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

// A probe (SCHED_FIFO 1) on core 0 with `other`, so that `other`, above it, preempts it: the
// probe's thread inherits this thread's mask while it is made.
adroit::SlowdownProbe probeOnCoreOf(std::thread& other, double period) {
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(0, &one);
  cpu_set_t before;
  pthread_getaffinity_np(pthread_self(), sizeof before, &before);
  pthread_setaffinity_np(pthread_self(), sizeof one, &one);
  pthread_setaffinity_np(other.native_handle(), sizeof one, &one);
  struct Restore {
    cpu_set_t mask;
    ~Restore() { pthread_setaffinity_np(pthread_self(), sizeof mask, &mask); }
  } restore{before};
  return adroit::SlowdownProbe(1, period);
}

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
  adroit::SlowdownProbe probe = probeOnCoreOf(hog, 0.003);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  probe.stop();
  run = false;
  hog.join();
  EXPECT_EQ(refused, "") << "the brownout thread could not enter SCHED_FIFO";
  EXPECT_GT(probe.slowdowns().count(), 0u) << "SCHED_FIFO refused: " << probe.refusal();
  EXPECT_GT(adroit::fractionAbove(probe.slowdowns(), 2.0), 0.25);
  EXPECT_LT(adroit::fractionAbove(probe.slowdowns(), 2.0), 0.75);  // the calm half stays calm
}

// A freeze: a thread above the probe, on its core, spins 80 ms without a pause, as when the
// machine itself stops. The probe's work never overlaps it (no slowdown need show), but its
// wake-up waits for the whole of it.
TEST(SlowdownProbe, SeesAFreezeAsItsLongestStall) {
  std::atomic<bool> spin{false};
  std::string refused;
  std::thread freezer([&] {
    if (!adroit::enterFifo(2, &refused)) return;
    while (!spin.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(80);
    while (std::chrono::steady_clock::now() < until) {
    }
  });
  adroit::SlowdownProbe probe = probeOnCoreOf(freezer, 0.005);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  spin = true;
  freezer.join();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  probe.stop();
  EXPECT_EQ(refused, "") << "the freezing thread could not enter SCHED_FIFO";
  ASSERT_GT(probe.slowdowns().count(), 0u) << "SCHED_FIFO refused: " << probe.refusal();
  EXPECT_GT(probe.longestStall(), 0.070);  // the 80 ms, less at most one period it slept anyway
  EXPECT_LT(probe.longestStall(), 0.300);
}

}  // namespace
