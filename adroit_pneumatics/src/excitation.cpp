#include "adroit_pneumatics/excitation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace adroit::pneumatics {

namespace {
constexpr double kTwoPi = 6.283185307179586;
}

void ExcitationParams::validate() const {
  if (kind != "steps" && kind != "sweep" && kind != "random" && kind != "chirp")
    throw std::invalid_argument("excitation: kind must be steps|sweep|random|chirp, got '" + kind + "'");
  if (!(amplitude > 0 && amplitude <= 5)) throw std::invalid_argument("excitation: amplitude must be in (0, 5]");
  if (!(step_hold > 0)) throw std::invalid_argument("excitation: step_hold must be > 0");
  if (!(sweep_period > 0)) throw std::invalid_argument("excitation: sweep_period must be > 0");
  if (!(cutoff_hz > 0)) throw std::invalid_argument("excitation: cutoff_hz must be > 0");
  if (!(random_hold > 0)) throw std::invalid_argument("excitation: random_hold must be > 0");
  if (!(chirp_f0 > 0 && chirp_f1 > chirp_f0 && chirp_duration > 0))
    throw std::invalid_argument("excitation: need 0 < chirp_f0 < chirp_f1 and chirp_duration > 0");
}

Excitation::Excitation(const ExcitationParams& params) : params_(params), rng_(params.seed) { params_.validate(); }

double Excitation::next(double t, double dt) {
  const double A = params_.amplitude;
  if (params_.kind == "steps") {
    // Alternate: from -A to a level, from +A to a level (5.2.2), levels sweeping the range.
    const int k = static_cast<int>(std::floor(t / params_.step_hold));
    const int pair = k / 2;
    const double level = -A + 2.0 * A * std::fmod(pair * 0.618033988749895, 1.0);
    const bool from_high = (pair % 2) == 1;
    return (k % 2 == 0) ? (from_high ? A : -A) : level;
  }
  if (params_.kind == "sweep") {
    const double phase = std::fmod(t / params_.sweep_period, 1.0);
    return phase < 0.5 ? -A + 4.0 * A * phase : 3.0 * A - 4.0 * A * phase;
  }
  if (params_.kind == "chirp") {
    // Linear chirp, repeated.
    const double tc = std::fmod(t, params_.chirp_duration);
    const double rate = (params_.chirp_f1 - params_.chirp_f0) / params_.chirp_duration;
    return A * std::sin(kTwoPi * (params_.chirp_f0 * tc + 0.5 * rate * tc * tc));
  }
  // Random: uniform targets held for random_hold, through a 2nd-order low-pass at cutoff.
  if (t >= next_change_) {
    target_ = A * uniform_(rng_);
    next_change_ = t + params_.random_hold;
  }
  const double blend = -std::expm1(-dt * kTwoPi * params_.cutoff_hz);
  filtered_ += blend * (target_ - filtered_);
  filtered2_ += blend * (filtered_ - filtered2_);
  return std::clamp(filtered2_, -A, A);
}

}  // namespace adroit::pneumatics
