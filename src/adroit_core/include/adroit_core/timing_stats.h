// Timing and sample statistics: min, median, p99, max over a recorded series.
#pragma once

#include <chrono>
#include <cstddef>
#include <string>
#include <vector>

namespace adroit {

struct Summary {
  std::size_t count = 0;
  double min = 0, mean = 0, median = 0, p99 = 0, max = 0;
};

// Collects samples (seconds, or any unit) and summarises them. Percentiles use the
// nearest-rank method on a sorted copy, so the series itself is left in arrival order.
class SampleStats {
 public:
  void add(double value) { samples_.push_back(value); }
  // Room for n samples: adding up to capacity() allocates nothing (a real-time loop
  // checks count() < capacity() before adding).
  void reserve(std::size_t n) { samples_.reserve(n); }
  std::size_t capacity() const { return samples_.capacity(); }
  void clear() { samples_.clear(); }  // keeps the capacity
  std::size_t count() const { return samples_.size(); }
  const std::vector<double>& samples() const { return samples_; }
  Summary summary() const;

 private:
  std::vector<double> samples_;
};

// p in [0, 100]; nearest-rank percentile of an unsorted series. Empty series -> 0.
double percentile(std::vector<double> values, double p);

// Monotonic stopwatch in seconds.
class Stopwatch {
 public:
  Stopwatch() : start_(Clock::now()) {}
  void restart() { start_ = Clock::now(); }
  double elapsed() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_;
};

// "min 1.2 / median 1.5 / p99 3.0 / max 4.1 <unit>" with values multiplied by `scale`.
std::string formatSummary(const Summary& s, double scale, const std::string& unit);

// A benchmark's RESULT line (DESIGN.md section 5):
//   "RESULT <scope>/<name> <value> <unit> target <op> <target> PASS|FAIL", op one of <=, <, >=, >.
// An unknown op never passes.
std::string resultLine(const std::string& scope, const std::string& name, double value, const std::string& unit,
                       const std::string& op, double target);

}  // namespace adroit
