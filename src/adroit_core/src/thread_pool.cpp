#include "adroit_core/thread_pool.h"

#include <atomic>
#include <exception>

namespace adroit {

ThreadPool::ThreadPool(std::size_t threads) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  workers_.reserve(threads);
  for (std::size_t i = 0; i < threads; ++i) workers_.emplace_back([this, i] { workerLoop(i); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (auto& w : workers_) w.join();
}

void ThreadPool::enqueue(std::function<void()> job) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    jobs_.push(std::move(job));
  }
  wake_.notify_one();
}

void ThreadPool::workerLoop(std::size_t worker) {
  std::size_t seen_generation = 0;
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] {
        return stopping_ || !jobs_.empty() || (batch_fn_ && batch_generation_ != seen_generation);
      });
      if (batch_fn_ && batch_generation_ != seen_generation) {
        seen_generation = batch_generation_;
        ++batch_workers_inside_;
        lock.unlock();
        runBatchIndices(worker);
        lock.lock();
        if (--batch_workers_inside_ == 0) batch_finished_.notify_all();
        continue;
      }
      if (jobs_.empty()) return;  // stopping and drained
      job = std::move(jobs_.front());
      jobs_.pop();
    }
    job();
  }
}

void ThreadPool::runBatchIndices(std::size_t worker) {
  for (std::size_t i = batch_next_++; i < batch_size_; i = batch_next_++) {
    try {
      batch_fn_(batch_context_, i, worker);
    } catch (...) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!batch_error_) batch_error_ = std::current_exception();
    }
    batch_done_++;
  }
}

void ThreadPool::runBatch(std::size_t n, BatchFunction fn, void* context) {
  if (n == 0) return;
  std::lock_guard<std::mutex> serial(batch_caller_);
  std::exception_ptr error;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    batch_fn_ = fn;
    batch_context_ = context;
    batch_size_ = n;
    batch_next_ = 0;
    batch_done_ = 0;
    batch_error_ = nullptr;
    ++batch_generation_;
    wake_.notify_all();
    // Done when every index ran and no worker still reads the batch (context lives on the
    // caller's stack). A worker busy with a submit() job may join late and find nothing left.
    batch_finished_.wait(lock, [&] { return batch_done_ == n && batch_workers_inside_ == 0; });
    batch_fn_ = nullptr;
    batch_context_ = nullptr;
    error = batch_error_;
    batch_error_ = nullptr;
  }
  if (error) std::rethrow_exception(error);
}

void ThreadPool::parallelFor(std::size_t n, const std::function<void(std::size_t)>& body) {
  if (n == 0) return;
  // Chunk the range so each worker takes indices from a shared counter: cheap balancing
  // when bodies have uneven cost (rollouts with different contact counts).
  std::atomic<std::size_t> next{0};
  std::exception_ptr first_error;
  std::mutex error_mutex;
  const std::size_t tasks = std::min(n, workers_.size());
  std::vector<std::future<void>> done;
  done.reserve(tasks);
  for (std::size_t t = 0; t < tasks; ++t) {
    done.push_back(submit([&] {
      for (std::size_t i = next++; i < n; i = next++) {
        try {
          body(i);
        } catch (...) {
          std::lock_guard<std::mutex> lock(error_mutex);
          if (!first_error) first_error = std::current_exception();
        }
      }
    }));
  }
  for (auto& f : done) f.get();
  if (first_error) std::rethrow_exception(first_error);
}

}  // namespace adroit
