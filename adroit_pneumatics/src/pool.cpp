#include "adroit_pneumatics/pool.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "adroit_core/mujoco_model.h"
#include "adroit_pneumatics/plant.h"

namespace adroit::pneumatics {

namespace {

constexpr double kValveLimit = 5.0;  // V, the valve's input range

bool allFinite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

const char* rejectReasonName(RejectReason reason) {
  switch (reason) {
    case RejectReason::kNone: return "none";
    case RejectReason::kTiming: return "timing";
    case RejectReason::kStampFuture: return "stamp_future";
    case RejectReason::kStampPast: return "stamp_past";
    case RejectReason::kLength: return "length";
    case RejectReason::kNonFinite: return "non_finite";
    case RejectReason::kUnknownName: return "unknown_name";
    case RejectReason::kDuplicateName: return "duplicate_name";
    case RejectReason::kCount: break;
  }
  return "?";
}

const char* rejectReasonName(StateReject reason) {
  switch (reason) {
    case StateReject::kNone: return "none";
    case StateReject::kNoStamp: return "no_stamp";
    case StateReject::kStampFuture: return "stamp_future";
    case StateReject::kStale: return "stale";
    case StateReject::kLength: return "length";
    case StateReject::kNonFinite: return "non_finite";
    case StateReject::kDuplicateName: return "duplicate_name";
    case StateReject::kNameOrder: return "name_order";
    case StateReject::kCount: break;
  }
  return "?";
}

NameColumns::NameColumns(const std::vector<std::string>& model_names) {
  model_order_.names = model_names;
  for (std::size_t k = 0; k < model_names.size(); ++k) {
    index_.emplace(model_names[k], static_cast<int>(k));
    model_order_.known.push_back(static_cast<int>(k));
  }
}

int NameColumns::find(const std::string& name) const {
  const auto it = index_.find(name);
  return it == index_.end() ? -1 : it->second;
}

const Columns& NameColumns::resolve(const std::vector<std::string>& names) {
  if (resolved_ && names == last_.names) return last_;  // the stream's usual case: no hashing
  last_.names = names;
  last_.known.assign(names.size(), -1);
  last_.first_unknown = last_.first_duplicate = -1;
  std::vector<char> seen(model_order_.size(), 0);
  for (std::size_t j = 0; j < names.size(); ++j) {
    const int k = find(names[j]);
    if (k < 0) {
      if (last_.first_unknown < 0) last_.first_unknown = static_cast<int>(j);
      continue;
    }
    if (seen[k] && last_.first_duplicate < 0) last_.first_duplicate = static_cast<int>(j);
    seen[k] = 1;
    last_.known[j] = k;
  }
  resolved_ = true;
  return last_;
}

void putCommand(CommandSlot& slot, double stamp, const std::vector<double>& volts) {
  PoolCommand& c = slot.back();
  c.stamp = stamp;
  std::copy(volts.begin(), volts.end(), c.volts.begin());  // sized by emptyCommand(n)
  slot.publish();
}

void PoolOptions::validate() const {
  if (controller == "ilqg") {
    ilqg.validate();
    if (solve_every < 1) throw std::invalid_argument("ilqg/solve_every: must be >= 1");
    if (!(solve_budget >= 0) || !std::isfinite(solve_budget))
      throw std::invalid_argument("ilqg/solve_budget: must be >= 0 (s; 0 = no budget)");
  } else if (controller == "pidf") {
    pidf.validate();
  } else {
    throw std::invalid_argument("controller: must be ilqg or pidf, got '" + controller + "'");
  }
  if (!(reference_timeout > 0) || !std::isfinite(reference_timeout))
    throw std::invalid_argument("reference_timeout: must be > 0");
  if (!(state_timeout > 0) || !std::isfinite(state_timeout)) throw std::invalid_argument("state_timeout: must be > 0");
  if (!(stamp_tolerance > 0) || !std::isfinite(stamp_tolerance))
    throw std::invalid_argument("stamp_tolerance: must be > 0");
  if (!(exhaust_volts >= -kValveLimit && exhaust_volts <= kValveLimit))
    throw std::invalid_argument("exhaust_volts: must be in [-5, 5]");
  if (!(atmosphere > 0) || !std::isfinite(atmosphere)) throw std::invalid_argument("atmosphere: must be > 0");
}

CylinderPool::CylinderPool(std::vector<PoolCylinder> cylinders, std::vector<std::string> known_names,
                           const PoolOptions& options)
    : cylinders_(std::move(cylinders)), known_names_(std::move(known_names)), options_(options),
      state_columns_(known_names_), reference_columns_(known_names_),
      plan_box_(std::vector<Plan>(cylinders_.size())), state_box_(std::vector<State>(cylinders_.size())) {
  options_.validate();
  ilqg_ = options_.controller == "ilqg";
  if (cylinders_.empty()) throw std::invalid_argument("pool has no cylinders");
  slot_of_known_.assign(known_names_.size(), -1);
  for (std::size_t i = 0; i < cylinders_.size(); ++i) {
    const PoolCylinder& c = cylinders_[i];
    const int known = state_columns_.find(c.name);
    if (known < 0) throw std::invalid_argument("unknown cylinder '" + c.name + "'");
    if (slot_of_known_[known] >= 0) throw std::invalid_argument("cylinder '" + c.name + "' listed twice");
    if (!(c.bore_area > 0) || !(c.dead_volume > 0))
      throw std::invalid_argument("cylinder '" + c.name + "' needs bore_area > 0 and dead_volume > 0");
    c.model.validate();
    slot_of_known_[known] = static_cast<int>(i);
    names_.push_back(c.name);
    const ParametricModel model(c.model);
    if (ilqg_)
      controllers_.push_back(std::make_unique<IlqgPressureController>(model, options_.ilqg, options_.solve_every));
    else
      controllers_.push_back(std::make_unique<PidfController>(model, options_.pidf));
  }
  input_plans_.resize(size());
  input_states_.resize(size());
  ours_.reserve(size());
  valve_index_.assign(size(), -1);
  expired_serial_.assign(size(), 0);
  active_.assign(size(), 0);
  commands_.assign(size(), options_.exhaust_volts);
  // The iLQG horizon needs horizon + 1 reference samples; PIDF uses only the first.
  ref_buffer_.resize(ilqg_ ? options_.ilqg.horizon + 1 : 1);
  // Room for 20 s of ticks at 200 Hz between two takeWindow() calls; beyond, samples drop.
  window_solve_.reserve(4096);
}

Verdict CylinderPool::setReference(double now, double t0, double dt, std::size_t steps,
                                   const std::vector<std::string>& names, const std::vector<double>& force) {
  return setResolvedReference(now, t0, dt, steps, reference_columns_.resolve(names), force);
}

Verdict CylinderPool::setResolvedReference(double now, double t0, double dt, std::size_t steps,
                                           const Columns& columns, const std::vector<double>& force) {
  if (!std::isfinite(t0)) return reject(RejectReason::kTiming, "reference stamp is not finite");
  if (steps == 0) return reject(RejectReason::kLength, "reference has 0 steps");
  if (steps > 1 && !(dt > 0 && std::isfinite(dt))) return reject(RejectReason::kTiming, "reference dt must be > 0");
  // A stamp on another clock (wall time under sim time or the reverse) or a reference that
  // is over already would otherwise be read as a constant: its last sample held.
  const double tol = options_.stamp_tolerance;
  if (t0 > now + tol)
    return reject(RejectReason::kStampFuture, "reference starts " + std::to_string(t0 - now) +
                                                  " s after the pool's clock (stamp_tolerance " + std::to_string(tol) +
                                                  " s)");
  const double end = t0 + (steps - 1) * (steps > 1 ? dt : 0.0);
  if (end < now - tol)
    return reject(RejectReason::kStampPast, "reference ended " + std::to_string(now - end) +
                                                " s before the pool's clock (stamp_tolerance " + std::to_string(tol) +
                                                " s)");
  const std::size_t width = columns.size();
  if (width == 0) return reject(RejectReason::kLength, "reference names no cylinders");
  if (force.size() != steps * width)
    return reject(RejectReason::kLength, "reference has " + std::to_string(force.size()) + " forces, expected steps " +
                                             std::to_string(steps) + " x names " + std::to_string(width));
  if (!allFinite(force)) return reject(RejectReason::kNonFinite, "reference contains NaN or Inf");
  ours_.clear();
  for (std::size_t j = 0; j < width; ++j) {
    const int known = columns.known[j];
    if (known < 0)
      return reject(RejectReason::kUnknownName, "reference names unknown cylinder '" + columns.names[j] + "'");
    if (static_cast<int>(j) == columns.first_duplicate)
      return reject(RejectReason::kDuplicateName, "reference names cylinder '" + columns.names[j] + "' twice");
    if (slot_of_known_[known] >= 0) ours_.emplace_back(slot_of_known_[known], j);
  }
  Verdict verdict;
  if (ours_.empty()) {
    verdict.ignored = true;
    return verdict;
  }
  const std::uint64_t serial = next_serial_++;
  for (const auto& [slot, col] : ours_) {
    Plan& plan = input_plans_[slot];
    plan.valid = true;
    plan.serial = serial;
    plan.t0 = t0;
    plan.dt = steps > 1 ? dt : 1.0;
    plan.received = now;
    plan.pressure.resize(steps);
    // Tendons only pull: a negative force asks for less than atmospheric pressure, which the
    // chamber cannot reach, so it is clamped to zero tension (and reported: the driver
    // rejects negative tensions, a planner sending them has a bug worth seeing).
    for (std::size_t k = 0; k < steps; ++k) {
      const double f = force[k * width + col];
      if (f < 0) verdict.clamped_negative = true;
      plan.pressure[k] = options_.atmosphere + std::max(0.0, f) / cylinders_[slot].bore_area;
    }
  }
  plan_box_.back() = input_plans_;  // this thread's buffer; reuses its capacity
  plan_box_.publish();
  return verdict;
}

StateVerdict CylinderPool::setState(double now, double stamp, const std::vector<std::string>& names,
                                    const std::vector<double>& pressure, const std::vector<double>& length,
                                    const std::vector<double>& length_rate, double supply) {
  const Columns& columns = names.empty() ? state_columns_.modelOrder() : state_columns_.resolve(names);
  return setResolvedState(now, stamp, columns, pressure, length, length_rate, supply);
}

StateVerdict CylinderPool::setResolvedState(double now, double stamp, const Columns& columns,
                                            const std::vector<double>& pressure, const std::vector<double>& length,
                                            const std::vector<double>& length_rate, double supply) {
  StateVerdict verdict;
  auto bad = [&verdict](StateReject reason, std::string detail) {
    verdict.reason = reason;
    verdict.detail = std::move(detail);
    return verdict;
  };
  if (!std::isfinite(stamp)) return bad(StateReject::kNoStamp, "actuator state has no stamp");
  if (stamp > now + options_.stamp_tolerance)
    return bad(StateReject::kStampFuture,
               "actuator state stamped " + std::to_string(stamp - now) + " s after the pool's clock");
  if (now - stamp > options_.state_timeout)
    return bad(StateReject::kStale, "actuator state stamped " + std::to_string(now - stamp) +
                                        " s ago (state_timeout " + std::to_string(options_.state_timeout) + " s)");
  const std::size_t n = columns.size();
  if (pressure.size() != n)
    return bad(StateReject::kLength, "actuator state has " + std::to_string(pressure.size()) + " pressures for " +
                                         std::to_string(n) + " cylinders");
  if (!length.empty() && length.size() != n) return bad(StateReject::kLength, "actuator state length[] has the wrong size");
  if (!length_rate.empty() && length_rate.size() != n)
    return bad(StateReject::kLength, "actuator state length_rate[] has the wrong size");
  if (!std::isfinite(supply)) return bad(StateReject::kNonFinite, "actuator state supply pressure is not finite");
  // Validate every entry before touching any state, so a bad message changes nothing.
  verdict.unknown_names = columns.first_unknown >= 0;  // another model's cylinders: skipped, reported
  ours_.clear();
  for (std::size_t j = 0; j < n; ++j) {
    if (static_cast<int>(j) == columns.first_duplicate)
      return bad(StateReject::kDuplicateName, "actuator state names '" + columns.names[j] + "' twice");
    const int known = columns.known[j];
    if (known < 0) continue;
    const int slot = slot_of_known_[known];
    if (slot < 0) continue;
    const double x = length.empty() ? 0.0 : length[j], xd = length_rate.empty() ? 0.0 : length_rate[j];
    if (!std::isfinite(pressure[j]) || !std::isfinite(x) || !std::isfinite(xd))
      return bad(StateReject::kNonFinite, "actuator state of '" + cylinders_[slot].name + "' is not finite");
    ours_.emplace_back(slot, j);
  }
  // Valve indices: fixed by the first state that has all of ours; a later state must have
  // them at the same places, or commands by index would reach the wrong cylinders.
  if (indices_resolved_.load(std::memory_order_relaxed)) {
    for (const auto& [slot, j] : ours_) {
      if (static_cast<int>(j) != valve_index_[slot])
        return bad(StateReject::kNameOrder, "actuator state has '" + cylinders_[slot].name + "' at " +
                                                std::to_string(j) + ", the valve commands address it as " +
                                                std::to_string(valve_index_[slot]));
    }
  }
  for (const auto& [slot, j] : ours_) {
    const PoolCylinder& c = cylinders_[slot];
    State& s = input_states_[slot];
    s.valid = true;
    s.stamp = stamp;
    s.pressure = pressure[j];
    s.inputs.volume = c.dead_volume + c.bore_area * std::max(0.0, length.empty() ? 0.0 : length[j]);
    s.inputs.volume_rate = c.bore_area * (length_rate.empty() ? 0.0 : length_rate[j]);
    s.inputs.supply = std::max(supply, options_.atmosphere);
    s.inputs.room = options_.atmosphere;
  }
  if (!indices_resolved_.load(std::memory_order_relaxed) && ours_.size() == size()) {
    for (const auto& [slot, j] : ours_) valve_index_[slot] = static_cast<int>(j);
    indices_resolved_.store(true, std::memory_order_release);
  }
  state_box_.back() = input_states_;  // same size every time: no allocation
  state_box_.publish();
  return verdict;
}

const std::vector<double>& CylinderPool::update(double now) {
  ticks_.fetch_add(1, std::memory_order_relaxed);
  plan_box_.take();  // the newest inputs, if any arrived since the last tick
  state_box_.take();
  const std::vector<Plan>& plans = plan_box_.front();
  const std::vector<State>& states = state_box_.front();
  std::size_t exhausting = 0;
  double solve_seconds = 0;
  bool driven = false, deferred = false;
  std::size_t next_first = first_;
  const double dt_ctrl = ilqg_ ? options_.ilqg.dt : 0.005;
  const bool budgeted = ilqg_ && options_.solve_budget > 0;
  const Stopwatch tick_watch;
  for (std::size_t k = 0; k < size(); ++k) {
    const std::size_t i = (first_ + k) % size();
    const Plan& plan = plans[i];
    const State& state = states[i];
    bool planned = plan.valid && plan.serial != expired_serial_[i];
    if (planned && now - plan.received > options_.reference_timeout) {
      expired_serial_[i] = plan.serial;  // counted once, even if the input thread hands it over again
      planned = false;
      reference_timeouts_.fetch_add(1, std::memory_order_relaxed);
    }
    const bool fresh_state = state.valid && now - state.stamp <= options_.state_timeout;
    double u = std::numeric_limits<double>::quiet_NaN();
    if (planned && fresh_state) {
      resampleReference(plan.pressure.data(), static_cast<int>(plan.pressure.size()), plan.dt, now - plan.t0, dt_ctrl,
                        static_cast<int>(ref_buffer_.size()), ref_buffer_.data());
      ControlStats stats;
      const bool may_solve = !budgeted || tick_watch.elapsed() < options_.solve_budget;
      const Stopwatch watch;  // whole controller call: solve (when due) + policy evaluation
      u = controllers_[i]->update(now, state.pressure, commands_[i], state.inputs, ref_buffer_.data(),
                                  static_cast<int>(ref_buffer_.size()), dt_ctrl, &stats, may_solve);
      if (!may_solve && !stats.solved) {  // (a controller without a plan yet solves regardless)
        if (!deferred) next_first = i;
        deferred = true;
        solves_deferred_.fetch_add(1, std::memory_order_relaxed);
      }
      solve_seconds += watch.elapsed();
      driven = true;
      if (stats.rejected) solver_rejections_.fetch_add(1, std::memory_order_relaxed);
      if (!std::isfinite(u)) nonfinite_commands_.fetch_add(1, std::memory_order_relaxed);
      const double e = state.pressure - ref_buffer_[0];
      pending_.pressure_sq += e * e;
      pending_.force_sq += e * e * cylinders_[i].bore_area * cylinders_[i].bore_area;
      ++pending_.tracking_n;
    }
    if (std::isfinite(u)) {
      commands_[i] = std::clamp(u, -kValveLimit, kValveLimit);
      active_[i] = 1;
    } else {
      // Fail safe; the controller starts afresh (no stale integrator or warm start) when
      // the cylinder is next driven.
      if (active_[i]) controllers_[i]->reset();
      active_[i] = 0;
      commands_[i] = options_.exhaust_volts;
      ++exhausting;
    }
  }
  first_ = next_first;
  exhausting_.store(exhausting, std::memory_order_relaxed);
  if (driven && pending_.solve_n < Pending::kCapacity) pending_.solve[pending_.solve_n++] = solve_seconds;
  mergeStatistics();
  return commands_;
}

void CylinderPool::mergeStatistics() {
  // Never wait for the monitoring thread: if it holds the lock, keep the samples pending.
  std::unique_lock<std::mutex> lock(window_mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  for (std::size_t k = 0; k < pending_.solve_n && window_solve_.size() < window_solve_.capacity(); ++k)
    window_solve_.push_back(pending_.solve[k]);  // within the reserved capacity: no allocation
  window_force_sq_ += pending_.force_sq;
  window_pressure_sq_ += pending_.pressure_sq;
  window_tracking_n_ += pending_.tracking_n;
  pending_ = Pending{};
}

PoolCounters CylinderPool::counters() const {
  PoolCounters c;
  c.ticks = ticks_.load(std::memory_order_relaxed);
  c.nonfinite_commands = nonfinite_commands_.load(std::memory_order_relaxed);
  c.solver_rejections = solver_rejections_.load(std::memory_order_relaxed);
  c.reference_timeouts = reference_timeouts_.load(std::memory_order_relaxed);
  c.solves_deferred = solves_deferred_.load(std::memory_order_relaxed);
  return c;
}

void CylinderPool::recordPolicyLag(double seconds) {
  const std::lock_guard<std::mutex> lock(lag_mutex_);
  lag_.add(seconds);
}

PoolWindow CylinderPool::takeWindow() {
  PoolWindow w;
  SampleStats solve;  // summarised outside the lock (sorting a copy allocates: not the tick's concern)
  {
    const std::lock_guard<std::mutex> lock(window_mutex_);
    for (double x : window_solve_) solve.add(x);
    window_solve_.clear();  // keeps the capacity
    w.tracking_samples = window_tracking_n_;
    if (window_tracking_n_ > 0) {
      w.force_rmse = std::sqrt(window_force_sq_ / window_tracking_n_);
      w.pressure_rmse = std::sqrt(window_pressure_sq_ / window_tracking_n_);
    }
    window_force_sq_ = window_pressure_sq_ = 0;
    window_tracking_n_ = 0;
  }
  w.solve = solve.summary();
  const std::lock_guard<std::mutex> lock(lag_mutex_);
  w.lag = lag_.summary();
  lag_.clear();
  return w;
}

std::vector<std::vector<std::string>> defaultPoolSplit(const std::vector<std::string>& model_names, int group_size) {
  if (group_size < 1) throw std::invalid_argument("group_size must be >= 1");
  std::vector<std::string> hand, arm;
  for (const auto& n : model_names) (n.rfind("A_ARJ", 0) == 0 ? arm : hand).push_back(n);
  std::vector<std::vector<std::string>> pools;
  for (std::size_t i = 0; i < hand.size(); i += group_size)
    pools.emplace_back(hand.begin() + i, hand.begin() + std::min(hand.size(), i + group_size));
  if (!arm.empty()) pools.push_back(arm);
  return pools;
}

double deadVolume(const std::string& type, double bore_diameter) {
  try {
    return cylinderSpec(type).dead_volume;
  } catch (const std::invalid_argument&) {
    const CylinderSpec m9 = cylinderSpec("M9");
    const double r = bore_diameter / m9.bore_diameter;
    return m9.dead_volume * r * r;
  }
}

std::vector<description::Cylinder> loadModelCylinders(const std::string& mjcf_path) {
  const LoadedModel loaded = loadModelFile(mjcf_path);  // ModelLoadError names the file
  try {
    return description::cylinderTable(loaded.model.get());
  } catch (const std::exception& e) {
    throw std::runtime_error(mjcf_path + ": " + e.what());
  }
}

}  // namespace adroit::pneumatics
