#include "adroit_pneumatics/tracking_floor.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace adroit::pneumatics {

namespace {
constexpr std::size_t kHistory = 256;  // references kept for the dead time
}  // namespace

TrackingFloor::TrackingFloor(const CylinderSpec& spec, double limit, double dead_time, double room)
    : spec_(spec), limit_(limit), dead_time_(dead_time), history_time_(kHistory), history_ref_(kHistory),
      pressure_(room) {
  if (!(limit > 0 && limit <= 5)) throw std::invalid_argument("TrackingFloor: limit must be in (0, 5] V");
  if (!(dead_time >= 0 && dead_time <= 0.1)) throw std::invalid_argument("TrackingFloor: dead_time must be in [0, 0.1] s");
  fill_.inlet_area = spec.valve.inlet(limit);
  fill_.outlet_area = spec.valve.exhaust(limit) + spec.leak_area;
  vent_.inlet_area = spec.valve.inlet(-limit);
  vent_.outlet_area = spec.valve.exhaust(-limit) + spec.leak_area;
  fill_.room = vent_.room = room;
}

void TrackingFloor::reset(double pressure) {
  pressure_ = pressure;
  held_ = 0.0;
  time_ = 0;
  count_ = 0;
}

double TrackingFloor::step(double p_ref, double dt, double volume, double volume_rate, double supply) {
  if (!std::isfinite(p_ref) || !std::isfinite(volume) || !std::isfinite(volume_rate) || !std::isfinite(supply) ||
      !(dt > 0) || !(volume > 0))
    return pressure_;
  for (ChamberInputs* in : {&fill_, &vent_}) {
    in->volume = volume;
    in->volume_rate = volume_rate;
    in->supply = supply;
  }
  if (hold_) return holdStep(p_ref, dt);
  head_ = (head_ + 1) % kHistory;
  history_time_[head_] = time_, history_ref_[head_] = p_ref;
  count_ = std::min(count_ + 1, kHistory);
  // The references act dead_time after they were given (the oldest kept one until then):
  // advance piecewise between the instants at which the acting reference changes.
  const double end = time_ + dt;
  double t = time_;
  while (t < end - 1e-12) {
    std::size_t acting = count_ - 1;  // age of the acting entry (0 = newest)
    for (std::size_t k = 0; k < count_; ++k)
      if (history_time_[(head_ + kHistory - k) % kHistory] + dead_time_ <= t + 1e-12) {
        acting = k;
        break;
      }
    const double change = acting == 0 ? end : history_time_[(head_ + kHistory - acting + 1) % kHistory] + dead_time_;
    const double until = std::min(end, std::max(change, t + 1e-9));
    // The reachable interval after the sub-step is [vented, filled]: both are monotone in
    // the start pressure, and any command within the limit ends between them.
    const double h = until - t;
    const double filled = chamberStep(pressure_, h, fill_), vented = chamberStep(pressure_, h, vent_);
    pressure_ = std::clamp(history_ref_[(head_ + kHistory - acting) % kHistory], std::min(vented, filled),
                           std::max(vented, filled));
    t = until;
  }
  time_ = end;
  return pressure_;
}

double TrackingFloor::advance(double p, double h, double u) const {
  if (!(h > 0)) return p;
  ChamberInputs in = fill_;
  in.inlet_area = spec_.valve.inlet(u);
  in.outlet_area = spec_.valve.exhaust(u) + spec_.leak_area;
  return chamberStep(p, h, in);
}

double TrackingFloor::holdStep(double p_ref, double dt) {
  // The command chosen now acts from dead_time on (the previous one until then) for one
  // step: the one whose pressure at the end of that window is the reference. The end
  // pressure rises monotonically with the command, so bisection finds it.
  const double lag = std::min(dead_time_, dt);
  const double start = advance(pressure_, lag, held_);
  double u;
  if (p_ref >= advance(start, dt, limit_)) {
    u = limit_;
  } else if (p_ref <= advance(start, dt, -limit_)) {
    u = -limit_;
  } else {
    double lo = -limit_, hi = limit_;
    for (int k = 0; k < 24; ++k) {  // 10 V / 2^24: far below any valve's resolution
      const double mid = 0.5 * (lo + hi);
      (advance(start, dt, mid) < p_ref ? lo : hi) = mid;
    }
    u = 0.5 * (lo + hi);
  }
  pressure_ = advance(start, dt - lag, u);
  held_ = u;
  time_ += dt;
  return pressure_;
}

std::string trackingGroup(const std::string& cylinder) {
  if (cylinder.rfind("A_WR", 0) == 0) return "wrist";
  if (cylinder.rfind("A_AR", 0) == 0) return "arm";
  return cylinder.size() >= 4 ? cylinder.substr(2, 2) : cylinder;
}

