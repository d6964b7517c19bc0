// Thin-port identification (thesis eq. 4.12, 5.4.1): the Gompertz inlet and exhaust port
// areas of a valve (eq. 4.13), the dead volume v_0 and the leak orifice a_l of a cylinder,
// fitted to recorded steps / sweeps by minimising the error between the measured pressure
// rate and the thin-plate model's
//   min  sum_k ( pdot_measured - kappa R T / (v_k + v_0) (a_c(u) phi(P_c, p) - (a_r(u) + a_l) phi(p, P_r)) )^2
// The measured rate is the finite difference (p_{k+1} - p_k) / dt and the model's rate the
// exact average over the same sample (chamberStep from p_k), which avoids differentiating the
// pressure. Exhaust offset and leak both add to the outlet area at every command, so they
// cannot be told apart on one cylinder: as in the thesis, the valve (and v_0) comes from a
// low-leak cylinder, then a_l (and v_0) from the leaky cylinder with that valve.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/sysid.h"

namespace adroit::pneumatics {

struct ThinPortParams {
  ValveParams valve;
  double dead_volume = 1e-7;  // m^3
  double leak_area = 0.0;     // m^2
};

struct ThinPortFitOptions {
  bool fit_valve = true;         // offset, a, b, c of both ports (d held, see gompertzCentre)
  bool fit_dead_volume = true;
  bool fit_leak = false;
  int max_iterations = 100;
};

struct ThinPortFitReport {
  ThinPortParams params;
  double rate_rmse = 0;  // Pa/s, over all samples
  int iterations = 0;
};

// recordings: the `volume` column is the swept volume bore_area * travel from the length
// sensor (the dead volume is what gets identified), volume_rate its rate, supply the
// measured supply; volts[k] acts over sample k. Throws std::invalid_argument on an empty
// set or a bad recording.
ThinPortFitReport fitThinPort(const std::vector<Recording>& recordings, const ThinPortParams& initial,
                              const ThinPortFitOptions& options = {});

// b and d of eq. 4.13 are not separately identifiable (b exp(-c (u + d)) depends on them
// only through b e^{-c d}); the fit holds d at its starting value. The identifiable centre
// of the curve, the command where the opening is a / e: u_c = ln(b) / c - d.
double gompertzCentre(const GompertzArea& g);

// Rate RMSE (Pa/s) of given parameters on recordings (same convention).
double thinPortRateRmse(const std::vector<Recording>& recordings, const ThinPortParams& params);

// Identification data from the plant model: one cylinder locked at `travel`, driven by the
// excitation `kind` (excitation.h), sub-stepped at 0.125 ms and recorded at 0.5 ms, noise-free,
// without tube delay or valve spread. The volume column holds the swept volume only (the
// dead volume is what the fit identifies).
Recording recordLockedCylinder(const CylinderSpec& spec, double travel, const std::string& kind, double seconds,
                               std::uint64_t seed);

}  // namespace adroit::pneumatics
