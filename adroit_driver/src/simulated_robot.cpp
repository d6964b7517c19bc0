#include "adroit_driver/simulated_robot.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include "adroit_core/number_text.h"

namespace adroit::driver {

namespace {
constexpr double kExhaustVolts = -5.0;  // safe state: every valve fully open to exhaust
constexpr double kIdleVolts = 0.0;      // valve centred: the command before any controller

// Plant cylinder for a model cylinder: the catalogue entry of its type with the model's
// bore and stroke.
pneumatics::CylinderSpec plantSpec(const description::Cylinder& c) {
  pneumatics::CylinderSpec spec = pneumatics::cylinderSpec(c.type);
  spec.bore_diameter = c.bore_diameter;
  spec.bore_area = c.bore_area;
  spec.stroke = c.stroke;
  return spec;
}

std::string joinNames(const NameIndex& index) {
  std::string out;
  for (const auto& n : index.names()) out += (out.empty() ? "" : ", ") + n;
  return out;
}

constexpr double kQuaternionTolerance = 1e-6;  // |norm - 1| of a quaternion a reset accepts

using adroit::shortNumber;

bool allFinite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

// The full copy is used only while the editable arrays still describe it: a caller that
// changed qpos/qvel/... in a SimState gets what it asked for.
bool physicsCopyMatches(const mjModel* m, const SimState& s) {
  const mjData* c = s.physics.get();
  return c && c->time == s.physics_time && std::equal(s.qpos.begin(), s.qpos.end(), c->qpos) &&
         std::equal(s.qvel.begin(), s.qvel.end(), c->qvel) && std::equal(s.act.begin(), s.act.end(), c->act) &&
         std::equal(s.qacc_warmstart.begin(), s.qacc_warmstart.end(), c->qacc_warmstart) &&
         static_cast<int>(s.qpos.size()) == m->nq;
}

}  // namespace

SimulatedRobot::SimulatedRobot(const SimConfig& config) : config_(config) {
  const std::string invalid = validate(config_);
  if (!invalid.empty()) throw std::invalid_argument(invalid);
  model_ = loadModelFile(config_.model_path).model;
  mjModel* m = model_.get();
  m->opt.timestep = config_.timestep;
  if (m->opt.integrator == mjINT_IMPLICIT)
    throw std::invalid_argument("model '" + config_.model_path + "': the implicit integrator is not supported");
  data_ = makeData(m);
  actuators_ = NameIndex(m, mjOBJ_ACTUATOR);
  cylinders_ = description::cylinderTable(m);
  if (static_cast<int>(cylinders_.size()) != m->nu)
    throw std::invalid_argument("model '" + config_.model_path + "': every actuator must be a tendon cylinder");

  const std::size_t n = cylinders_.size();
  valve_limits_.lower.assign(n, -5.0);
  valve_limits_.upper.assign(n, 5.0);
  force_limits_.lower.assign(n, 0.0);
  force_limits_.clamp_above = true;
  std::vector<double> bore_area;
  std::vector<pneumatics::CylinderSpec> specs;
  for (const auto& c : cylinders_) {
    force_limits_.upper.push_back(c.max_tension);
    bore_area.push_back(c.bore_area);
    specs.push_back(plantSpec(c));
  }
  if (config_.mode == ActuationMode::kPneumatic) {
    pneumatics::SupplyParams supply;
    supply.nominal_pressure = config_.supply_pressure;
    supply.atmospheric_pressure = description::kAtmosphericPressure;
    plant_ = std::make_unique<pneumatics::PneumaticPlant>(specs, supply, config_.sensors.seed + 1);
  }

  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
    joint_ids_.push_back(j);
    joint_names_.push_back(mj_id2name(m, mjOBJ_JOINT, j));
  }
  for (int s = 0; s < m->nsensor; ++s) {
    if (m->sensor_type[s] != mjSENS_TOUCH) continue;
    touch_adr_.push_back(m->sensor_adr[s]);
    touch_names_.push_back(mj_id2name(m, mjOBJ_SENSOR, s));
  }
  const int object = mj_name2id(m, mjOBJ_BODY, "object");
  if (object >= 0 && m->body_jntnum[object] == 1 && m->jnt_type[m->body_jntadr[object]] == mjJNT_FREE) {
    object_body_ = object;
    object_qpos_ = m->jnt_qposadr[m->body_jntadr[object]];
    object_dof_ = m->jnt_dofadr[m->body_jntadr[object]];
  }