ForceTrackingAudit::ForceTrackingAudit(std::vector<Cylinder> cylinders, double limit, double dead_time, double room)
    : cylinders_(std::move(cylinders)), room_(room) {
  for (const Cylinder& c : cylinders_) {
    if (!(c.spec.bore_area > 0)) throw std::invalid_argument("ForceTrackingAudit: bore area of '" + c.group + "' <= 0");
    floors_.emplace_back(c.spec, limit, dead_time, room);
    ticks_.emplace_back(c.spec, limit, dead_time, room);
    ticks_.back().setHoldCommandPerStep(true);
  }
}

void ForceTrackingAudit::setMinTension(double newtons) {
  if (!(newtons >= 0) || !std::isfinite(newtons))
    throw std::invalid_argument("ForceTrackingAudit: min tension must be finite and >= 0");
  min_tension_ = newtons;
}

void ForceTrackingAudit::setSensor(const SensorParams& params, std::uint64_t seed) {
  floor_sensor_ = std::make_unique<SensorModel>(cylinders_.size(), params, seed);
  tick_sensor_ = std::make_unique<SensorModel>(cylinders_.size(), params, seed + 1);
}

void ForceTrackingAudit::start(const std::vector<double>& pressure) {
  for (std::size_t j = 0; j < cylinders_.size(); ++j) {
    const double p = j < pressure.size() && std::isfinite(pressure[j]) ? pressure[j] : room_;
    floors_[j].reset(p);
    ticks_[j].reset(p);
  }
  given_.assign(cylinders_.size(), std::nan(""));
}

void ForceTrackingAudit::add(double dt, const std::vector<double>& reference, const std::vector<double>& tension,
                             const std::vector<double>& volume, const std::vector<double>& volume_rate,
                             double supply) {
  const std::size_t n = std::min({cylinders_.size(), reference.size(), tension.size(), volume.size(),
                                  volume_rate.size()});
  const std::size_t all = cylinders_.size();
  last_tick_tension_.assign(all, std::nan(""));
  given_.resize(all, std::nan(""));
  // Causal: a controller learns of this sample's reference now, so over the interval that
  // ends now the floors act on the one given at the previous sample (a reference that
  // changes at this sample is met at the next one at the earliest, as by the robot).
  floor_pressure_.resize(all);
  tick_pressure_.resize(all);
  for (std::size_t j = 0; j < all; ++j) {
    const bool usable = j < n && std::isfinite(reference[j]) && std::isfinite(tension[j]);
    floor_pressure_[j] = usable ? floors_[j].step(given_[j], dt, volume[j], volume_rate[j], supply) : floors_[j].pressure();
    tick_pressure_[j] = usable ? ticks_[j].step(given_[j], dt, volume[j], volume_rate[j], supply) : ticks_[j].pressure();
  }
  if (floor_sensor_) {  // the floors seen through the measurement's sensor
    no_length_.assign(all, 0.0);
    floor_sensor_->update(dt, floor_pressure_, no_length_);
    tick_sensor_->update(dt, tick_pressure_, no_length_);
  }
  const std::vector<double>& floor_seen = floor_sensor_ ? floor_sensor_->pressure() : floor_pressure_;
  const std::vector<double>& tick_seen = tick_sensor_ ? tick_sensor_->pressure() : tick_pressure_;
  for (std::size_t j = 0; j < n; ++j) {
    if (!std::isfinite(reference[j]) || !std::isfinite(tension[j])) continue;
    const double area = cylinders_[j].spec.bore_area, want = std::max(0.0, reference[j]);
    // Tension is pull only: a chamber below the room pressure pulls nothing (or the minimum).
    const auto pull = [&](double p) { return std::max(min_tension_, (p - room_) * area); };
    const double floor = pull(floor_seen[j]), tick = pull(tick_seen[j]);
    given_[j] = room_ + want / area;
    last_tick_tension_[j] = tick;
    Sums& s = sums_[cylinders_[j].group];
    s.error += (tension[j] - want) * (tension[j] - want);
    s.floor += (floor - want) * (floor - want);
    s.per_tick += (tick - want) * (tick - want);
    s.max_reference = std::max(s.max_reference, want);
    ++s.samples;
  }
}

std::map<std::string, ForceTrackingAudit::Group> ForceTrackingAudit::groups() const {
  std::map<std::string, Group> out;
  for (const auto& [name, s] : sums_) {
    const double n = static_cast<double>(std::max(1L, s.samples));
    out[name] = {std::sqrt(s.error / n), std::sqrt(s.floor / n), std::sqrt(s.per_tick / n), s.max_reference, s.samples};
  }
  return out;
}

