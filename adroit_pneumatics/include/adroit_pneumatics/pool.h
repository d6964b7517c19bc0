// A pool of pneumatic cylinders driven as ideal force actuators (thesis 5.6-5.7, 7.4):
// force references in, valve commands out, one pressure controller per cylinder.
// ROS-free; the pool node and nodelet are thin wrappers around CylinderPool.
//
// Fail-safe rules (DESIGN.md section 4):
//  * a reference with a bad shape, a non-finite value, an unknown or repeated cylinder name,
//    or a stamp far from the pool's clock (starting in the future, or already over) is
//    rejected whole and its reason returned; the plan in force stays;
//  * negative forces are clamped to zero tension (tendons only pull) and reported;
//  * an actuator state with a bad shape, a non-finite entry of ours, a repeated name, a name
//    order other than the one the valve indices were resolved from, or a stamp that is
//    missing, in the future or already stale is rejected whole; entries with names the
//    model does not know are skipped and reported;
//  * a cylinder whose plan is older than reference_timeout, or whose state (by its header
//    stamp) is older than state_timeout, commands exhaust_volts (exhaust port fully open);
//  * a controller result that is not finite is replaced by exhaust_volts and counted.
//
// Threads: setReference/setState (one input thread, e.g. the ROS callback queue), update
// (one tick thread) and the monitoring calls (counters, exhausting, takeWindow,
// recordPolicyLag; any thread) may run concurrently. Inputs reach the tick through
// lock-free hand-overs (handover.h), and update() allocates nothing and never waits once
// every buffer has been used once (test_pool_realtime checks it). Several pools driven by
// one input path, one tick and one command: PoolGroup (pool_group.h).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "adroit_core/timing_stats.h"
#include "adroit_description/cylinders.h"
#include "adroit_pneumatics/handover.h"
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
  // s of wall time per tick for the controllers' solves; once spent, the tick's remaining
  // cylinders evaluate the plans they have (each solve is deferred to the next tick, and the
  // next tick starts with them). Bounds the CPU a pool takes when its solves grow (a burst of
  // reference jumps) or the machine slows down, so the tick, and the commands the driver's
  // watchdog waits for, stay on time. 0 = no budget.
  double solve_budget = 0.0;
  PidfParams pidf;
  double reference_timeout = 0.25;  // s since the last valid reference; then exhaust
  double state_timeout = 0.05;      // s since the stamp of the last valid actuator state; then exhaust
  // s: how far a stamp may be from the pool's clock. A reference starting later than
  // now + stamp_tolerance, or ending before now - stamp_tolerance, is rejected; so is a
  // state stamped later than now + stamp_tolerance. Larger than the transport latency and
  // the clock skew between nodes, far smaller than the offset between wall and sim time.
  double stamp_tolerance = 0.1;
  double exhaust_volts = -5.0;      // fail-safe command
  double atmosphere = constants::kAtmosphere;  // Pa, for force -> pressure
  // Throws std::invalid_argument naming the first bad field.
  void validate() const;
};

// Why a force reference was rejected.
enum class RejectReason {
  kNone = 0,
  kTiming,          // stamp not finite, or dt <= 0 with more than one step
  kStampFuture,     // starts later than now + stamp_tolerance (e.g. a wall-clock stamp under sim time)
  kStampPast,       // ended before now - stamp_tolerance: nothing of it is left to track
  kLength,
  kNonFinite,
  kUnknownName,
  kDuplicateName,
  kCount
};
// Why an actuator state was rejected.
enum class StateReject {
  kNone = 0,
  kNoStamp,         // stamp missing (zero) or not finite: its freshness is unknown
  kStampFuture,     // stamped later than now + stamp_tolerance
  kStale,           // stamped more than state_timeout ago: already too old to use
  kLength,
  kNonFinite,
  kDuplicateName,
  kNameOrder,       // our cylinders are not where they were when the valve indices were resolved
  kCount
};
const char* rejectReasonName(RejectReason reason);  // "timing", "stamp_future", ...
const char* rejectReasonName(StateReject reason);   // "no_stamp", "stale", ...

// Result of handing the pool a force reference: reason kNone = accepted; detail is one line.
struct Verdict {
  RejectReason reason = RejectReason::kNone;
  std::string detail;
  bool ignored = false;           // valid, but names none of this pool's cylinders
  bool clamped_negative = false;  // accepted with negative forces of ours clamped to 0 N
  bool ok() const { return reason == RejectReason::kNone; }
};