  // Teleop scenes: a free joint named hand_base on the robot's root and the mocap body it is
  // welded to (generate_model.py); both or neither.
  const int base_joint = mj_name2id(m, mjOBJ_JOINT, "hand_base");
  const int base_target = mj_name2id(m, mjOBJ_BODY, "hand_base_target");
  if ((base_joint >= 0) != (base_target >= 0 && m->body_mocapid[base_target] >= 0))
    throw std::invalid_argument("model '" + config_.model_path +
                                "': a free joint 'hand_base' needs a mocap body 'hand_base_target' and vice versa");
  if (base_joint >= 0) {
    if (m->jnt_type[base_joint] != mjJNT_FREE)
      throw std::invalid_argument("model '" + config_.model_path + "': joint 'hand_base' must be a free joint");
    base_qpos_ = m->jnt_qposadr[base_joint];
    base_mocap_ = m->body_mocapid[base_target];
    base_frame_ = mj_id2name(m, mjOBJ_BODY, m->jnt_bodyid[base_joint]);
  }

  checked_.actuator.reserve(n);
  checked_.value.reserve(n);
  seen_.reserve(n);
  const double idle = config_.mode == ActuationMode::kPneumatic ? kIdleVolts : config_.min_tension;
  command_.assign(n, idle);
  applied_command_ = command_;
  last_command_clock_.assign(n, kNeverCommanded);
  never_commanded_ = n;
  travel_.assign(n, 0.0);
  travel_rate_.assign(n, 0.0);
  sensors_ = SensorPipeline(config_.sensors, config_.mode, bore_area, description::kAtmosphericPressure,
                            config_.min_tension, config_.timestep);
  std::vector<char> slide;
  for (int j : joint_ids_) slide.push_back(m->jnt_type[j] == mjJNT_SLIDE);
  sensors_.setSlideJoints(std::move(slide));

  std::string error;
  if (!resetToKeyframe(config_.initial_keyframe, &error)) throw std::invalid_argument("~initial_keyframe: " + error);
}

// ---------------------------------------------------------------------------- commands

CommandResult SimulatedRobot::acceptCommand(const CheckedCommand& checked) {
  CommandResult result = countCommand(checked, safety_.safe_state, &counters_);
  if (!result.applied) return result;
  for (std::size_t k = 0; k < checked.actuator.size(); ++k) {
    const int a = checked.actuator[k];
    if (last_command_clock_[a] == kNeverCommanded) --never_commanded_;
    command_[a] = checked.value[k];
    last_command_clock_[a] = clock_;
  }
  safety_.watchdog_armed = true;
  return result;
}

namespace {
constexpr const char* kValvesInForceMode = "valve command rejected: driver is in force mode";
constexpr const char* kForcesInPneumaticMode = "tendon force command rejected: driver is in pneumatic mode";
}  // namespace

CommandResult SimulatedRobot::commandValves(const std::vector<std::string>& names,
                                            const std::vector<std::uint16_t>& indices,
                                            const std::vector<double>& volts) {
  if (config_.mode != ActuationMode::kPneumatic) return applyValves({});  // counted as the wrong mode
  checkCommand(actuators_, names, indices, volts, valve_limits_, &checked_, &seen_);
  return acceptCommand(checked_);
}

CommandResult SimulatedRobot::commandForces(const std::vector<std::string>& names,
                                            const std::vector<std::uint16_t>& indices,
                                            const std::vector<double>& newtons) {
  if (config_.mode != ActuationMode::kForce) return applyForces({});  // counted as the wrong mode
  checkCommand(actuators_, names, indices, newtons, force_limits_, &checked_, &seen_);
  return acceptCommand(checked_);
}

CheckedCommand SimulatedRobot::checkValves(const std::vector<std::string>& names,
                                           const std::vector<std::uint16_t>& indices,
                                           const std::vector<double>& volts) const {
  if (config_.mode != ActuationMode::kPneumatic) return {CommandVerdict::kBadAddressing, kValvesInForceMode, {}, {}};
  return checkCommand(actuators_, names, indices, volts, valve_limits_);
}

CheckedCommand SimulatedRobot::checkForces(const std::vector<std::string>& names,
                                           const std::vector<std::uint16_t>& indices,
                                           const std::vector<double>& newtons) const {
  if (config_.mode != ActuationMode::kForce) return {CommandVerdict::kBadAddressing, kForcesInPneumaticMode, {}, {}};
  return checkCommand(actuators_, names, indices, newtons, force_limits_);
}

CommandResult SimulatedRobot::applyValves(const CheckedCommand& checked) {
  if (config_.mode != ActuationMode::kPneumatic) {
    ++counters_.rejected_wrong_mode;
    return {CommandVerdict::kBadAddressing, false, kValvesInForceMode};
  }
  return acceptCommand(checked);
}

