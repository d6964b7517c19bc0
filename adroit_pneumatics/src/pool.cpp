#include "adroit_pneumatics/pool.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_set>

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
    case RejectReason::kLength: return "length";
    case RejectReason::kNonFinite: return "non_finite";
    case RejectReason::kUnknownName: return "unknown_name";
    case RejectReason::kDuplicateName: return "duplicate_name";
    case RejectReason::kCount: break;
  }
  return "?";
}

std::uint64_t PoolCounters::rejectedTotal() const {
  std::uint64_t n = 0;
  for (auto c : references_rejected) n += c;
  return n;
}

void PoolOptions::validate() const {
  if (controller == "ilqg") {
    ilqg.validate();
    if (solve_every < 1) throw std::invalid_argument("ilqg/solve_every: must be >= 1");
  } else if (controller == "pidf") {
    pidf.validate();
  } else {
    throw std::invalid_argument("controller: must be ilqg or pidf, got '" + controller + "'");
  }
  if (!(reference_timeout > 0) || !std::isfinite(reference_timeout))
    throw std::invalid_argument("reference_timeout: must be > 0");
  if (!(state_timeout > 0) || !std::isfinite(state_timeout)) throw std::invalid_argument("state_timeout: must be > 0");
  if (!(exhaust_volts >= -kValveLimit && exhaust_volts <= kValveLimit))
    throw std::invalid_argument("exhaust_volts: must be in [-5, 5]");
  if (!(atmosphere > 0) || !std::isfinite(atmosphere)) throw std::invalid_argument("atmosphere: must be > 0");
}

CylinderPool::CylinderPool(std::vector<PoolCylinder> cylinders, std::vector<std::string> known_names,
                           const PoolOptions& options)
    : cylinders_(std::move(cylinders)), known_names_(std::move(known_names)), options_(options) {
  options_.validate();
  if (cylinders_.empty()) throw std::invalid_argument("pool has no cylinders");
  for (const auto& n : known_names_) slot_.emplace(n, -1);
  for (std::size_t i = 0; i < cylinders_.size(); ++i) {
    const PoolCylinder& c = cylinders_[i];
    const auto it = slot_.find(c.name);
    if (it == slot_.end()) throw std::invalid_argument("unknown cylinder '" + c.name + "'");
    if (it->second >= 0) throw std::invalid_argument("cylinder '" + c.name + "' listed twice");
    if (!(c.bore_area > 0) || !(c.dead_volume > 0))
      throw std::invalid_argument("cylinder '" + c.name + "' needs bore_area > 0 and dead_volume > 0");
    c.model.validate();
    it->second = static_cast<int>(i);
    names_.push_back(c.name);
    const ParametricModel model(c.model);
    if (options_.controller == "ilqg")
      controllers_.push_back(std::make_unique<IlqgPressureController>(model, options_.ilqg, options_.solve_every));
    else
      controllers_.push_back(std::make_unique<PidfController>(model, options_.pidf));
  }
  plans_.resize(size());
  states_.resize(size());
  active_.assign(size(), 0);
  commands_.assign(size(), options_.exhaust_volts);
  // The iLQG horizon needs horizon + 1 reference samples; PIDF uses only the first.
  ref_buffer_.resize(options_.controller == "ilqg" ? options_.ilqg.horizon + 1 : 1);
}

Verdict CylinderPool::reject(RejectReason reason, std::string detail) {
  ++counters_.references_rejected[static_cast<int>(reason)];
  return {reason, std::move(detail)};
}

Verdict CylinderPool::setReference(double now, double t0, double dt, std::size_t steps,
                                   const std::vector<std::string>& names, const std::vector<double>& force) {
  if (!std::isfinite(t0)) return reject(RejectReason::kTiming, "reference stamp is not finite");
  if (steps == 0) return reject(RejectReason::kLength, "reference has 0 steps");
  if (steps > 1 && !(dt > 0 && std::isfinite(dt))) return reject(RejectReason::kTiming, "reference dt must be > 0");
  if (names.empty()) return reject(RejectReason::kLength, "reference names no cylinders");
  if (force.size() != steps * names.size())
    return reject(RejectReason::kLength, "reference has " + std::to_string(force.size()) + " forces, expected steps " +
                                             std::to_string(steps) + " x names " + std::to_string(names.size()));
  if (!allFinite(force)) return reject(RejectReason::kNonFinite, "reference contains NaN or Inf");
  std::vector<std::pair<int, std::size_t>> ours;  // (slot, column)
  std::unordered_set<std::string> seen;
  for (std::size_t j = 0; j < names.size(); ++j) {
    const auto it = slot_.find(names[j]);
    if (it == slot_.end()) return reject(RejectReason::kUnknownName, "reference names unknown cylinder '" + names[j] + "'");
    if (!seen.insert(names[j]).second)
      return reject(RejectReason::kDuplicateName, "reference names cylinder '" + names[j] + "' twice");
    if (it->second >= 0) ours.emplace_back(it->second, j);
  }
  if (ours.empty()) {
    ++counters_.references_ignored;
    return {};
  }
  for (const auto& [slot, col] : ours) {
    Plan& plan = plans_[slot];
    plan.valid = true;
    plan.t0 = t0;
    plan.dt = steps > 1 ? dt : 1.0;
    plan.received = now;
    plan.pressure.resize(steps);
    // Tendons only pull: a negative force asks for less than atmospheric pressure, which the
    // chamber cannot reach, so it is clamped to zero tension.
    for (std::size_t k = 0; k < steps; ++k)
      plan.pressure[k] = options_.atmosphere + std::max(0.0, force[k * names.size() + col]) / cylinders_[slot].bore_area;
  }
  ++counters_.references_accepted;
  return {};
}

