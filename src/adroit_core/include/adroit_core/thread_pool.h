// A fixed-size pool of worker threads for planners, rollouts and fitting.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <exception>
#include <functional>
#include <future>
#include <mutex>
#include <queue>
#include <thread>
#include <type_traits>
#include <vector>

namespace adroit {

class ThreadPool {
 public:
  // threads == 0 means one per hardware core.
  explicit ThreadPool(std::size_t threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  std::size_t size() const { return workers_.size(); }

  // Queues a task; the future carries its result or exception.
  template <typename F>
  auto submit(F&& task) -> std::future<decltype(task())> {
    using R = decltype(task());
    auto packaged = std::make_shared<std::packaged_task<R()>>(std::forward<F>(task));
    std::future<R> result = packaged->get_future();
    enqueue([packaged] { (*packaged)(); });
    return result;
  }

  // Runs body(i) for i in [0, n) spread over the workers and waits for all of them.
  // The first exception thrown by a body is rethrown here after every index has run.
  void parallelFor(std::size_t n, const std::function<void(std::size_t)>& body);

  // Runs body(i, worker) for i in [0, n) on the workers and waits; worker in [0, size())
  // names the thread, so callers index per-thread workspaces (one mjData per worker).
  // Allocates nothing (no std::function, no futures): for planners' per-iteration paths.
  // Calls from several threads are serialised. The first exception of a body is rethrown
  // here after every index has run.
  template <typename Body>
  void parallelForWorkers(std::size_t n, Body&& body) {
    using B = std::remove_reference_t<Body>;
    runBatch(n, [](void* ctx, std::size_t i, std::size_t w) { (*static_cast<B*>(ctx))(i, w); },
             const_cast<void*>(static_cast<const void*>(&body)));
  }

 private:
  using BatchFunction = void (*)(void* context, std::size_t index, std::size_t worker);
  void runBatch(std::size_t n, BatchFunction fn, void* context);
  void runBatchIndices(std::size_t worker);
  void enqueue(std::function<void()> job);
  void workerLoop(std::size_t worker);

  std::vector<std::thread> workers_;
  std::queue<std::function<void()>> jobs_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;

  // The current parallelForWorkers batch (guarded by mutex_ except the atomic counters).
  std::mutex batch_caller_;  // one batch at a time
  BatchFunction batch_fn_ = nullptr;
  void* batch_context_ = nullptr;
  std::size_t batch_size_ = 0;
  std::size_t batch_generation_ = 0;
  std::size_t batch_workers_inside_ = 0;
  std::atomic<std::size_t> batch_next_{0};
  std::atomic<std::size_t> batch_done_{0};
  std::exception_ptr batch_error_;
  std::condition_variable batch_finished_;
};

}  // namespace adroit