CommandResult SimulatedRobot::applyForces(const CheckedCommand& checked) {
  if (config_.mode != ActuationMode::kForce) {
    ++counters_.rejected_wrong_mode;
    return {CommandVerdict::kBadAddressing, false, kForcesInPneumaticMode};
  }
  return acceptCommand(checked);
}

// ---------------------------------------------------------------------------- safety

void SimulatedRobot::enterSafeState(SafeCause cause, int cylinder, const FaultSite* fault) {
  SafetyEvent event;
  event.cause = cause;
  event.clock = clock_;
  event.cylinder = cylinder;
  if (cause == SafeCause::kFault && fault) {
    event.fault = fault->source;
    const bool in_physics = fault->source == FaultSource::kQpos || fault->source == FaultSource::kQvel ||
                            fault->source == FaultSource::kQacc;
    if (in_physics) {
      event.index = fault->index;
    } else {
      event.cylinder = fault->index;
    }
  }
  if (!latchSafeState(&event, &safety_, &counters_, &events_)) return;
  if (cause == SafeCause::kFault) safety_.fault = faultText(event);  // formatted once per fault event
}

std::string SimulatedRobot::jointName(int joint) const {
  const char* name = mj_id2name(model_.get(), mjOBJ_JOINT, joint);
  return name ? std::string(name) : "#" + std::to_string(joint);
}

std::string SimulatedRobot::faultText(const SafetyEvent& e) const {
  const mjModel* m = model_.get();
  auto cylinder = [&] {
    return e.cylinder >= 0 && e.cylinder < static_cast<int>(cylinders_.size()) ? "'" + cylinderNames()[e.cylinder] + "'"
                                                                              : std::string("?");
  };
  switch (e.fault) {
    case FaultSource::kQpos: {
      int joint = 0;  // the joint whose coordinates contain the address (addresses grow with the id)
      for (int j = 0; j < m->njnt; ++j)
        if (m->jnt_qposadr[j] <= e.index) joint = j;
      return "bad qpos[" + std::to_string(e.index) + "] (joint '" + jointName(joint) + "')";
    }
    case FaultSource::kQvel:
    case FaultSource::kQacc: {
      const char* array = e.fault == FaultSource::kQvel ? "qvel" : "qacc";
      const int joint = e.index >= 0 && e.index < m->nv ? m->dof_jntid[e.index] : -1;
      return std::string("bad ") + array + "[" + std::to_string(e.index) + "] (joint '" + jointName(joint) + "')";
    }
    case FaultSource::kCommand: return "non-finite command for cylinder " + cylinder();
    case FaultSource::kPressure:
      return e.cylinder < 0 ? std::string("non-finite supply pressure") : "non-finite pressure in cylinder " + cylinder();
    case FaultSource::kTension: return "non-finite tension of cylinder " + cylinder();
    case FaultSource::kNone:
    case FaultSource::kBus:  // the hardware's sources: the simulation never records them
    case FaultSource::kStream:
    case FaultSource::kHeartbeat:
    case FaultSource::kBoard: break;
  }
  return "fault";
}

std::string SimulatedRobot::describe(const SafetyEvent& e) const {
  const std::string when = " (clock " + shortNumber(e.clock) + " s, event " + std::to_string(e.sequence) + ")";
  switch (e.cause) {
    case SafeCause::kEstop: return "e-stop" + when;
    case SafeCause::kWatchdog: {
      const std::string name = e.cylinder >= 0 && e.cylinder < static_cast<int>(cylinders_.size())
                                   ? cylinderNames()[e.cylinder]
                                   : "?";
      return "watchdog: '" + name + "' not commanded for " + shortNumber(config_.watchdog_timeout) + " s" + when;
    }
    case SafeCause::kFault: return "fault: " + faultText(e) + when;
    case SafeCause::kNone: break;
  }
  return "no safety event";
}

void SimulatedRobot::estop() { enterSafeState(SafeCause::kEstop); }

void SimulatedRobot::setEstopInput(bool held) {
  if (held && !safety_.estop_input) enterSafeState(SafeCause::kEstop);
  safety_.estop_input = held;
}

bool SimulatedRobot::release(std::string* why) {
  if (safety_.estop_input) {
    if (why) *why = "refused: the e-stop input is held";
    return false;
  }
  if (safety_.fault_persists) {
    if (why) *why = "refused: the physics fault persists (" + safety_.fault + "); reset the simulation first";
    return false;
  }
  const bool was_safe = safety_.safe_state;
  safety_ = SafetyStatus{};
  // Start again from the idle command; the watchdog re-arms with the next command.
  std::fill(command_.begin(), command_.end(),
            config_.mode == ActuationMode::kPneumatic ? kIdleVolts : config_.min_tension);
  std::fill(last_command_clock_.begin(), last_command_clock_.end(), kNeverCommanded);
  never_commanded_ = last_command_clock_.size();
  if (plant_) plant_->setSupplyEnabled(true);
  if (why) *why = was_safe ? "released" : "not in the safe state";
  return true;
}

