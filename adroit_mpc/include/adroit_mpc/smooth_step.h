// Smooth step functions that switch cost terms on and off over time (thesis 6.5, typing):
//   S_up(t) = 0.5 ((t - a1) / sqrt((t - a1)^2 + b1^2) - (t - a2) / sqrt((t - a2)^2 + b2^2))
//   S_dn(t) = 1 - S_up(t)
// S_up rises around a1 and falls around a2 (a pulse that is ~1 between them); b1, b2 set how
// sharp each edge is (seconds).
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

namespace adroit_mpc {

struct SmoothStep {
  double a1 = 0, b1 = 0.01, a2 = 1, b2 = 0.01;

  // Throws std::invalid_argument when an edge width is not positive or a value is not finite
  // (b = 0 would divide by zero at the step location).
  void validate() const {
    if (!std::isfinite(a1) || !std::isfinite(a2) || !std::isfinite(b1) || !std::isfinite(b2))
      throw std::invalid_argument("smooth step: a1, a2, b1, b2 must be finite");
    if (b1 <= 0 || b2 <= 0)
      throw std::invalid_argument("smooth step: the smoothness b1, b2 must be > 0 (got " + std::to_string(b1) +
                                  ", " + std::to_string(b2) + ")");
  }
  double up(double t) const {
    const double e1 = t - a1, e2 = t - a2;
    return 0.5 * (e1 / std::sqrt(e1 * e1 + b1 * b1) - e2 / std::sqrt(e2 * e2 + b2 * b2));
  }
  double down(double t) const { return 1.0 - up(t); }
};

}  // namespace adroit_mpc