Verdict CylinderPool::setState(double now, const std::vector<std::string>& names, const std::vector<double>& pressure,
                               const std::vector<double>& length, const std::vector<double>& length_rate,
                               double supply) {
  auto bad = [&](std::string detail) {
    ++counters_.states_rejected;
    return Verdict{RejectReason::kLength, std::move(detail)};
  };
  const std::size_t n = names.empty() ? known_names_.size() : names.size();
  if (pressure.size() != n) return bad("actuator state has " + std::to_string(pressure.size()) + " pressures for " +
                                       std::to_string(n) + " cylinders");
  if (!length.empty() && length.size() != n) return bad("actuator state length[] has the wrong size");
  if (!length_rate.empty() && length_rate.size() != n) return bad("actuator state length_rate[] has the wrong size");
  if (!std::isfinite(supply)) {
    ++counters_.states_rejected;
    return {RejectReason::kNonFinite, "actuator state supply pressure is not finite"};
  }
  // Validate every entry of ours before touching any state, so a bad message changes nothing.
  std::vector<std::pair<int, std::size_t>> ours;
  for (std::size_t j = 0; j < n; ++j) {
    const auto it = slot_.find(names.empty() ? known_names_[j] : names[j]);
    if (it == slot_.end() || it->second < 0) continue;
    const double x = length.empty() ? 0.0 : length[j], xd = length_rate.empty() ? 0.0 : length_rate[j];
    if (!std::isfinite(pressure[j]) || !std::isfinite(x) || !std::isfinite(xd)) {
      ++counters_.states_rejected;
      return {RejectReason::kNonFinite, "actuator state of '" + cylinders_[it->second].name + "' is not finite"};
    }
    ours.emplace_back(it->second, j);
  }
  for (const auto& [slot, j] : ours) {
    const PoolCylinder& c = cylinders_[slot];
    State& s = states_[slot];
    s.valid = true;
    s.received = now;
    s.pressure = pressure[j];
    s.inputs.volume = c.dead_volume + c.bore_area * std::max(0.0, length.empty() ? 0.0 : length[j]);
    s.inputs.volume_rate = c.bore_area * (length_rate.empty() ? 0.0 : length_rate[j]);
    s.inputs.supply = std::max(supply, options_.atmosphere);
    s.inputs.room = options_.atmosphere;
  }
  ++counters_.states_accepted;
  return {};
}

const std::vector<double>& CylinderPool::update(double now) {
  ++counters_.ticks;
  exhausting_ = 0;
  double solve_seconds = 0;
  bool driven = false;
  const double dt_ctrl = options_.controller == "ilqg" ? options_.ilqg.dt : 0.005;
  for (std::size_t i = 0; i < size(); ++i) {
    Plan& plan = plans_[i];
    const State& state = states_[i];
    if (plan.valid && now - plan.received > options_.reference_timeout) {
      plan.valid = false;
      ++counters_.reference_timeouts;
    }
    const bool fresh_state = state.valid && now - state.received <= options_.state_timeout;
    double u = std::numeric_limits<double>::quiet_NaN();
    if (plan.valid && fresh_state) {
      resampleReference(plan.pressure.data(), static_cast<int>(plan.pressure.size()), plan.dt, now - plan.t0, dt_ctrl,
                        static_cast<int>(ref_buffer_.size()), ref_buffer_.data());
      ControlStats stats;
      const Stopwatch watch;  // whole controller call: solve (when due) + policy evaluation
      u = controllers_[i]->update(now, state.pressure, commands_[i], state.inputs, ref_buffer_.data(),
                                  static_cast<int>(ref_buffer_.size()), dt_ctrl, &stats);
      solve_seconds += watch.elapsed();
      driven = true;
      if (stats.rejected) ++counters_.solver_rejections;
      if (!std::isfinite(u)) ++counters_.nonfinite_commands;
      const double e = state.pressure - ref_buffer_[0];
      pressure_sq_ += e * e;
      force_sq_ += e * e * cylinders_[i].bore_area * cylinders_[i].bore_area;
      ++tracking_n_;
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
      ++exhausting_;
    }
  }
  if (driven) solve_.add(solve_seconds);
  return commands_;
}

PoolWindow CylinderPool::takeWindow() {
  PoolWindow w;
  w.solve = solve_.summary();
  w.lag = lag_.summary();
  w.tracking_samples = tracking_n_;
  if (tracking_n_ > 0) {
    w.force_rmse = std::sqrt(force_sq_ / tracking_n_);
    w.pressure_rmse = std::sqrt(pressure_sq_ / tracking_n_);
  }
  solve_.clear();
  lag_.clear();
  force_sq_ = pressure_sq_ = 0;
  tracking_n_ = 0;
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