// ---------------------------------------------------------------------------- stepping

bool SimulatedRobot::physicsIsBad(FaultSite* fault) const {
  const mjModel* m = model_.get();
  const mjData* d = data_.get();
  for (int i = 0; i < m->nq; ++i)
    if (mju_isBad(d->qpos[i])) return *fault = {FaultSource::kQpos, i}, true;
  for (int i = 0; i < m->nv; ++i)
    if (mju_isBad(d->qvel[i])) return *fault = {FaultSource::kQvel, i}, true;
  return false;
}

bool SimulatedRobot::applyActuation(FaultSite* fault) {
  *fault = FaultSite{};
  const std::size_t n = cylinders_.size();
  mjData* d = data_.get();
  for (std::size_t i = 0; i < n; ++i) {
    const auto& c = cylinders_[i];
    // The chamber grows as the tendon shortens (cylinders.h).
    travel_[i] = description::pistonTravel(c, d->ten_length[c.tendon]);
    travel_rate_[i] = -d->ten_velocity[c.tendon];
  }
  // Commands are checked on arrival, so only a restored state can carry a non-finite one.
  // It must not act (the plant would silently read NaN volts as 0 V): this step already
  // acts as in the safe state, which the fault then latches.
  bool safe = safety_.safe_state;
  for (std::size_t i = 0; i < n && !safe; ++i)
    if (!std::isfinite(command_[i])) *fault = {FaultSource::kCommand, static_cast<int>(i)}, safe = true;
  if (plant_) {
    for (std::size_t i = 0; i < n; ++i) applied_command_[i] = safe ? kExhaustVolts : command_[i];
    plant_->setSupplyEnabled(!safe);
    plant_->step(config_.timestep, applied_command_.data(), travel_.data(), travel_rate_.data());
    // A non-finite pressure or tension out of the plant is a fault; it never reaches ctrl
    // (the cylinder gets the slack-avoiding minimum while the step is refused).
    const auto& pressure = plant_->pressure();
    if (!std::isfinite(plant_->supplyPressure()) && fault->source == FaultSource::kNone)
      *fault = {FaultSource::kPressure, -1};
    for (std::size_t i = 0; i < n; ++i) {
      double tension = plant_->tension(i);
      if (!std::isfinite(pressure[i]) || !std::isfinite(tension)) {
        if (fault->source == FaultSource::kNone)
          *fault = {std::isfinite(pressure[i]) ? FaultSource::kTension : FaultSource::kPressure, static_cast<int>(i)};
        tension = config_.min_tension;
      }
      d->ctrl[cylinders_[i].actuator] = std::clamp(std::max(config_.min_tension, tension), 0.0, cylinders_[i].max_tension);
    }
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      applied_command_[i] = safe ? config_.min_tension : std::max(config_.min_tension, command_[i]);
      d->ctrl[cylinders_[i].actuator] = std::clamp(applied_command_[i], 0.0, cylinders_[i].max_tension);
    }
  }
  return fault->source == FaultSource::kNone;
}

// mj_step split open so that (1) the plant sees the piston travel of the current state and
// (2) a bad state is refused instead of being silently reset: MuJoCo's own checks in
// mj_step reset mjData on bad qpos/qvel/qacc, which would erase the evidence.
bool SimulatedRobot::physicsStep(FaultSite* fault) {
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  if (physicsIsBad(fault)) {
    // Pressures still evolve (the safe state exhausts them); physics stays frozen.
    FaultSite ignored;
    applyActuation(&ignored);
    return false;
  }
  mj_fwdPosition(m, d);
  mj_sensorPos(m, d);
  mj_fwdVelocity(m, d);
  mj_sensorVel(m, d);
  if (!applyActuation(fault)) return false;  // refused: the physics does not advance
  mj_fwdActuation(m, d);
  mj_fwdAcceleration(m, d);
  mj_fwdConstraint(m, d);
  mj_sensorAcc(m, d);
  for (int i = 0; i < m->nv; ++i)
    if (mju_isBad(d->qacc[i])) return *fault = {FaultSource::kQacc, i}, false;
  if (m->opt.integrator == mjINT_RK4) {
    mj_RungeKutta(m, d, 4);
  } else {
    mj_Euler(m, d);
  }
  return true;
}

