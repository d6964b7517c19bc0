#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <stdexcept>
#include <thread>

#include "adroit_core/thread_pool.h"

TEST(ThreadPool, SubmitReturnsResults) {
  adroit::ThreadPool pool(3);
  EXPECT_EQ(pool.size(), 3u);
  auto a = pool.submit([] { return 6 * 7; });
  auto b = pool.submit([] { return std::string("ok"); });
  EXPECT_EQ(a.get(), 42);
  EXPECT_EQ(b.get(), "ok");
}

TEST(ThreadPool, ParallelForVisitsEveryIndexOnce) {
  adroit::ThreadPool pool(4);
  std::vector<std::atomic<int>> hits(1000);
  pool.parallelFor(hits.size(), [&](std::size_t i) { hits[i]++; });
  for (auto& h : hits) EXPECT_EQ(h.load(), 1);
}

TEST(ThreadPool, ParallelForUsesSeveralThreads) {
  adroit::ThreadPool pool(2);
  std::mutex m;
  std::set<std::thread::id> ids;
  pool.parallelFor(2, [&](std::size_t) {
    {
      std::lock_guard<std::mutex> lock(m);
      ids.insert(std::this_thread::get_id());
    }
    // Hold each body long enough that one worker cannot take both indices.
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  });
  EXPECT_EQ(ids.size(), 2u);
}

TEST(ThreadPool, ExceptionsReachTheCaller) {
  adroit::ThreadPool pool(2);
  std::atomic<int> ran{0};
  EXPECT_THROW(pool.parallelFor(10,
                                [&](std::size_t i) {
                                  ran++;
                                  if (i == 3) throw std::runtime_error("boom");
                                }),
               std::runtime_error);
  EXPECT_EQ(ran.load(), 10);  // the other indices still ran
  auto f = pool.submit([]() -> int { throw std::logic_error("bad"); });
  EXPECT_THROW(f.get(), std::logic_error);
}

TEST(ThreadPool, ZeroMeansHardwareConcurrency) {
  adroit::ThreadPool pool(0);
  EXPECT_EQ(pool.size(), std::max(1u, std::thread::hardware_concurrency()));
}