PreviewAudit::PreviewAudit(std::vector<std::string> groups, std::vector<double> leads)
    : groups_(std::move(groups)), leads_(std::move(leads)) {
  for (double lead : leads_)
    if (!(lead >= 0) || !std::isfinite(lead)) throw std::invalid_argument("PreviewAudit: leads must be finite and >= 0");
  for (const std::string& g : groups_) {
    squares_[g].assign(leads_.size(), 0.0);
    counts_[g].assign(leads_.size(), 0);
  }
}

void PreviewAudit::addReference(double t, double dt, std::size_t steps, const std::vector<double>& forces) {
  if (!(dt > 0) || !std::isfinite(t) || steps == 0 || forces.size() != steps * groups_.size()) return;
  history_.push_back({t, dt, steps, forces});
}

void PreviewAudit::addSample(double t, const std::vector<double>& desired) {
  const std::size_t n = std::min(desired.size(), groups_.size());
  const double longest = leads_.empty() ? 0.0 : *std::max_element(leads_.begin(), leads_.end());
  // Keep the newest reference given at or before t - longest and everything after it.
  std::size_t keep = 0;
  while (keep + 1 < history_.size() && history_[keep + 1].t <= t - longest) ++keep;
  history_.erase(history_.begin(), history_.begin() + static_cast<std::ptrdiff_t>(keep));
  for (std::size_t l = 0; l < leads_.size(); ++l) {
    const Given* g = nullptr;  // the newest reference given at or before t - lead
    for (const Given& h : history_)
      if (h.t <= t - leads_[l] + 1e-9) g = &h;
    if (!g) continue;
    const double x = (t - g->t) / g->dt;
    if (x > static_cast<double>(g->steps - 1) + 1e-9) continue;  // beyond that reference's horizon
    const auto k0 = static_cast<std::size_t>(std::max(0.0, x));
    const std::size_t k1 = std::min(k0 + 1, g->steps - 1);
    const double a = std::clamp(x - static_cast<double>(k0), 0.0, 1.0);
    for (std::size_t j = 0; j < n; ++j) {
      if (!std::isfinite(desired[j])) continue;
      const double said = std::max(0.0, (1 - a) * g->forces[k0 * groups_.size() + j] + a * g->forces[k1 * groups_.size() + j]);
      const double e = said - std::max(0.0, desired[j]);
      if (!std::isfinite(e)) continue;
      squares_[groups_[j]][l] += e * e;
      ++counts_[groups_[j]][l];
    }
  }
}

std::map<std::string, std::vector<double>> PreviewAudit::groups() const {
  std::map<std::string, std::vector<double>> out;
  for (const auto& [group, sq] : squares_) {
    std::vector<double>& rmse = out[group];
    for (std::size_t l = 0; l < sq.size(); ++l)
      rmse.push_back(counts_.at(group)[l] > 0 ? std::sqrt(sq[l] / static_cast<double>(counts_.at(group)[l])) : std::nan(""));
  }
  return out;
}

ReferenceStepAudit::ReferenceStepAudit(std::vector<std::string> groups) : groups_(std::move(groups)) {
  for (const auto& g : groups_) histogram_.emplace(g, std::vector<long>(1000, 0));
}

void ReferenceStepAudit::addReference(std::size_t steps, const double* forces, std::size_t size) {
  const std::size_t n = groups_.size();
  if (n == 0 || size != steps * n) return;
  for (std::size_t k = 1; k < steps; ++k)
    for (std::size_t j = 0; j < n; ++j) {
      const double step = std::abs(forces[k * n + j] - forces[(k - 1) * n + j]);
      if (!std::isfinite(step)) continue;
      double& largest = largest_[groups_[j]];
      largest = std::max(largest, step);
      std::vector<long>& bins = histogram_[groups_[j]];
      ++bins[std::min(bins.size() - 1, static_cast<std::size_t>(step / kBin))];
    }
}

double ReferenceStepAudit::largest(const std::string& group) const {
  const auto it = largest_.find(group);
  return it == largest_.end() ? 0.0 : it->second;
}

double ReferenceStepAudit::percentile99(const std::string& group) const {
  const auto it = histogram_.find(group);
  if (it == histogram_.end()) return 0.0;
  long total = 0, seen = 0;
  for (const long count : it->second) total += count;
  if (total == 0) return 0.0;
  // The bin's upper edge, but never above the largest step (which is exact).
  for (std::size_t b = 0; b < it->second.size(); ++b)
    if ((seen += it->second[b]) >= 0.99 * static_cast<double>(total))
      return std::min(static_cast<double>(b + 1) * kBin, largest(group));
  return largest(group);
}

}  // namespace adroit::pneumatics
