#include "adroit_core/slowdown_probe.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <vector>

#include "adroit_core/scheduling.h"

namespace adroit {
namespace {

double work() {  // ~50 us of dependent arithmetic at full speed on the VMs here
  volatile double x = 1.0;
  for (int i = 0; i < 12000; ++i) x = x * 1.0000001 + 1e-9;
  return x;
}

}  // namespace

SlowdownProbe::SlowdownProbe(int priority, double period) : thread_([this, priority, period] { run(priority, period); }) {}

void SlowdownProbe::stop() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
}

void SlowdownProbe::run(int priority, double period) {
  if (!enterFifo(priority, &refusal_)) return;
  double fastest = std::numeric_limits<double>::infinity();
  std::vector<double> times;
  times.reserve(static_cast<std::size_t>(600.0 / period));  // ten minutes without allocating
  const auto step = std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(period));
  auto next = std::chrono::steady_clock::now();
  while (running_.load()) {
    Stopwatch sw;
    work();
    const double t = sw.elapsed();
    fastest = std::min(fastest, t);
    if (times.size() < times.capacity()) times.push_back(t);
    next += step;
    std::this_thread::sleep_until(next);
    const double late = std::chrono::duration<double>(std::chrono::steady_clock::now() - next).count();
    longest_stall_ = std::max(longest_stall_, late);
  }
  for (double t : times) slowdowns_.add(t / fastest);
}

double fractionAbove(const SampleStats& samples, double factor) {
  const auto& s = samples.samples();
  if (s.empty()) return 0.0;
  return static_cast<double>(std::count_if(s.begin(), s.end(), [factor](double x) { return x > factor; })) /
         static_cast<double>(s.size());
}

}  // namespace adroit
