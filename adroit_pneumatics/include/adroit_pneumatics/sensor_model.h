// Pressure and length sensor model (table 3.1): additive noise, quantisation and a
// first-order low-pass filter, applied at the driver's step. ROS-free; copyable, so the
// driver saves and restores it (including the random generator) by value.
#pragma once

#include <cstdint>
#include <vector>

#include "adroit_core/normal_noise.h"

namespace adroit::pneumatics {

struct SensorParams {
  // SMC PSE540: 0-1 MPa, repeatability +-0.2 % of full scale -> 2 kPa noise per raw sample.
  double pressure_noise_std = 2000.0;     // Pa
  double pressure_quantum = 1e6 / 65536;  // Pa, 16-bit DAQ over the 1 MPa range
  double pressure_cutoff_hz = 500.0;      // low-pass of the 32 kHz stream
  // SICK MPS: resolution 0.05 mm, repeatability 0.1 mm.
  double length_noise_std = 1e-4;         // m
  double length_quantum = 5e-5;           // m
  double length_cutoff_hz = 100.0;
};

class SensorModel {
 public:
  SensorModel(std::size_t cylinders, const SensorParams& params = {}, std::uint64_t seed = 7);

  // Filters one sample per cylinder; results in pressure()/length(). The first call
  // initialises the filters to the (noisy) sample so there is no start-up transient.
  void update(double dt, const std::vector<double>& true_pressure, const std::vector<double>& true_length);

  const std::vector<double>& pressure() const { return pressure_; }
  const std::vector<double>& length() const { return length_; }
  const SensorParams& params() const { return params_; }

 private:
  double measure(double value, double noise_std, double quantum);
  SensorParams params_;
  NormalNoise noise_;
  bool initialised_ = false;
  std::vector<double> pressure_, length_;
};

}  // namespace adroit::pneumatics
