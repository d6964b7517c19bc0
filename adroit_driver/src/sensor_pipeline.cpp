#include "adroit_driver/sensor_pipeline.h"

#include <algorithm>
#include <cmath>

namespace adroit::driver {

namespace {
constexpr double kTwoPi = 6.283185307179586;
constexpr double kTimeEps = 1e-9;
const std::vector<double> kNoFrame;  // what an empty line reads (never, in use: restart() pushes first)

double quantise(double v, double quantum) { return quantum > 0 ? quantum * std::round(v / quantum) : v; }
}  // namespace

bool allFinite(const Signals& s) {
  auto finite = [](const auto& values) {
    return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v); });
  };
  return finite(s.joint_position) && finite(s.joint_velocity) && finite(s.joint_effort) && finite(s.pressure) &&
         finite(s.length) && finite(s.length_rate) && finite(s.tension) && std::isfinite(s.supply_pressure) &&
         finite(s.touch) && finite(s.object) && finite(s.base);
}

void DelayLine::reserve(std::size_t frames, std::size_t frame_size) {
  if (frames > slots_.size()) resize(frames);
  for (Slot& s : slots_) s.values.reserve(frame_size);
}

void DelayLine::resize(std::size_t capacity) {
  // Oldest first from index 0; the slots not in use move along with their storage.
  std::vector<Slot> slots(capacity);
  for (std::size_t k = 0; k < slots_.size(); ++k) slots[k] = std::move(slot(k));
  slots_.swap(slots);
  head_ = 0;
}

void DelayLine::push(double time, const std::vector<double>& frame) {
  if (size_ == slots_.size()) resize(std::max<std::size_t>(4, 2 * slots_.size()));  // not reserved enough
  Slot& s = slot(size_);
  s.time = time;
  s.values.assign(frame.begin(), frame.end());  // within the slot's capacity once reserved
  ++size_;
}

const std::vector<double>& DelayLine::at(double time) {
  if (size_ == 0) return kNoFrame;
  while (size_ >= 2 && slot(1).time <= time + kTimeEps) {
    head_ = (head_ + 1) % slots_.size();
    --size_;
  }
  return slot(0).values;
}

SensorPipeline::SensorPipeline(const SensorRealism& params, ActuationMode mode, std::vector<double> bore_area,
                               double atmospheric_pressure, double min_tension, double timestep)
    : params_(params),
      mode_(mode),
      bore_area_(std::move(bore_area)),
      atmospheric_pressure_(atmospheric_pressure),
      min_tension_(min_tension),
      timestep_(timestep),
      noise_(params.seed),
      cylinder_model_(bore_area_.size(), params.cylinder, params.seed + 2) {}

void SensorPipeline::reserveLines(const Signals& truth) {
  if (!(timestep_ > 0)) return;
  // A line holds the frames of the last `delay` (one per update at most), the newest frame
  // older than that, and the one pushed before the read: 2 more; 1 more for rounding.
  auto frames = [this](double delay) {
    return static_cast<std::size_t>(std::ceil((params_.enabled ? delay : 0.0) / timestep_)) + 3;
  };
  const std::size_t nj = truth.joint_position.size(), nc = truth.pressure.size();
  joints_.reserve(frames(params_.joint_delay), 3 * nj);
  cylinders_.reserve(frames(params_.cylinder_delay), 4 * nc + 1);
  touch_.reserve(frames(params_.touch_delay), truth.touch.size());
  object_.reserve(frames(params_.object_delay), truth.object.size());
  frame_.reserve(std::max({3 * nj, 4 * nc + 1, truth.touch.size(), truth.object.size()}));
}

void SensorPipeline::restart(double now, const Signals& truth) {
  reserveLines(truth);
  joints_.clear();
  cylinders_.clear();
  touch_.clear();
  object_.clear();
  if (params_.enabled) cylinder_model_ = pneumatics::SensorModel(bore_area_.size(), params_.cylinder, noise_.bits());
  next_joint_sample_ = now;
  sampleJoints(now, truth);
  sampleCylinders(now, 0.0, truth, true);
  sampleTouchAndObject(now, truth);
  readDelayed(now);
  sensed_.base = truth.base;  // the simulated base pose, for tf (not a sensor of the robot)
}

void SensorPipeline::shiftTime(double delta) {
  next_joint_sample_ += delta;
  for (DelayLine* line : {&joints_, &cylinders_, &touch_, &object_}) line->shiftTime(delta);
}

void SensorPipeline::update(double now, double dt, const Signals& truth) {
  if (now + kTimeEps >= next_joint_sample_) sampleJoints(now, truth);
  sampleCylinders(now, dt, truth, false);
  sampleTouchAndObject(now, truth);
  readDelayed(now);
  sensed_.base = truth.base;  // the simulated base pose, for tf (not a sensor of the robot)
}

