#include "adroit_core/normal_noise.h"

#include <cmath>

namespace adroit {

namespace {

constexpr int kLayers = 256;
// Right edge of the base layer for 256 layers of equal area under exp(-x^2 / 2)
// (Marsaglia and Tsang 2000); the layer area follows from it.
constexpr double kTailStart = 3.6541528853610088;

double density(double x) { return std::exp(-0.5 * x * x); }

// edge[i]: half-width of layer i (edge[0] is the base layer's width including its tail,
// edge[kLayers] = 0 the peak); height[i] = density(edge[i]). Layer i >= 1 spans heights
// [height[i], height[i + 1]] and |x| < edge[i]; every layer has the same area.
struct Ziggurat {
  std::array<double, kLayers + 1> edge, height;
  Ziggurat() {
    const double r = kTailStart;
    const double area = r * density(r) + std::sqrt(M_PI / 2) * std::erfc(r / std::sqrt(2.0));
    edge[0] = area / density(r);
    edge[1] = r;
    for (int i = 1; i < kLayers - 1; ++i) edge[i + 1] = std::sqrt(-2.0 * std::log(density(edge[i]) + area / edge[i]));
    edge[kLayers] = 0.0;
    for (int i = 0; i <= kLayers; ++i) height[i] = density(edge[i]);
  }
};

const Ziggurat& ziggurat() {
  static const Ziggurat table;
  return table;
}

std::uint64_t splitmix64(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

inline std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

}  // namespace

NormalNoise::NormalNoise(std::uint64_t seed) {
  for (auto& word : state_) word = splitmix64(seed);  // never all zero
  ziggurat();  // build the table now, not inside a timed loop
}

std::uint64_t NormalNoise::bits() {
  const std::uint64_t result = rotl(state_[1] * 5, 7) * 9;
  const std::uint64_t t = state_[1] << 17;
  state_[2] ^= state_[0];
  state_[3] ^= state_[1];
  state_[1] ^= state_[2];
  state_[0] ^= state_[3];
  state_[2] ^= t;
  state_[3] = rotl(state_[3], 45);
  return result;
}

double NormalNoise::operator()() {
  const Ziggurat& z = ziggurat();
  for (;;) {
    const std::uint64_t b = bits();
    const int layer = static_cast<int>(b & (kLayers - 1));            // bits 0-7
    const double u = (static_cast<double>(b >> 11) + 0.5) * 0x1.0p-52 - 1.0;  // bits 11-63, in (-1, 1)
    const double x = u * z.edge[layer];
    if (std::abs(x) < z.edge[layer + 1]) return x;  // inside the layer's rectangle core (~99 %)
    if (layer == 0) return tail(u < 0);
    // In the wedge between the rectangle core and the layer's edge: accept under the curve.
    const double y = z.height[layer] + uniform() * (z.height[layer + 1] - z.height[layer]);
    if (y < density(x)) return x;
  }
}

// Beyond the base layer's edge r: Marsaglia's (1964) exact tail method.
double NormalNoise::tail(bool negative) {
  double a, b;
  do {
    a = -std::log(1.0 - uniform()) / kTailStart;  // 1 - uniform() is in (0, 1]
    b = -std::log(1.0 - uniform());
  } while (b + b < a * a);
  return negative ? -(kTailStart + a) : kTailStart + a;
}

}  // namespace adroit
