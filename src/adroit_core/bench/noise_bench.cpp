// Cost of one N(0, 1) sample: adroit::NormalNoise against the baseline it replaced,
// std::normal_distribution over std::mt19937_64, measured in the same run.
#include <algorithm>
#include <cstdio>
#include <random>

#include "adroit_core/normal_noise.h"
#include "adroit_core/timing_stats.h"

namespace {

template <typename Draw>
double nanosecondsPerSample(Draw draw, long n) {
  [[maybe_unused]] volatile double sink = 0;  // keeps the draws from being optimised away
  double best = 1e9;
  for (int run = 0; run < 5; ++run) {
    adroit::Stopwatch watch;
    for (long i = 0; i < n; ++i) sink = draw();
    best = std::min(best, watch.elapsed() / n * 1e9);
  }
  return best;
}

}  // namespace

int main() {
  const long n = 5000000;
  adroit::NormalNoise noise(1);
  std::mt19937_64 mt(1);
  std::normal_distribution<double> normal(0.0, 1.0);
  const double fast = nanosecondsPerSample([&] { return noise(); }, n);
  const double baseline = nanosecondsPerSample([&] { return normal(mt); }, n);
  std::printf("one N(0,1) sample, best of 5 x %ld:\n", n);
  std::printf("  std::normal_distribution + std::mt19937_64 (baseline)  %6.2f ns\n", baseline);
  std::printf("  adroit::NormalNoise (xoshiro256** + ziggurat)          %6.2f ns\n", fast);
  std::printf("RESULT adroit_core/normal_noise_speedup %.3g x target >= 2 %s\n", baseline / fast,
              baseline / fast >= 2 ? "PASS" : "FAIL");
}