void SimulatedRobot::step() {
  // Watchdog: every cylinder a controller has commanded must keep being commanded. The
  // stalest one is the cause recorded when it trips.
  if (!safety_.safe_state && safety_.watchdog_armed) {
    int stalest = -1;
    for (std::size_t i = 0; i < last_command_clock_.size(); ++i) {
      const double t = last_command_clock_[i];
      if (t != kNeverCommanded && (stalest < 0 || t < last_command_clock_[stalest])) stalest = static_cast<int>(i);
    }
    if (stalest >= 0) {
      const double age = clock_ - last_command_clock_[stalest];
      command_age_max_ = std::max(command_age_max_, age);
      if (age >= config_.watchdog_timeout - 1e-9) enterSafeState(SafeCause::kWatchdog, stalest);
    }
  }
  if (base_target_set_) moveBaseTarget();
  FaultSite fault;
  const bool ok = physicsStep(&fault);
  safety_.fault_persists = !ok;
  if (!ok) {
    ++counters_.faulted_steps;
    enterSafeState(SafeCause::kFault, -1, &fault);
  }
  clock_ += config_.timestep;
  ++counters_.steps;
  computeTruth();
  sensors_.update(clock_, config_.timestep, truth_);
}

void SimulatedRobot::computeTruth() {
  const mjModel* m = model_.get();
  const mjData* d = data_.get();
  const std::size_t nj = joint_ids_.size(), n = cylinders_.size();
  truth_.joint_position.resize(nj);
  truth_.joint_velocity.resize(nj);
  truth_.joint_effort.resize(nj);
  for (std::size_t k = 0; k < nj; ++k) {
    const int j = joint_ids_[k];
    truth_.joint_position[k] = d->qpos[m->jnt_qposadr[j]];
    truth_.joint_velocity[k] = d->qvel[m->jnt_dofadr[j]];
    truth_.joint_effort[k] = d->qfrc_actuator[m->jnt_dofadr[j]];
  }
  truth_.pressure.resize(n);
  truth_.tension.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double tension = d->ctrl[cylinders_[i].actuator];
    truth_.tension[i] = tension;
    // Force mode has no chamber: report the pressure that would produce the tension.
    truth_.pressure[i] = plant_ ? plant_->pressure()[i] : description::kAtmosphericPressure + tension / cylinders_[i].bore_area;
  }
  truth_.length = travel_;
  truth_.length_rate = travel_rate_;
  truth_.supply_pressure = plant_ ? plant_->supplyPressure()
                                  : (safety_.safe_state ? description::kAtmosphericPressure : config_.supply_pressure);
  truth_.touch.resize(touch_adr_.size());
  for (std::size_t k = 0; k < touch_adr_.size(); ++k) truth_.touch[k] = d->sensordata[touch_adr_[k]];
  if (base_qpos_ >= 0) std::copy(d->qpos + base_qpos_, d->qpos + base_qpos_ + 7, truth_.base.begin());
  if (object_body_ >= 0) {
    std::copy(d->qpos + object_qpos_, d->qpos + object_qpos_ + 7, truth_.object.begin());
    std::copy(d->qvel + object_dof_, d->qvel + object_dof_ + 6, truth_.object.begin() + 7);
  }
}

// ---------------------------------------------------------------------------- state

SimState SimulatedRobot::state() const {
  const mjModel* m = model_.get();
  const mjData* d = data_.get();
  SimState s;
  s.physics = std::shared_ptr<const mjData>(copyData(m, d).release(), DataDeleter());
  s.physics_time = d->time;
  s.qpos.assign(d->qpos, d->qpos + m->nq);
  s.qvel.assign(d->qvel, d->qvel + m->nv);
  s.act.assign(d->act, d->act + m->na);
  s.qacc_warmstart.assign(d->qacc_warmstart, d->qacc_warmstart + m->nv);
  if (plant_) s.plant = plant_->state();
  s.command = command_;
  s.sensors = sensors_;
  s.sensors_clock = clock_;
  return s;
}

