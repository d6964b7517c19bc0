// Pneumatic plant model: the "truth" used by the simulation driver and the tests.
// ROS-free. Thin-plate ports with valve areas as Gompertz functions of the command,
// a leak orifice, chamber pressure dynamics with volume and volume rate (eq. 4.11, 5.3),
// a tube transport delay on the valve command and a shared supply that sags with flow.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "adroit_pneumatics/flow.h"

namespace adroit::pneumatics {

// One single-acting cylinder (front chamber driven, rear chamber open) with its valve.
struct CylinderSpec {
  std::string type;            // catalogue name ("M9", "M16", "M24", "M40")
  double bore_diameter = 0;    // m
  double bore_area = 0;        // m^2
  double stroke = 0;           // m
  double dead_volume = 0;      // m^3, chamber volume at zero travel (tubes, end caps)
  double leak_area = 0;        // m^2, equivalent orifice of the air seal (0 = leak-free)
  ValveParams valve;           // port areas vs command
  double swept_volume() const { return bore_area * stroke; }
};

// Catalogue: "M9" (AIRPEL M9D37.5, fingers), "M16" (AIRPEL M16, wrist), "M24" (arm),
// "M40" (arm shoulder/elbow, 40 mm bore, 100 mm stroke).
// Unknown type -> std::invalid_argument naming it. The values are adroit_description's
// catalogue (config/cylinders.yaml, compiled in as adroit_description/cylinder_catalogue.h);
// their sources are in that file (table 4.3, section 4.5, 3.5.1); M24 and M40 values are
// documented assumptions.
CylinderSpec cylinderSpec(const std::string& type);

// Shared supply (section 4.3.6): a first-order lag towards
//   nominal - sag_per_mass_flow * (total inlet mass flow)
// or towards atmosphere when the supply is disabled (e-stop exhausts the supply).
struct SupplyParams {
  double nominal_pressure = 620e3;                       // Pa absolute (fig. 5.9)
  double atmospheric_pressure = constants::kAtmosphere;  // Pa absolute
  double sag_per_mass_flow = 5e6;                        // Pa per (kg/s) of total inflow
  double time_constant = 0.05;                           // s
};

// See PlantOptions::transient_threshold: 1 % of the working range; with 10 kPa the worst
// 2 ms step error over the catalogue's cylinders near dead volume was 2.1 % of it.
constexpr double kTransientThreshold = 5e3;

struct PlantOptions {
  double tube_delay = 2e-3;     // s, valve -> chamber transport delay (fig. 3.8: T3 - T2)
  double area_spread = 0.08;    // relative std of each valve's port-area scale
  double offset_spread = 0.05;  // V, std of each valve's zero shift
  double initial_volts = 0.0;   // command assumed before the first step
  double initial_pressure = constants::kAtmosphere;
  // Pa: a step of a fast chamber (|slope| dt > 0.25) that moves its pressure further than
  // this is recomputed by transientStep (fills and exhausts near dead volume); infinity keeps
  // the two-stage integrator everywhere (the benchmark's cost baseline).
  double transient_threshold = kTransientThreshold;
};

// Full dynamic state, enough to save and restore the plant exactly.
struct PlantState {
  double time = 0;
  double supply_pressure = 0;
  bool supply_enabled = true;
  std::vector<double> pressure;       // Pa absolute, per cylinder
  std::vector<double> history_time;   // delay-line frames (command time), oldest first
  std::vector<double> history_volts;  // frames x cylinders, row-major
};

// Inputs of one chamber, held constant over an integration step.
struct ChamberInputs {
  double inlet_area = 0;    // m^2, supply port
  double outlet_area = 0;   // m^2, exhaust port + leak (both open to the room)
  double volume = 0;        // m^3
  double volume_rate = 0;   // m^3/s
  double supply = 0;        // Pa
  double room = constants::kAtmosphere;  // Pa
};

// dp/dt of eq. 4.7/5.3 with the leak of eq. 4.11, using the exact (std::pow) flow function.
double chamberPressureRate(double p, const ChamberInputs& in);

// Advances one chamber by dt with a two-stage exponential integrator: an exponential-Euler
// predictor on the local linearisation, then a corrector that uses the secant slope
// between start and predicted pressure (second order when smooth; in the stiff limit it
// lands on the quasi-static equilibrium instead of oscillating around it).
// Stable for any dt. inlet_mass_flow (optional) receives the supply-port flow at the start.
// A fast step that moves the pressure further than transient_threshold is redone by
// transientStep (the plant does the same; see PlantOptions).
double chamberStep(double p, double dt, const ChamberInputs& in, double* inlet_mass_flow = nullptr,
                   double transient_threshold = kTransientThreshold);

// One step of a fast transient, nearly exact for any dt. With the inputs constant over the
// step, dp/dt = f(p) is autonomous and f falls monotonically through the equilibrium p*, so
// the time to get from p0 to p is the integral of dp / f. This takes f linear on segments
// between p0 and p* (fine at both ends: the flow function's square-root edges at supply and
// room pressure, and the exponential approach to p*), sums the exact times per segment and
// inverts the one in which dt ends; past the last point it approaches p* exponentially.
// About 20 evaluations of f: for the few steps in which a chamber near its dead volume fills
// or empties, where the two-stage step lags the true approach along the square-root edge by
// up to a quarter of the working range. Returns NaN when f has no equilibrium in the
// direction of travel (a chamber compressed faster than it can vent).
double transientStep(double p, double dt, const ChamberInputs& in);

class PneumaticPlant {
 public:
  // seed drives the valve-to-valve spread: each cylinder's valve areas are scaled and
  // shifted by a random amount so no two cylinders are identical (area_spread = 0 and
  // offset_spread = 0 give the catalogue valves exactly).
  PneumaticPlant(std::vector<CylinderSpec> specs, const SupplyParams& supply = {},
                 std::uint64_t seed = 1, const PlantOptions& options = {});

