#include "adroit_driver/sensor_pipeline.h"

#include <algorithm>
#include <cmath>

namespace adroit::driver {

namespace {
constexpr double kTwoPi = 6.283185307179586;
constexpr double kTimeEps = 1e-9;

double quantise(double v, double quantum) { return quantum > 0 ? quantum * std::round(v / quantum) : v; }
}  // namespace

void DelayLine::push(double time, const std::vector<double>& frame) {
  // Reuses the storage of a frame that has left the line: no allocation per step.
  std::vector<double> storage;
  if (!spare_.empty()) {
    storage = std::move(spare_.back());
    spare_.pop_back();
  }
  storage.assign(frame.begin(), frame.end());
  frames_.emplace_back(time, std::move(storage));
}

const std::vector<double>& DelayLine::at(double time) {
  while (frames_.size() >= 2 && frames_[1].first <= time + kTimeEps) {
    spare_.push_back(std::move(frames_.front().second));
    frames_.pop_front();
  }
  return frames_.front().second;
}

SensorPipeline::SensorPipeline(const SensorRealism& params, ActuationMode mode, std::vector<double> bore_area,
                               double atmospheric_pressure, double min_tension)
    : params_(params),
      mode_(mode),
      bore_area_(std::move(bore_area)),
      atmospheric_pressure_(atmospheric_pressure),
      min_tension_(min_tension),
      noise_(params.seed),
      cylinder_model_(bore_area_.size(), params.cylinder, params.seed + 2) {}

void SensorPipeline::restart(double now, const Signals& truth) {
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
}

void SensorPipeline::sampleJoints(double now, const Signals& truth) {
  const double period = 1.0 / params_.joint_rate;
  next_joint_sample_ = std::max(next_joint_sample_ + period, now + 0.5 * period);
  const std::size_t n = truth.joint_position.size();
  frame_.resize(3 * n);
  for (std::size_t j = 0; j < n; ++j) {
    double q = truth.joint_position[j], v = truth.joint_velocity[j];
    if (params_.enabled) {
      q = quantise(q + noise(params_.joint_noise_std), params_.joint_quantum);
      v += noise(params_.joint_velocity_noise_std);
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
