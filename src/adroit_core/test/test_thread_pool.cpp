#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <stdexcept>
#include <thread>

#include "adroit_core/thread_pool.h"

#include <cstdlib>
#include <new>

// Counts heap allocations made while `counting` is set (parallelForWorkers must make none).
static std::atomic<bool> counting{false};
static std::atomic<long> allocations{0};
void* operator new(std::size_t size) {
  if (counting) allocations++;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

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

TEST(ThreadPool, ParallelForWorkersVisitsEveryIndexOnceWithItsWorker) {
  adroit::ThreadPool pool(3);
  std::vector<std::atomic<int>> hits(500);
  std::vector<std::atomic<int>> per_worker(3);
  std::atomic<int> bad_worker{0};
  for (int round = 0; round < 20; ++round) {  // repeated batches reuse the same workers
    pool.parallelForWorkers(hits.size(), [&](std::size_t i, std::size_t w) {
      hits[i]++;
      if (w >= 3) bad_worker++; else per_worker[w]++;
    });
  }
  for (auto& h : hits) EXPECT_EQ(h.load(), 20);
  EXPECT_EQ(bad_worker.load(), 0);
  EXPECT_EQ(per_worker[0] + per_worker[1] + per_worker[2], 20 * 500);
}

TEST(ThreadPool, ParallelForWorkersGivesEachThreadItsOwnWorkerIndex) {
  adroit::ThreadPool pool(2);
  std::mutex m;
  std::set<std::pair<std::size_t, std::thread::id>> seen;
  pool.parallelForWorkers(2, [&](std::size_t, std::size_t w) {
    {
      std::lock_guard<std::mutex> lock(m);
      seen.insert({w, std::this_thread::get_id()});
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  });
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_NE(seen.begin()->first, std::next(seen.begin())->first);    // two worker indices
  EXPECT_NE(seen.begin()->second, std::next(seen.begin())->second);  // on two threads
}

TEST(ThreadPool, ParallelForWorkersRethrowsAfterEveryIndexRan) {
  adroit::ThreadPool pool(2);
  std::atomic<int> ran{0};
  EXPECT_THROW(pool.parallelForWorkers(10,
                                       [&](std::size_t i, std::size_t) {
                                         ran++;
                                         if (i == 5) throw std::runtime_error("boom");
                                       }),
               std::runtime_error);
  EXPECT_EQ(ran.load(), 10);
  // The pool still works afterwards, for both kinds of parallel loops.
  std::atomic<int> after{0};
  pool.parallelForWorkers(4, [&](std::size_t, std::size_t) { after++; });
  pool.parallelFor(4, [&](std::size_t) { after++; });
  EXPECT_EQ(after.load(), 8);
}

TEST(ThreadPool, ParallelForWorkersAllocatesNothing) {
  adroit::ThreadPool pool(2);
  std::vector<double> out(64, 0.0);
  pool.parallelForWorkers(out.size(), [&](std::size_t i, std::size_t) { out[i] = 1.0; });  // warm up
  allocations = 0;
  counting = true;
  for (int round = 0; round < 50; ++round)
    pool.parallelForWorkers(out.size(), [&](std::size_t i, std::size_t w) { out[i] += 1.0 + 0.0 * w; });
  counting = false;
  EXPECT_EQ(allocations.load(), 0);
  EXPECT_EQ(out[0], 51.0);
  EXPECT_EQ(out[63], 51.0);
}
