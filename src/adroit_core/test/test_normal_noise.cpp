#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "adroit_core/normal_noise.h"

using adroit::NormalNoise;

namespace {

double normalCdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

std::vector<double> draw(NormalNoise& noise, std::size_t n) {
  std::vector<double> v(n);
  for (double& x : v) x = noise();
  return v;
}

}  // namespace

TEST(NormalNoise, SameSeedSameStreamAndCopiesContinueIt) {
  NormalNoise a(42), b(42), c(43);
  EXPECT_EQ(draw(a, 100), draw(b, 100));
  NormalNoise copy = a;
  EXPECT_EQ(draw(a, 1000), draw(copy, 1000));
  EXPECT_NE(draw(b, 100), draw(c, 100));
}

TEST(NormalNoise, MomentsAreThoseOfTheStandardNormal) {
  NormalNoise noise(7);
  const std::size_t n = 2000000;
  double m1 = 0, m2 = 0, m3 = 0, m4 = 0;
  for (double x : draw(noise, n)) {
    const double x2 = x * x;
    m1 += x, m2 += x2, m3 += x2 * x, m4 += x2 * x2;
  }
  m1 /= n, m2 /= n, m3 /= n, m4 /= n;
  // Standard errors at n = 2e6: mean 7e-4, variance 1e-3, third moment 1.7e-3, fourth 7e-3.
  EXPECT_NEAR(m1, 0.0, 0.004);
  EXPECT_NEAR(m2, 1.0, 0.005);
  EXPECT_NEAR(m3, 0.0, 0.01);
  EXPECT_NEAR(m4, 3.0, 0.04);
}

TEST(NormalNoise, DistributionMatchesTheNormalCdf) {
  NormalNoise noise(11);
  const std::size_t n = 1000000;
  std::vector<double> v = draw(noise, n);
  std::sort(v.begin(), v.end());
  double ks = 0;  // Kolmogorov-Smirnov distance
  for (std::size_t i = 0; i < n; ++i) {
    const double f = normalCdf(v[i]);
    ks = std::max({ks, std::abs(f - double(i) / n), std::abs(f - double(i + 1) / n)});
  }
  EXPECT_LT(ks, 1.63 / std::sqrt(double(n)));  // 1 % critical value
}

TEST(NormalNoise, TailsBeyondTheBaseLayerHaveTheNormalMass) {
  // Beyond 3.654 the samples come from the separate tail method: its mass and its shape
  // (the share beyond 4.2 of what lies beyond 3.654) must be those of the normal law.
  NormalNoise noise(5);
  const std::size_t n = 20000000;
  std::size_t beyond_r = 0, beyond_far = 0, negative = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = noise();
    if (std::abs(x) > 3.6541528853610088) {
      ++beyond_r;
      if (x < 0) ++negative;
      if (std::abs(x) > 4.2) ++beyond_far;
    }
  }
  const double p_r = 2 * (1 - normalCdf(3.6541528853610088)), p_far = 2 * (1 - normalCdf(4.2));
  const double expect_r = p_r * n, expect_far = p_far * n;  // ~5160 and ~534
  EXPECT_NEAR(double(beyond_r), expect_r, 5 * std::sqrt(expect_r));
  EXPECT_NEAR(double(beyond_far), expect_far, 5 * std::sqrt(expect_far));
  EXPECT_NEAR(double(negative), 0.5 * beyond_r, 5 * 0.5 * std::sqrt(double(beyond_r)));
}

TEST(NormalNoise, UniformBitsAreBalanced) {
  NormalNoise noise(3);
  const int n = 200000;
  std::vector<int> ones(64, 0);
  for (int i = 0; i < n; ++i) {
    const std::uint64_t b = noise.bits();
    for (int k = 0; k < 64; ++k) ones[k] += (b >> k) & 1;
  }
  for (int k = 0; k < 64; ++k) EXPECT_NEAR(ones[k], n / 2, 5 * std::sqrt(n / 4.0)) << "bit " << k;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double u = noise.uniform();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    sum += u;
  }
  EXPECT_NEAR(sum / n, 0.5, 5 * std::sqrt(1.0 / 12 / n));
}
