// A pool of pneumatic cylinders driven as ideal force actuators (thesis 5.6-5.7, 7.4):
// force references in, valve commands out, one pressure controller per cylinder.
// ROS-free; the pool node and nodelet are thin wrappers around CylinderPool.
//
// Fail-safe rules (DESIGN.md section 4):
//  * a reference with a bad shape, a non-finite value, or an unknown or repeated cylinder
//    name is rejected whole and counted by reason; the plan in force stays;
//  * a cylinder whose plan is older than reference_timeout, or whose state is older than
//    state_timeout, commands exhaust_volts (exhaust port fully open);
//  * a controller result that is not finite is replaced by exhaust_volts and counted.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "adroit_core/timing_stats.h"
#include "adroit_description/cylinders.h"
#include "adroit_pneumatics/pressure_control.h"

namespace adroit::pneumatics {

// One cylinder of a pool: what the controller and the force->pressure map need.
struct PoolCylinder {
  std::string name;        // actuator name in the model, e.g. A_FFJ2_flex
  double bore_area = 0;    // m^2
  double dead_volume = 0;  // m^3, chamber volume at zero travel
  ParametricParams model;  // identified parametric pressure model
};

struct PoolOptions {
  std::string controller = "ilqg";  // ilqg | pidf
  IlqgParams ilqg;
  int solve_every = 1;              // iLQG: ticks between solves (policy evaluated every tick)
  PidfParams pidf;
  double reference_timeout = 0.25;  // s since the last valid reference; then exhaust
  double state_timeout = 0.05;      // s since the last valid actuator state; then exhaust
  double exhaust_volts = -5.0;      // fail-safe command
  double atmosphere = constants::kAtmosphere;  // Pa, for force -> pressure
  // Throws std::invalid_argument naming the first bad field.
  void validate() const;
};

enum class RejectReason { kNone = 0, kTiming, kLength, kNonFinite, kUnknownName, kDuplicateName, kCount };
const char* rejectReasonName(RejectReason reason);  // "timing", "length", ...

// Result of handing the pool a message: reason kNone = accepted; detail is one line.
struct Verdict {
  RejectReason reason = RejectReason::kNone;
  std::string detail;
  bool ok() const { return reason == RejectReason::kNone; }
};

struct PoolCounters {
  std::uint64_t ticks = 0;
  std::uint64_t references_accepted = 0;
  std::uint64_t references_ignored = 0;  // valid, but named none of this pool's cylinders
  std::array<std::uint64_t, static_cast<int>(RejectReason::kCount)> references_rejected{};
  std::uint64_t states_accepted = 0;
  std::uint64_t states_rejected = 0;
  std::uint64_t nonfinite_commands = 0;  // controller output not finite -> exhaust
  std::uint64_t solver_rejections = 0;   // solver result dropped by the controller itself
  std::uint64_t reference_timeouts = 0;  // cylinder plans that expired
  std::uint64_t rejectedTotal() const;
};

// Statistics over a reporting window (since the last takeWindow()).
struct PoolWindow {
  Summary solve;           // s, controller time per tick (all driven cylinders)
  Summary lag;             // s, state receipt -> command publication (recorded by the caller)
  double force_rmse = 0;   // N, tracking error of the cylinders with a plan
  double pressure_rmse = 0;  // Pa
  std::size_t tracking_samples = 0;
};

class CylinderPool {
 public:
  // known_names: every cylinder of the model (states without names use this order, and a
  // reference naming anything else is rejected). Throws std::invalid_argument for an empty
  // pool, a cylinder not in known_names, a repeated name, bad geometry or bad options.
  CylinderPool(std::vector<PoolCylinder> cylinders, std::vector<std::string> known_names, const PoolOptions& options);

  std::size_t size() const { return cylinders_.size(); }
  const std::vector<std::string>& names() const { return names_; }
  const PoolOptions& options() const { return options_; }

  // Force reference (N): sample k of column j, force[k * names.size() + j], applies at
  // t0 + k dt. Accepted references replace the plans of the pool's cylinders they name.
  Verdict setReference(double now, double t0, double dt, std::size_t steps, const std::vector<std::string>& names,
                       const std::vector<double>& force);

  // Actuator state. names empty = known_names order. length / length_rate may be empty
  // (travel and rate 0). Entries of other cylinders are not looked at.
  Verdict setState(double now, const std::vector<std::string>& names, const std::vector<double>& pressure,
                   const std::vector<double>& length, const std::vector<double>& length_rate, double supply);

  // One control tick at time now. Commands (V) in names() order, always finite, in [-5, 5].
  const std::vector<double>& update(double now);

  // Cylinders commanding exhaust in the last tick (no plan, stale state, or bad result).
  std::size_t exhausting() const { return exhausting_; }
  void recordPolicyLag(double seconds) { lag_.add(seconds); }
  PoolWindow takeWindow();
  const PoolCounters& counters() const { return counters_; }

 private:
  struct Plan {
    bool valid = false;
    double t0 = 0, dt = 0, received = 0;
    std::vector<double> pressure;  // Pa absolute
  };
  struct State {
    bool valid = false;
    double received = 0, pressure = 0;
    ParametricInputs inputs;
  };
  Verdict reject(RejectReason reason, std::string detail);

  std::vector<PoolCylinder> cylinders_;
  std::vector<std::string> names_, known_names_;
  std::unordered_map<std::string, int> slot_;  // known name -> pool slot, -1 = not ours
  PoolOptions options_;
  std::vector<std::unique_ptr<PressureController>> controllers_;
  std::vector<Plan> plans_;
  std::vector<State> states_;
  std::vector<char> active_;
  std::vector<double> commands_, ref_buffer_;
  std::size_t exhausting_ = 0;
  PoolCounters counters_;
  SampleStats solve_, lag_;
  double force_sq_ = 0, pressure_sq_ = 0;
  std::size_t tracking_n_ = 0;
};

// Default split of the model's cylinders into pools: the hand cylinders (all but A_ARJ*)
// in model order in groups of group_size, then the arm cylinders as one more pool.
std::vector<std::vector<std::string>> defaultPoolSplit(const std::vector<std::string>& model_names,
                                                       int group_size = 8);

// Dead volume of a cylinder type from the plant catalogue; types the catalogue lacks
// (M40) get the M9 dead volume scaled with the bore area, the rule the catalogue uses.
double deadVolume(const std::string& type, double bore_diameter);

// The cylinders of an MJCF scene in model order (adroit_description::cylinderTable).
// Throws std::runtime_error with one line naming the file and the problem.
std::vector<description::Cylinder> loadModelCylinders(const std::string& mjcf_path);

}  // namespace adroit::pneumatics