void SensorPipeline::sampleJoints(double now, const Signals& truth) {
  const double period = 1.0 / params_.joint_rate;
  next_joint_sample_ = std::max(next_joint_sample_ + period, now + 0.5 * period);
  const std::size_t n = truth.joint_position.size();
  frame_.resize(3 * n);
  for (std::size_t j = 0; j < n; ++j) {
    double q = truth.joint_position[j], v = truth.joint_velocity[j];
    if (params_.enabled) {
      const bool slide = j < slide_.size() && slide_[j];
      q = quantise(q + noise(slide ? params_.slide_noise_std : params_.joint_noise_std),
                   slide ? params_.slide_quantum : params_.joint_quantum);
      v += noise(slide ? params_.slide_velocity_noise_std : params_.joint_velocity_noise_std);
    }
    frame_[j] = q;
    frame_[n + j] = v;
    frame_[2 * n + j] = truth.joint_effort[j];
  }
  joints_.push(now, frame_);
}

void SensorPipeline::sampleCylinders(double now, double dt, const Signals& truth, bool first) {
  const std::size_t n = truth.pressure.size();
  const std::vector<double>* pressure = &truth.pressure;
  const std::vector<double>* length = &truth.length;
  double supply = truth.supply_pressure;
  if (params_.enabled) {
    cylinder_model_.update(dt > 0 ? dt : 1e-3, truth.pressure, truth.length);
    pressure = &cylinder_model_.pressure();
    length = &cylinder_model_.length();
    supply = quantise(supply + noise(params_.cylinder.pressure_noise_std), params_.cylinder.pressure_quantum);
  }
  // Length rate: derivative of the (filtered) length, low-passed with the length filter,
  // as the hardware driver has to compute it. Without realism it is the true rate.
  if (first || !params_.enabled || dt <= 0) {
    length_rate_ = truth.length_rate;
  } else {
    const double k = -std::expm1(-dt * kTwoPi * params_.cylinder.length_cutoff_hz);
    for (std::size_t i = 0; i < n; ++i)
      length_rate_[i] += k * (((*length)[i] - previous_length_[i]) / dt - length_rate_[i]);
  }
  previous_length_ = *length;
  frame_.resize(4 * n + 1);
  for (std::size_t i = 0; i < n; ++i) {
    frame_[i] = (*pressure)[i];
    frame_[n + i] = (*length)[i];
    frame_[2 * n + i] = length_rate_[i];
    frame_[3 * n + i] = mode_ == ActuationMode::kPneumatic
                            ? std::max(min_tension_, ((*pressure)[i] - atmospheric_pressure_) * bore_area_[i])
                            : truth.tension[i];
  }
  frame_[4 * n] = supply;
  cylinders_.push(now, frame_);
}

void SensorPipeline::sampleTouchAndObject(double now, const Signals& truth) {
  frame_ = truth.touch;
  if (params_.enabled)
    for (double& f : frame_) f = std::max(0.0, f + noise(params_.touch_noise_std));
  touch_.push(now, frame_);
  frame_.assign(truth.object.begin(), truth.object.end());
  if (params_.enabled)
    for (int k = 0; k < 3; ++k) frame_[k] += noise(params_.object_noise_std);
  object_.push(now, frame_);
}

void SensorPipeline::readDelayed(double now) {
  const bool real = params_.enabled;
  {
    const auto& f = joints_.at(now - (real ? params_.joint_delay : 0.0));
    const std::size_t n = f.size() / 3;
    sensed_.joint_position.assign(f.begin(), f.begin() + n);
    sensed_.joint_velocity.assign(f.begin() + n, f.begin() + 2 * n);
    sensed_.joint_effort.assign(f.begin() + 2 * n, f.end());
  }
  {
    const auto& f = cylinders_.at(now - (real ? params_.cylinder_delay : 0.0));
    const std::size_t n = (f.size() - 1) / 4;
    sensed_.pressure.assign(f.begin(), f.begin() + n);
    sensed_.length.assign(f.begin() + n, f.begin() + 2 * n);
    sensed_.length_rate.assign(f.begin() + 2 * n, f.begin() + 3 * n);
    sensed_.tension.assign(f.begin() + 3 * n, f.begin() + 4 * n);
    sensed_.supply_pressure = f[4 * n];
  }
  sensed_.touch = touch_.at(now - (real ? params_.touch_delay : 0.0));
  const auto& o = object_.at(now - (real ? params_.object_delay : 0.0));
  std::copy(o.begin(), o.end(), sensed_.object.begin());
}

}  // namespace adroit::driver
