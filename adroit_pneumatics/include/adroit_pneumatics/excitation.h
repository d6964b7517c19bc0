// Valve-command excitation signals for identification (thesis 5.2.2, 5.4): steps from
// either extreme, a slow sweep, low-passed random commands and a chirp. Deterministic
// from a seed; evaluated sample by sample at a fixed period.
#pragma once

#include <cstdint>
#include <random>
#include <string>

namespace adroit::pneumatics {

struct ExcitationParams {
  std::string kind = "random";  // steps | sweep | random | chirp
  double amplitude = 3.0;       // V, commands stay in [-amplitude, amplitude]
  double step_hold = 0.25;      // s per step level (steps)
  double sweep_period = 20.0;   // s for one -A -> +A -> -A cycle (sweep)
  double cutoff_hz = 30.0;      // low-pass of the random commands (below the valve's 125 Hz)
  double random_hold = 0.02;    // s between new random targets
  double chirp_f0 = 0.5, chirp_f1 = 25.0, chirp_duration = 20.0;  // Hz, Hz, s
  std::uint64_t seed = 1;
  void validate() const;        // throws std::invalid_argument naming the field
};

class Excitation {
 public:
  explicit Excitation(const ExcitationParams& params);
  // Command for the sample at time t (call with increasing t, fixed period dt).
  double next(double t, double dt);

 private:
  ExcitationParams params_;
  std::mt19937_64 rng_;
  std::uniform_real_distribution<double> uniform_{-1.0, 1.0};
  double target_ = 0, filtered_ = 0, filtered2_ = 0, next_change_ = 0;
  int step_index_ = 0;
};

}  // namespace adroit::pneumatics
