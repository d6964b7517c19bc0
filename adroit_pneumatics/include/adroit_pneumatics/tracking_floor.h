// The tracking error no pressure controller can avoid: the best any controller within a
// command limit can do when it learns of the reference only as it happens, and an audit
// of a set of cylinders' force tracking against it.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/sensor_model.h"

namespace adroit::pneumatics {

// Follows a reference as closely as one chamber can: each step it moves towards the
// reference as far as the valve held at the command limit takes it and stops exactly on it
// (no sensing, tick or solver delay, no overshoot). The reference acts dead_time after it
// is given (the plant's own tube delay belongs to the floor). A real controller has all of
// those delays, so its error against the same reference is at least this follower's,
// unless it anticipates the reference (preview). Uses the plant's chamber step with the
// spec's valve and leak.
class TrackingFloor {
 public:
  // limit: the controller's command limit, V (> 0); dead_time in [0, 0.1] s.
  TrackingFloor(const CylinderSpec& spec, double limit, double dead_time = 0.0,
                double room = constants::kAtmosphere);
  // A controller that holds each command for a whole step (a pool's tick) instead of
  // stopping exactly: each step it picks the command within the limit that ends its window
  // (dead_time after the step's start, one step long; the dead time at most one step) on
  // the reference, or the limit. Its model of the chamber is exact.
  void setHoldCommandPerStep(bool hold) { hold_ = hold; }
  void reset(double pressure);
  // Advances dt with the reference p_ref (Pa) given now, the chamber volume (m^3), its rate
  // (m^3/s) and the supply pressure; returns the pressure at the end of the step.
  // Non-finite inputs leave it where it is. References older than 255 steps are forgotten
  // (dead time / step <= 255).
  double step(double p_ref, double dt, double volume, double volume_rate, double supply);
  double pressure() const { return pressure_; }

 private:
  // End pressure after h from p with the command u held.
  double advance(double p, double h, double u) const;
  double holdStep(double p_ref, double dt);

  CylinderSpec spec_;
  double limit_, dead_time_, time_ = 0;
  bool hold_ = false;
  double held_ = 0.0;                    // V, the command acting (hold mode)
  ChamberInputs fill_, vent_;            // geometry and supply of this step; ports at +limit, -limit
  std::vector<double> history_time_, history_ref_;  // ring buffer of the recent references
  std::size_t head_ = 0, count_ = 0;
  double pressure_;
};

// The group a cylinder's tracking is reported in: "wrist" (A_WR*), "arm" (A_AR*), else the
// finger of its name (A_FFJ2_flex -> "FF").
std::string trackingGroup(const std::string& cylinder);

// Force tracking of cylinders against their references, per group (e.g. per finger), next
// to two floors: TrackingFloor stopping exactly, and holding one command per sample (the
// ideal controller at the sampling rate, e.g. a pool's 200 Hz tick). The floors are causal:
// they learn of each sample's reference at that sample, as the robot's controller does, so
// a reference that jumps at a sample counts in full there and is met at the next sample at
// the earliest (and only if the chamber fills that fast).
class ForceTrackingAudit {
 public:
  struct Cylinder {
    std::string group;
    CylinderSpec spec;  // with the cylinder's own dead volume and bore
  };
  struct Group {
    double rmse = 0, floor = 0, per_tick = 0;  // N
    double max_reference = 0;                  // N
    long samples = 0;
  };
  // limit: the controller's command limit (V); dead_time (s): from a command to the measured
  // tension seeing it, the plant's tube delay plus the sensing delay of the tension compared.
  ForceTrackingAudit(std::vector<Cylinder> cylinders, double limit, double dead_time,
                     double room = constants::kAtmosphere);
  std::size_t size() const { return cylinders_.size(); }
  // The least tension the robot applies and reports (the simulation's slack-avoiding
  // ~min_tension; 0 for a sensor that reads what the pressure pulls): the floors' tensions
  // are at least this too, so a reference below it counts against both alike. >= 0.
  void setMinTension(double newtons);
  // The floors read through the sensor the measured tension comes from: their chamber
  // pressures pass the same noise, quantisation and low-pass (SensorModel at each sample)
  // before they become tensions, so the floors carry the sensor's error as the measurement
  // does (its delay is the dead time above). Without it the floors see the exact chamber.
  // Call before start(); `seed` starts the noise (the floors' noise is not the run's).
  void setSensor(const SensorParams& params, std::uint64_t seed = 11);
  // Starts the floors at these pressures (Pa) for a new run; the sums go on.
  void start(const std::vector<double>& pressure);
  // One sample dt after the previous one: per cylinder the reference and measured tension
  // (N), the chamber volume (m^3) and its rate; the supply pressure (Pa).
  void add(double dt, const std::vector<double>& reference, const std::vector<double>& tension,
           const std::vector<double>& volume, const std::vector<double>& volume_rate, double supply);
  std::map<std::string, Group> groups() const;
  // Tension (N) of each cylinder's per-tick floor after the last add(), for traces.
  const std::vector<double>& lastPerTickTension() const { return last_tick_tension_; }

