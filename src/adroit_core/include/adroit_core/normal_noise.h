// Seeded standard normal samples for simulated sensor noise. The simulator draws a few
// hundred per 2 ms step, where std::normal_distribution over std::mt19937_64 (a logarithm
// and a square root per pair, plus rejections) was a visible share of the step.
// Bits: xoshiro256** (Blackman and Vigna), seeded through splitmix64. Normals: the ziggurat
// method (Marsaglia and Tsang 2000) with 256 layers, with the abscissa and the layer taken
// from disjoint bits of one draw (Doornik 2005). Copyable: a copy continues the same stream,
// so saving and restoring a simulation state replays the same noise.
#pragma once

#include <array>
#include <cstdint>

namespace adroit {

class NormalNoise {
 public:
  explicit NormalNoise(std::uint64_t seed = 0);

  // One sample of N(0, 1).
  double operator()();
  // 64 uniform random bits.
  std::uint64_t bits();
  // Uniform in [0, 1), 53 bits.
  double uniform() { return static_cast<double>(bits() >> 11) * 0x1.0p-53; }

 private:
  double tail(bool negative);
  std::array<std::uint64_t, 4> state_;
};

}  // namespace adroit
