#include "adroit_pneumatics/sensor_model.h"

#include <cmath>
#include <stdexcept>

namespace adroit::pneumatics {

namespace {
constexpr double kTwoPi = 6.283185307179586;
}

SensorModel::SensorModel(std::size_t cylinders, const SensorParams& params, std::uint64_t seed)
    : params_(params), noise_(seed), pressure_(cylinders, 0.0), length_(cylinders, 0.0) {
  if (!(params.pressure_noise_std >= 0) || !(params.length_noise_std >= 0) || !(params.pressure_quantum >= 0) ||
      !(params.length_quantum >= 0) || !(params.pressure_cutoff_hz > 0) || !(params.length_cutoff_hz > 0))
    throw std::invalid_argument("SensorModel: noise and quantum must be >= 0, cutoffs > 0");
}

double SensorModel::measure(double value, double noise_std, double quantum) {
  double v = value + (noise_std > 0 ? noise_std * noise_() : 0.0);
  if (quantum > 0) v = quantum * std::round(v / quantum);
  return v;
}

void SensorModel::update(double dt, const std::vector<double>& true_pressure, const std::vector<double>& true_length) {
  const std::size_t n = pressure_.size();
  if (true_pressure.size() != n || true_length.size() != n)
    throw std::invalid_argument("SensorModel::update: expected " + std::to_string(n) + " cylinders");
  const double kp = initialised_ ? -std::expm1(-dt * kTwoPi * params_.pressure_cutoff_hz) : 1.0;
  const double kl = initialised_ ? -std::expm1(-dt * kTwoPi * params_.length_cutoff_hz) : 1.0;
  for (std::size_t i = 0; i < n; ++i) {
    pressure_[i] += kp * (measure(true_pressure[i], params_.pressure_noise_std, params_.pressure_quantum) - pressure_[i]);
    length_[i] += kl * (measure(true_length[i], params_.length_noise_std, params_.length_quantum) - length_[i]);
  }
  initialised_ = true;
}

}  // namespace adroit::pneumatics