void SimulatedRobot::setState(const SimState& s) {
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  if (static_cast<int>(s.qpos.size()) != m->nq || static_cast<int>(s.qvel.size()) != m->nv ||
      static_cast<int>(s.act.size()) != m->na || static_cast<int>(s.qacc_warmstart.size()) != m->nv ||
      s.command.size() != cylinders_.size() || (plant_ && s.plant.pressure.size() != cylinders_.size()))
    throw std::invalid_argument("SimulatedRobot::setState: state does not match model '" + config_.model_path + "'");
  if (plant_) plant_->setState(s.plant);  // validates and may throw before anything changes
  d->time = s.physics_time;
  std::copy(s.qpos.begin(), s.qpos.end(), d->qpos);
  std::copy(s.qvel.begin(), s.qvel.end(), d->qvel);
  std::copy(s.act.begin(), s.act.end(), d->act);
  std::copy(s.qacc_warmstart.begin(), s.qacc_warmstart.end(), d->qacc_warmstart);
  command_ = s.command;
  sensors_ = s.sensors;
  // The sensors' delay lines are stamped with the clock of capture; time never goes back,
  // so shift them to now.
  sensors_.shiftTime(clock_ - s.sensors_clock);
  if (physicsCopyMatches(m, s)) {
    mj_copyData(d, m, s.physics.get());  // everything, intermediates included: exact replay
  } else {
    mj_forward(m, d);
    // mj_forward's constraint solver overwrites the warm start; the next step must start
    // from the saved one to replay exactly.
    std::copy(s.qacc_warmstart.begin(), s.qacc_warmstart.end(), d->qacc_warmstart);
  }
  for (std::size_t i = 0; i < cylinders_.size(); ++i) {
    travel_[i] = description::pistonTravel(cylinders_[i], d->ten_length[cylinders_[i].tendon]);
    travel_rate_[i] = -d->ten_velocity[cylinders_[i].tendon];
  }
  computeTruth();
  safety_.fault_persists = false;
}

void SimulatedRobot::afterTeleport() {
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  // Tensions for the new state so derived data (and the published efforts) match it.
  mj_fwdPosition(m, d);
  mj_fwdVelocity(m, d);
  for (std::size_t i = 0; i < cylinders_.size(); ++i) {
    travel_[i] = description::pistonTravel(cylinders_[i], d->ten_length[cylinders_[i].tendon]);
    travel_rate_[i] = -d->ten_velocity[cylinders_[i].tendon];
    const double tension = plant_ ? plant_->tension(i) : command_[i];
    d->ctrl[cylinders_[i].actuator] = std::clamp(std::max(config_.min_tension, tension), 0.0, cylinders_[i].max_tension);
  }
  mj_forward(m, d);
  computeTruth();
  sensors_.restart(clock_, truth_);
  safety_.fault_persists = false;
}

namespace {
// Plant state with every chamber at `pressure`, the supply at its level, and the delay
// line holding `volts` as if it had always been commanded.
pneumatics::PlantState settledPlant(const pneumatics::PneumaticPlant& plant, const std::vector<double>& pressure,
                                    const std::vector<double>& volts, bool safe) {
  pneumatics::PlantState s = plant.state();
  s.pressure = pressure;
  s.supply_pressure = safe ? plant.atmosphericPressure() : plant.supplyParams().nominal_pressure;
  s.supply_enabled = !safe;
  s.history_time.assign(1, s.time - 1.0);
  s.history_volts = volts;
  return s;
}
}  // namespace

bool SimulatedRobot::resetToKeyframe(const std::string& keyframe, std::string* error) {
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  if (keyframe.empty()) {
    if (m->nkey > 0) mj_resetDataKeyframe(m, d, 0); else mj_resetData(m, d);
  } else {
    const int key = mj_name2id(m, mjOBJ_KEY, keyframe.c_str());
    if (key < 0) {
      if (error) *error = "unknown keyframe '" + keyframe + "' (known: " + joinNames(NameIndex(m, mjOBJ_KEY)) + ")";
      return false;
    }
    mj_resetDataKeyframe(m, d, key);
  }
  if (plant_) {
    const std::vector<double> atmosphere(cylinders_.size(), plant_->atmosphericPressure());
    const std::vector<double> volts = safety_.safe_state ? std::vector<double>(cylinders_.size(), kExhaustVolts) : command_;
    plant_->setState(settledPlant(*plant_, atmosphere, volts, safety_.safe_state));
  }
  holdBaseWhereItIs();
  afterTeleport();
  return true;
}

