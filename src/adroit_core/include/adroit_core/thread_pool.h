// A fixed-size pool of worker threads for planners, rollouts and fitting.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <functional>
#include <future>
#include <mutex>
#include <queue>
#include <thread>
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

 private:
  void enqueue(std::function<void()> job);
  void workerLoop();

  std::vector<std::thread> workers_;
  std::queue<std::function<void()>> jobs_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
};

}  // namespace adroit