  std::size_t size() const { return specs_.size(); }

  // volts[i] in [-5, 5] (clamped; non-finite -> 0 V); travel[i] piston travel in m
  // (clamped to [0, stroke]); travel_rate[i] in m/s. Any pointer may be null: volts null
  // keeps the last command, travel null means 0, travel_rate null means 0.
  void step(double dt, const double* volts, const double* travel, const double* travel_rate);

  const std::vector<double>& pressure() const { return pressure_; }  // Pa absolute, true
  double supplyPressure() const { return supply_pressure_; }
  double atmosphericPressure() const { return supply_params_.atmospheric_pressure; }
  double time() const { return time_; }
  // Tendon tension max(0, (p - p_atm) * bore_area), N.
  double tension(std::size_t i) const;
  // Command currently acting at valve i (after the tube delay).
  double appliedVolts(std::size_t i) const { return applied_volts_[i]; }

  void setSupplyEnabled(bool enabled) { supply_enabled_ = enabled; }
  bool supplyEnabled() const { return supply_enabled_; }

  PlantState state() const;
  // Throws std::invalid_argument if the state does not match this plant's size.
  void setState(const PlantState& state);

  // Spec of cylinder i with its individual (spread) valve.
  const CylinderSpec& spec(std::size_t i) const { return specs_[i]; }
  const SupplyParams& supplyParams() const { return supply_params_; }
  const PlantOptions& options() const { return options_; }

 private:
  void updateAreas(std::size_t i, double volts) {
    if (volts == applied_volts_[i]) return;  // areas depend only on the command
    applied_volts_[i] = volts;
    inlet_area_[i] = fast_inlet_[i](volts);
    outlet_area_[i] = fast_exhaust_[i](volts) + specs_[i].leak_area;
  }

  // One port in the tabulated form area = offset + a H_b(c u + c d).
  struct FastPort {
    double offset = 0, a = 0, c = 0, cd = 0;
    const GompertzTable* table = nullptr;
    double operator()(double volts) const { return offset + a * (*table)(c * volts + cd); }
  };

  std::vector<CylinderSpec> specs_;
  SupplyParams supply_params_;
  PlantOptions options_;
  double time_ = 0;
  double supply_pressure_ = 0;
  bool supply_enabled_ = true;
  std::vector<double> pressure_;
  // Delay line of commands: frames pushed at each step's start time.
  std::vector<double> history_time_;
  std::vector<double> history_volts_;
  // Derived caches (not state): command acting now and its port areas.
  std::vector<double> applied_volts_, inlet_area_, outlet_area_;
  std::vector<double> last_volts_;
  std::vector<FastPort> fast_inlet_, fast_exhaust_;
  // Scratch of the batched integrator (not state).
  struct Work {
    std::vector<ChamberInputs> in;
    std::vector<double> gain, volume_term, f0, j0, q0, p1, f1, p2, f2, z;
    std::vector<std::size_t> stiff;
    void resize(std::size_t n);
  };
  Work work_;
};

}  // namespace adroit::pneumatics