// Result of handing the pool an actuator state.
struct StateVerdict {
  StateReject reason = StateReject::kNone;
  std::string detail;
  bool unknown_names = false;  // names the model does not have were skipped (accepted or not)
  bool ok() const { return reason == StateReject::kNone; }
};

// What only the tick sees (the input verdicts are counted by the caller).
struct PoolCounters {
  std::uint64_t ticks = 0;
  std::uint64_t nonfinite_commands = 0;  // controller output not finite -> exhaust
  std::uint64_t solver_rejections = 0;   // solver result dropped by the controller itself
  std::uint64_t reference_timeouts = 0;  // cylinder plans that expired
  std::uint64_t solves_deferred = 0;     // controller calls past the tick's solve budget
};

// Statistics over a reporting window (since the last takeWindow()).
struct PoolWindow {
  Summary solve;           // s, controller time per tick (all driven cylinders)
  Summary lag;             // s, state receipt -> command publication (recorded by the caller)
  double force_rmse = 0;   // N, tracking error of the cylinders with a plan
  double pressure_rmse = 0;  // Pa
  std::size_t tracking_samples = 0;
};

// A message's names resolved against the model's cylinders. Hashing every name of every
// message (48 names, 250 states/s, once per pool) was a visible share of the pools' CPU;
// the names of a stream (the driver's states, the MPC's references) are the same from one
// message to the next, so NameColumns keeps the last resolution and reuses it while the
// names compare equal.
struct Columns {
  std::vector<std::string> names;  // as given (empty: the message named no cylinders)
  std::vector<int> known;          // per column: position in the model order, -1 = not in the model
  int first_unknown = -1;          // first column not in the model, -1 = none
  int first_duplicate = -1;        // first column whose name an earlier column has, -1 = none
  std::size_t size() const { return known.size(); }
};

class NameColumns {
 public:
  explicit NameColumns(const std::vector<std::string>& model_names);
  // The resolution of `names`, valid until the next call. Allocates only when the names
  // differ from the previous call's.
  const Columns& resolve(const std::vector<std::string>& names);
  // Every model cylinder in model order (a state without names).
  const Columns& modelOrder() const { return model_order_; }
  int find(const std::string& name) const;  // model position, -1 = none

 private:
  std::unordered_map<std::string, int> index_;
  Columns model_order_, last_;
  bool resolved_ = false;  // last_ holds a resolution
};

// The tick's commands on their way to the publisher thread.
struct PoolCommand {
  double stamp = 0;           // s, the pool's clock at the tick
  std::vector<double> volts;  // names() order
};
using CommandSlot = LatestValue<PoolCommand>;
// A slot for a pool of n cylinders (every buffer sized once, here).
inline PoolCommand emptyCommand(std::size_t n) { return {0.0, std::vector<double>(n, 0.0)}; }
// Tick side: copies into the slot's back buffer (same size: no allocation) and publishes it.
void putCommand(CommandSlot& slot, double stamp, const std::vector<double>& volts);

class CylinderPool {
 public:
  // known_names: every cylinder of the model (states without names use this order, and a
  // reference naming anything else is rejected). Throws std::invalid_argument for an empty
  // pool, a cylinder not in known_names, a repeated name, bad geometry or bad options.
  CylinderPool(std::vector<PoolCylinder> cylinders, std::vector<std::string> known_names, const PoolOptions& options);

  std::size_t size() const { return cylinders_.size(); }
  const std::vector<std::string>& names() const { return names_; }
  const std::vector<std::string>& knownNames() const { return known_names_; }
  const PoolOptions& options() const { return options_; }

  // --- input thread ---------------------------------------------------------------------
  // Force reference (N): sample k of column j, force[k * names.size() + j], applies at
  // t0 + k dt (t0 = the message's stamp, now = the pool's clock). Accepted references
  // replace the plans of the pool's cylinders they name.
  Verdict setReference(double now, double t0, double dt, std::size_t steps, const std::vector<std::string>& names,
                       const std::vector<double>& force);
  // The same with the names already resolved against known_names (PoolGroup resolves a
  // message once for all of its pools).
  Verdict setResolvedReference(double now, double t0, double dt, std::size_t steps, const Columns& columns,
                               const std::vector<double>& force);

