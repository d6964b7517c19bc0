// Turns the true simulation signals into what the robot's sensors report: noise and
// quantisation per sensor type, sampling rates (500 Hz joint sensing of the palm MCU) and
// sensing delays. ROS-free and copyable by value (random generators and delay lines
// included), so it is part of the simulation state that get/set state saves and restores.
#pragma once

#include <array>
#include <cstddef>
#include <utility>
#include <vector>

#include "adroit_core/normal_noise.h"
#include "adroit_driver/sim_config.h"
#include "adroit_pneumatics/sensor_model.h"

namespace adroit::driver {

// One set of signals, either true (from the simulation) or as sensed.
struct Signals {
  std::vector<double> joint_position, joint_velocity, joint_effort;  // 1-DOF joints
  std::vector<double> pressure;     // Pa absolute, per cylinder
  std::vector<double> length;       // m, piston travel from full retraction
  std::vector<double> length_rate;  // m/s, positive = extending
  std::vector<double> tension;      // N
  double supply_pressure = 0;       // Pa absolute
  std::vector<double> touch;        // N, per touch sensor
  // Free object: position (3), quaternion w x y z (4), linear velocity in the world frame
  // (3), angular velocity in the object frame (3). Unused when the scene has no object.
  std::array<double, 13> object{};
  // Teleop scenes: the hand base's pose in the world, position (3) and quaternion w x y z (4),
  // as simulated (it follows the operator's own motion-capture stream). Unused otherwise.
  std::array<double, 7> base{};
};

// True when every value of `s` is finite (no allocation; what may be published).
bool allFinite(const Signals& s);

// Frames pushed with their sample time; reading at time t gives the newest frame sampled
// at or before t (the oldest one if none is old enough, e.g. right after a restart).
// A ring of frame slots whose storage is reused: once reserve() has made room for the
// frames the line holds at most (delay / update interval + a few) and for their size,
// push() and at() never allocate. A line without enough room grows (allocating), so an
// unreserved line still works, e.g. in tests.
class DelayLine {
 public:
  void reserve(std::size_t frames, std::size_t frame_size);
  void push(double time, const std::vector<double>& frame);
  const std::vector<double>& at(double time);
  void clear() { head_ = size_ = 0; }
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  std::size_t capacity() const { return slots_.size(); }
  void shiftTime(double delta) {
    for (std::size_t k = 0; k < size_; ++k) slot(k).time += delta;
  }

 private:
  struct Slot {
    double time = 0;
    std::vector<double> values;
  };
  Slot& slot(std::size_t k) { return slots_[(head_ + k) % slots_.size()]; }  // k-th oldest
  void resize(std::size_t capacity);

  std::vector<Slot> slots_;
  std::size_t head_ = 0;  // oldest frame
  std::size_t size_ = 0;
};

class SensorPipeline {
 public:
  SensorPipeline() = default;
  // bore_area: per cylinder, to derive tension from the measured pressure in pneumatic
  // mode (what the hardware driver can do: there is no tension sensor).
  // timestep: the shortest interval between updates; it sizes the delay lines at restart()
  // so that update() never allocates (0: the lines grow as needed).
  SensorPipeline(const SensorRealism& params, ActuationMode mode, std::vector<double> bore_area,
                 double atmospheric_pressure, double min_tension, double timestep = 0);

  // Which joints of Signals::joint_position are slide joints (metres: SensorRealism's
  // slide_* figures) rather than hinges (radians); none by default.
  void setSlideJoints(std::vector<char> slide) { slide_ = std::move(slide); }

  // Feeds the true signals at monotonic time `now`, `dt` after the previous update.
  void update(double now, double dt, const Signals& truth);
  // Drops all history (filters, delay lines): from now on the sensors see `truth` (after a
  // reset or a teleport the sensors must not report a transient from the old state).
  void restart(double now, const Signals& truth);

  // Moves every stored sample time by delta (state restored at a later clock).
  void shiftTime(double delta);

  const Signals& sensed() const { return sensed_; }

 private:
  void reserveLines(const Signals& truth);
  void sampleJoints(double now, const Signals& truth);
  void sampleCylinders(double now, double dt, const Signals& truth, bool first);
  void sampleTouchAndObject(double now, const Signals& truth);
  void readDelayed(double now);
  double noise(double std) { return std > 0 ? std * noise_() : 0.0; }

  SensorRealism params_;
  ActuationMode mode_ = ActuationMode::kPneumatic;
  std::vector<double> bore_area_;
  double atmospheric_pressure_ = 0;
  double min_tension_ = 0;
  double timestep_ = 0;
  NormalNoise noise_;
  pneumatics::SensorModel cylinder_model_{1};
  double next_joint_sample_ = 0;
  std::vector<char> slide_;              // per joint: 1 = slide joint
  std::vector<double> previous_length_;  // filtered, for the length rate
  std::vector<double> length_rate_;
  DelayLine joints_, cylinders_, touch_, object_;
  std::vector<double> frame_;  // scratch
  Signals sensed_;
};

}  // namespace adroit::driver