 private:
  struct Sums {
    double error = 0, floor = 0, per_tick = 0, max_reference = 0;
    long samples = 0;
  };
  std::vector<Cylinder> cylinders_;
  double room_, min_tension_ = 0;
  std::vector<TrackingFloor> floors_, ticks_;
  std::vector<double> last_tick_tension_;
  std::vector<double> given_;  // Pa, each cylinder's reference at the previous sample (NaN: none yet)
  std::unique_ptr<SensorModel> floor_sensor_, tick_sensor_;  // null: the exact chambers
  std::vector<double> floor_pressure_, tick_pressure_, no_length_;
  std::map<std::string, Sums> sums_;
};

// How well a reference's preview predicts it: at each sample, the desired tension against
// what the reference that was newest `lead` seconds earlier said about that instant, RMSE
// per group for each lead. A controller's own response takes the floor's time above; a
// preview that misses by about the floor at that lead carries no better knowledge of the
// jumps than learning each value as it comes, which the floors assume.
class PreviewAudit {
 public:
  // groups: the group of each column; leads in s, each >= 0.
  PreviewAudit(std::vector<std::string> groups, std::vector<double> leads);
  // A reference given at time t: `steps` rows dt apart from t, one value per column (N),
  // row-major. Given in time order; a reference with the wrong size or dt <= 0 is ignored.
  void addReference(double t, double dt, std::size_t steps, const std::vector<double>& forces);
  // The desired tension of each column at time t (NaN columns are skipped), t not before
  // the previous sample's.
  void addSample(double t, const std::vector<double>& desired);
  const std::vector<double>& leads() const { return leads_; }
  // Per group, the preview's RMSE (N) for each lead; NaN for a lead no sample could check.
  std::map<std::string, std::vector<double>> groups() const;

 private:
  struct Given {
    double t, dt;
    std::size_t steps;
    std::vector<double> forces;
  };
  std::vector<std::string> groups_;
  std::vector<double> leads_;
  std::vector<Given> history_;  // time order; pruned to what the longest lead needs
  std::map<std::string, std::vector<double>> squares_;
  std::map<std::string, std::vector<long>> counts_;
};

// How far a reference's tension moves from one row to the next (one plan knot), per group of
// columns: the largest step, and the 99th percentile (the largest is one event; the
// percentile is the plans' habit). Steps are binned at 0.1 N up to 100 N (larger ones count
// in the top bin; the largest is kept exactly).
class ReferenceStepAudit {
 public:
  explicit ReferenceStepAudit(std::vector<std::string> groups);  // the group of each column
  // One reference: `steps` rows of one value per column (N), row-major; a size that does not
  // match the columns is ignored.
  void addReference(std::size_t steps, const double* forces, std::size_t size);
  double largest(const std::string& group) const;        // N; 0 for a group without steps
  double percentile99(const std::string& group) const;   // N: its bin's upper edge, at most largest()
  static constexpr double kBin = 0.1;                    // N

 private:
  std::vector<std::string> groups_;
  std::map<std::string, double> largest_;
  std::map<std::string, std::vector<long>> histogram_;
};

}  // namespace adroit::pneumatics