// Finite but absurd states (qpos 1e300, a joint far outside its range, a quaternion of
// norm 2, qvel 1e6) would be accepted and then fault in the next step; refuse them here,
// naming the joint.
bool SimulatedRobot::checkResetState(const std::vector<double>& qpos, const std::vector<double>& qvel,
                                     std::string* error) const {
  const mjModel* m = model_.get();
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  auto unitQuaternion = [](const double* q) {
    const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    return std::abs(norm - 1.0) <= kQuaternionTolerance ? -1.0 : norm;  // -1: fine, else the norm
  };
  for (int j = 0; j < m->njnt && !qpos.empty(); ++j) {
    const double* q = qpos.data() + m->jnt_qposadr[j];
    auto name = [&] { return "joint '" + jointName(j) + "'"; };
    switch (m->jnt_type[j]) {
      case mjJNT_FREE: {
        const double distance = std::hypot(q[0], q[1], q[2]);  // no overflow to inf for 1e300
        if (distance > config_.max_reset_distance)
          return fail(name() + " position is " + shortNumber(distance) + " m from the origin, beyond max_reset_distance " +
                      shortNumber(config_.max_reset_distance) + " m");
        const double norm = unitQuaternion(q + 3);
        if (norm >= 0) return fail(name() + " quaternion has norm " + shortNumber(norm) + ", must be 1");
        break;
      }
      case mjJNT_BALL: {
        const double norm = unitQuaternion(q);
        if (norm >= 0) return fail(name() + " quaternion has norm " + shortNumber(norm) + ", must be 1");
        break;
      }
      default: {  // hinge or slide
        const double lo = m->jnt_range[2 * j], hi = m->jnt_range[2 * j + 1];
        const double margin = config_.reset_range_margin * (hi - lo);  // soft limits (sim_config.h)
        const char* unit = m->jnt_type[j] == mjJNT_HINGE ? " rad" : " m";
        if (m->jnt_limited[j] && !(q[0] >= lo - margin && q[0] <= hi + margin))
          return fail(name() + " qpos " + shortNumber(q[0]) + unit + " outside its range [" + shortNumber(lo) + ", " + shortNumber(hi) +
                      "]" + unit + " (by more than reset_range_margin " + shortNumber(config_.reset_range_margin) +
                      " of it)");
        if (!(std::abs(q[0]) <= mjMAXVAL))  // unlimited: at least what MuJoCo's own check accepts
          return fail(name() + " qpos " + shortNumber(q[0]) + unit + " beyond MuJoCo's bound " + shortNumber(mjMAXVAL));
      }
    }
  }
  for (int i = 0; i < m->nv && !qvel.empty(); ++i)
    if (!(std::abs(qvel[i]) <= config_.max_reset_velocity))
      return fail("joint '" + jointName(m->dof_jntid[i]) + "' qvel[" + std::to_string(i) + "] " + shortNumber(qvel[i]) +
                  " beyond max_reset_velocity " + shortNumber(config_.max_reset_velocity) + " (rad/s or m/s)");
  return true;
}

bool SimulatedRobot::resetToState(const std::vector<double>& qpos, const std::vector<double>& qvel,
                                  const std::vector<double>& pressure, std::string* error) {
  const mjModel* m = model_.get();
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  if (!qpos.empty() && static_cast<int>(qpos.size()) != m->nq)
    return fail("qpos has " + std::to_string(qpos.size()) + " values, the model needs " + std::to_string(m->nq));
  if (!qvel.empty() && static_cast<int>(qvel.size()) != m->nv)
    return fail("qvel has " + std::to_string(qvel.size()) + " values, the model needs " + std::to_string(m->nv));
  if (!pressure.empty() && !plant_) return fail("pressure given but the driver is in force mode (no chambers)");
  if (!pressure.empty() && pressure.size() != cylinders_.size())
    return fail("pressure has " + std::to_string(pressure.size()) + " values, the model has " +
                std::to_string(cylinders_.size()) + " cylinders");
  if (!allFinite(qpos) || !allFinite(qvel) || !allFinite(pressure)) return fail("state contains NaN or Inf");
  for (double p : pressure)
    if (p < 1e3 || p > 2e6) return fail("pressure " + shortNumber(p) + " Pa outside [1e3, 2e6] Pa absolute");
  if (!checkResetState(qpos, qvel, error)) return false;
  std::string ignored;
  resetToKeyframe("", &ignored);  // model default for whatever is not given
  mjData* d = data_.get();
  if (!qpos.empty()) std::copy(qpos.begin(), qpos.end(), d->qpos);
  if (!qvel.empty()) std::copy(qvel.begin(), qvel.end(), d->qvel);
  if (plant_ && !pressure.empty()) {
    const std::vector<double> volts = safety_.safe_state ? std::vector<double>(cylinders_.size(), kExhaustVolts) : command_;
    plant_->setState(settledPlant(*plant_, pressure, volts, safety_.safe_state));
  }
  holdBaseWhereItIs();
  afterTeleport();
  return true;
}

bool SimulatedRobot::checkPose(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                               double* norm, std::string* error) const {
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  for (double v : position) if (!std::isfinite(v)) return fail("position contains NaN or Inf");
  *norm = 0;
  for (double v : quaternion) {
    if (!std::isfinite(v)) return fail("orientation contains NaN or Inf");
    *norm += v * v;
  }
  *norm = std::sqrt(*norm);
  if (*norm < 1e-6) return fail("orientation is not a quaternion (norm ~ 0)");
  const double distance = std::hypot(position[0], position[1], position[2]);
  if (distance > config_.max_reset_distance)
    return fail("position is " + shortNumber(distance) + " m from the origin, beyond max_reset_distance " +
                shortNumber(config_.max_reset_distance) + " m");
  return true;
}