  // Actuator state stamped `stamp` (its freshness is judged by the stamp, not by when it
  // arrived). names empty = known_names order. length / length_rate may be empty (travel
  // and rate 0). Entries of other cylinders are not looked at beyond their names. The
  // first accepted state that has all of the pool's cylinders fixes valveIndices().
  StateVerdict setState(double now, double stamp, const std::vector<std::string>& names,
                        const std::vector<double>& pressure, const std::vector<double>& length,
                        const std::vector<double>& length_rate, double supply);
  // The same with the names resolved against known_names (NameColumns::resolve, or
  // modelOrder() for a state without names).
  StateVerdict setResolvedState(double now, double stamp, const Columns& columns, const std::vector<double>& pressure,
                                const std::vector<double>& length, const std::vector<double>& length_rate,
                                double supply);

  // --- tick thread ----------------------------------------------------------------------
  // One control tick at time now. Commands (V) in names() order, always finite, in [-5, 5].
  const std::vector<double>& update(double now);

  // --- any thread -----------------------------------------------------------------------
  // Position of each of the pool's cylinders (names() order) in the actuator-state order,
  // for valve commands by index; valid once valveIndicesResolved() (then it never changes:
  // a state with another order is rejected, kNameOrder).
  bool valveIndicesResolved() const { return indices_resolved_.load(std::memory_order_acquire); }
  const std::vector<int>& valveIndices() const { return valve_index_; }
  // Cylinders commanding exhaust in the last tick (no plan, stale state, or bad result).
  std::size_t exhausting() const { return exhausting_.load(std::memory_order_relaxed); }
  PoolCounters counters() const;
  void recordPolicyLag(double seconds);
  PoolWindow takeWindow();

 private:
  struct Plan {
    bool valid = false;
    std::uint64_t serial = 0;  // which accepted reference made it
    double t0 = 0, dt = 0, received = 0;
    std::vector<double> pressure;  // Pa absolute
  };
  struct State {
    bool valid = false;
    double stamp = 0, pressure = 0;
    ParametricInputs inputs;
  };
  // Tick-side statistics not yet merged into the window (the merge only try-locks).
  struct Pending {
    static constexpr std::size_t kCapacity = 64;
    std::array<double, kCapacity> solve{};
    std::size_t solve_n = 0;
    double force_sq = 0, pressure_sq = 0;
    std::size_t tracking_n = 0;
  };
  Verdict reject(RejectReason reason, std::string detail) const { return {reason, std::move(detail)}; }
  void mergeStatistics();

  std::vector<PoolCylinder> cylinders_;
  std::vector<std::string> names_, known_names_;
  std::vector<int> slot_of_known_;  // known position -> pool slot, -1 = not ours
  PoolOptions options_;
  bool ilqg_ = true;                // options_.controller, compared once

  // Input thread: the complete current plans and states (a message may name only some
  // cylinders), copied whole into the hand-over's back buffer on every accepted message.
  std::vector<Plan> input_plans_;
  std::vector<State> input_states_;
  std::uint64_t next_serial_ = 1;
  NameColumns state_columns_, reference_columns_;  // the names API's resolutions, one per stream
  std::vector<std::pair<int, std::size_t>> ours_;  // (slot, column) of the message being read
  std::vector<int> valve_index_;
  std::atomic<bool> indices_resolved_{false};
  LatestValue<std::vector<Plan>> plan_box_;
  LatestValue<std::vector<State>> state_box_;

  // Tick thread.
  std::vector<std::unique_ptr<PressureController>> controllers_;
  std::vector<std::uint64_t> expired_serial_;  // plan serial that timed out, per slot
  std::vector<char> active_;
  std::vector<double> commands_, ref_buffer_;
  std::size_t first_ = 0;  // the slot the next tick starts with (the first one deferred)
  Pending pending_;
  std::atomic<std::size_t> exhausting_{0};
  std::atomic<std::uint64_t> ticks_{0}, nonfinite_commands_{0}, solver_rejections_{0}, reference_timeouts_{0},
      solves_deferred_{0};

  // Window statistics: the tick merges into them with try_lock (never waits), takeWindow locks.
  std::mutex window_mutex_;
  std::vector<double> window_solve_;  // capacity fixed at construction; full = samples dropped
  double window_force_sq_ = 0, window_pressure_sq_ = 0;
  std::size_t window_tracking_n_ = 0;
  std::mutex lag_mutex_;  // recordPolicyLag (the publisher thread) vs takeWindow
  SampleStats lag_;
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