bool SimulatedRobot::setBaseTarget(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                                   std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  if (base_mocap_ < 0) return fail("the scene has no free hand base (teleop scenes: teleop_tube, teleop_ball)");
  double norm = 0;
  if (!checkPose(position, quaternion, &norm, error)) return false;
  for (int k = 0; k < 3; ++k) base_target_[k] = position[k];
  for (int k = 0; k < 4; ++k) base_target_[3 + k] = quaternion[k] / norm;
  base_target_set_ = true;
  return true;
}

void SimulatedRobot::holdBaseWhereItIs() {
  if (base_mocap_ < 0) return;
  // The weld's reference is the identity: the mocap body at the base's pose holds it there
  // until a new target comes.
  mjData* d = data_.get();
  mju_copy3(d->mocap_pos + 3 * base_mocap_, d->qpos + base_qpos_);
  mju_copy4(d->mocap_quat + 4 * base_mocap_, d->qpos + base_qpos_ + 3);
  base_target_set_ = false;
}

void SimulatedRobot::moveBaseTarget() {
  mjData* d = data_.get();
  double* pos = d->mocap_pos + 3 * base_mocap_;
  double* quat = d->mocap_quat + 4 * base_mocap_;
  // Translation: straight towards the target, at most max_base_speed * dt per step.
  double delta[3], length = 0;
  for (int k = 0; k < 3; ++k) {
    delta[k] = base_target_[k] - pos[k];
    length += delta[k] * delta[k];
  }
  length = std::sqrt(length);
  const double max_step = config_.max_base_speed * config_.timestep;
  const double scale = length > max_step ? max_step / length : 1.0;
  for (int k = 0; k < 3; ++k) pos[k] += scale * delta[k];
  // Rotation: about the axis of the remaining rotation, at most max_base_angular_speed * dt.
  double inverse[4], difference[4], velocity[3];
  mju_negQuat(inverse, quat);
  mju_mulQuat(difference, base_target_.data() + 3, inverse);  // target = difference * current
  mju_quat2Vel(velocity, difference, 1.0);                      // axis * angle (world frame)
  const double angle = mju_norm3(velocity);
  const double max_angle = config_.max_base_angular_speed * config_.timestep;
  if (angle > max_angle) mju_scl3(velocity, velocity, max_angle / angle);
  if (angle > 1e-12) {
    double turn[4];
    mju_normalize3(velocity);
    mju_axisAngle2Quat(turn, velocity, std::min(angle, max_angle));
    double moved[4];
    mju_mulQuat(moved, turn, quat);
    mju_normalize4(moved);
    mju_copy4(quat, moved);
  }
}

bool SimulatedRobot::setObjectPose(const std::array<double, 3>& position, const std::array<double, 4>& quaternion,
                                   const std::array<double, 3>& linear, const std::array<double, 3>& angular,
                                   std::string* error) {
  auto fail = [&](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  if (object_body_ < 0) return fail("the scene has no free body named 'object'");
  double norm = 0;
  if (!checkPose(position, quaternion, &norm, error)) return false;
  for (double v : linear) if (!std::isfinite(v)) return fail("linear velocity contains NaN or Inf");
  for (double v : angular) if (!std::isfinite(v)) return fail("angular velocity contains NaN or Inf");
  for (const auto* velocity : {&linear, &angular})
    for (double v : *velocity)
      if (std::abs(v) > config_.max_reset_velocity)
        return fail(std::string(velocity == &linear ? "linear" : "angular") + " velocity component " + shortNumber(v) +
                    " beyond max_reset_velocity " + shortNumber(config_.max_reset_velocity) + " (m/s or rad/s)");
  mjData* d = data_.get();
  double* q = d->qpos + object_qpos_;
  for (int k = 0; k < 3; ++k) q[k] = position[k];
  for (int k = 0; k < 4; ++k) q[3 + k] = quaternion[k] / norm;
  // Free joint velocity: linear in the world frame, angular in the body frame.
  double rot[9], angular_body[3];
  mju_quat2Mat(rot, q + 3);
  mju_rotVecMatT(angular_body, angular.data(), rot);
  double* v = d->qvel + object_dof_;
  for (int k = 0; k < 3; ++k) {
    v[k] = linear[k];
    v[3 + k] = angular_body[k];
  }
  afterTeleport();
  return true;
}

}  // namespace adroit::driver
