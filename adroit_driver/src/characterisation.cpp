#include "adroit_driver/characterisation.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cstdio>
#include <set>
#include <sstream>
#include <stdexcept>

namespace adroit::driver::characterisation {

namespace {

double median(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return kNaN;
  const std::size_t n = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + n, v.end());
  if (v.size() % 2) return v[n];
  return 0.5 * (v[n] + *std::max_element(v.begin(), v.begin() + n));
}

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

// Index of the first sample with t >= time.
std::size_t lowerIndex(const Series& s, double time) {
  return static_cast<std::size_t>(std::lower_bound(s.t.begin(), s.t.end(), time) - s.t.begin());
}

// The first time after `from` at which (v - origin) * sign reaches `level`, interpolated
// linearly between the crossing sample and the one before it; NaN if never before `until`.
double crossing(const Series& s, double from, double until, double origin, double sign, double level) {
  for (std::size_t i = lowerIndex(s, from); i < s.size() && s.t[i] <= until; ++i) {
    const double x = (s.v[i] - origin) * sign;
    if (x < level) continue;
    if (i == 0) return s.t[i];
    const double x0 = (s.v[i - 1] - origin) * sign;
    if (x0 >= level || x == x0) return s.t[i];
    return s.t[i - 1] + (level - x0) / (x - x0) * (s.t[i] - s.t[i - 1]);
  }
  return kNaN;
}

struct ModelData {
  explicit ModelData(const mjModel* m) : data(mj_makeData(m)) {
    if (!data) throw std::runtime_error("MuJoCo could not allocate data");
    mj_forward(m, data);  // the reference posture qpos0
  }
  ~ModelData() { mj_deleteData(data); }
  ModelData(const ModelData&) = delete;
  ModelData& operator=(const ModelData&) = delete;
  mjData* data;
};

std::string fmt(const char* format, double value) {
  if (!std::isfinite(value)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, value);
  return buf;
}
std::string ms(double seconds, const char* format = "%.1f") { return fmt(format, seconds * 1e3); }

}  // namespace

// ------------------------------------------------------------------------------ time series

Baseline baselineOf(const Series& s, double t0, double t1) {
  Baseline b;
  double sum = 0, sum_sq = 0;
  for (std::size_t i = lowerIndex(s, t0); i < s.size() && s.t[i] < t1; ++i) {
    sum += s.v[i];
    sum_sq += s.v[i] * s.v[i];
    ++b.samples;
  }
  if (b.samples == 0) return b;
  b.mean = sum / b.samples;
  b.sigma = b.samples > 1 ? std::sqrt(std::max(0.0, (sum_sq - b.samples * b.mean * b.mean) / (b.samples - 1))) : 0.0;
  return b;
}

double noiseThreshold(const Baseline& b, double k_sigma, double floor) {
  return std::isfinite(b.sigma) ? std::max(k_sigma * b.sigma, floor) : floor;
}

double firstDeparture(const Series& s, double after, double until, const Baseline& b, double threshold, int direction) {
  if (!std::isfinite(b.mean)) return kNaN;
  for (std::size_t i = lowerIndex(s, after); i < s.size() && s.t[i] <= until; ++i) {
    const double d = s.v[i] - b.mean;
    const double x = direction > 0 ? d : direction < 0 ? -d : std::fabs(d);
    if (x > threshold) return s.t[i];
  }
  return kNaN;
}

void OnsetDetector::reset() {
  sum_ = sum_sq_ = 0;
  n_ = 0;
  mean_ = 0;
  threshold_ = kNaN;
  armed_ = fired_ = false;
}

void OnsetDetector::train(double value) {
  if (armed_) return;
  sum_ += value;
  sum_sq_ += value * value;
  ++n_;
}

Baseline OnsetDetector::baseline() const {
  Baseline b;
  b.samples = n_;
  if (n_ > 0) b.mean = sum_ / n_;
  if (n_ > 1) b.sigma = std::sqrt(std::max(0.0, (sum_sq_ - n_ * b.mean * b.mean) / (n_ - 1)));
  return b;
}

bool OnsetDetector::arm() {
  if (n_ < kMinSamples) return false;
  const Baseline b = baseline();
  mean_ = b.mean;
  threshold_ = noiseThreshold(b, k_sigma_, floor_);
  if (threshold_ > max_threshold_) return false;
  armed_ = true;
  fired_ = false;
  return true;
}

bool OnsetDetector::feed(double value) {
  if (!armed_ || fired_) return false;
  if (std::fabs(value - mean_) <= threshold_) return false;
  fired_ = true;
  return true;
}

// ------------------------------------------------------------------------ the robot (model)

std::vector<JointPair> jointPairs(const mjModel* m) {
  ModelData md(m);
  std::vector<JointPair> pairs;
  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] != mjJNT_HINGE || !m->jnt_limited[j]) continue;
    const char* name = mj_id2name(m, mjOBJ_JOINT, j);
    if (!name) continue;
    JointPair p;
    p.joint = name;
    p.flexor = "A_" + p.joint + "_flex";
    p.extensor = "A_" + p.joint + "_ext";
    p.flexor_actuator = mj_name2id(m, mjOBJ_ACTUATOR, p.flexor.c_str());
    p.extensor_actuator = mj_name2id(m, mjOBJ_ACTUATOR, p.extensor.c_str());
    if (p.flexor_actuator < 0 || p.extensor_actuator < 0) continue;
    p.joint_id = j;
    p.qpos = m->jnt_qposadr[j];
    p.dof = m->jnt_dofadr[j];
    p.lower = m->jnt_range[2 * j];
    p.upper = m->jnt_range[2 * j + 1];
    // Generalised force on the joint per newton of each cylinder's pull (actuator force >= 0).
    const double flex = md.data->actuator_moment[p.flexor_actuator * m->nv + p.dof];
    const double ext = md.data->actuator_moment[p.extensor_actuator * m->nv + p.dof];
    if (std::fabs(flex) < 1e-6 || std::fabs(ext) < 1e-6 || flex * ext > 0)
      throw std::runtime_error("cylinders of joint '" + p.joint + "' are not an antagonistic pair (moments " +
                               std::to_string(flex) + ", " + std::to_string(ext) + " m)");
    p.flex_sign = flex > 0 ? 1 : -1;
    p.damping = m->dof_damping[p.dof];
    p.flexor_arm = std::fabs(flex);
    p.extensor_arm = std::fabs(ext);
    auto maxTension = [m](int a) {
      if (m->actuator_ctrllimited[a])
        return m->actuator_ctrlrange[2 * a + 1] * std::fabs(m->actuator_gainprm[a * mjNGAIN]);
      return m->actuator_forcelimited[a] ? m->actuator_forcerange[2 * a + 1] : kNaN;
    };
    p.flexor_max_tension = maxTension(p.flexor_actuator);
    p.extensor_max_tension = maxTension(p.extensor_actuator);
    pairs.push_back(p);
  }
  return pairs;
}

const JointPair& findPair(const std::vector<JointPair>& pairs, const std::string& joint) {
  for (const auto& p : pairs)
    if (p.joint == joint) return p;
  std::string known;
  for (const auto& p : pairs) known += (known.empty() ? "" : ", ") + p.joint;
  throw std::invalid_argument("no cylinder pair drives joint '" + joint + "' (driven: " + known + ")");
}

double dampingBoundTime(const JointPair& p, double excursion, bool flexion) {
  const double torque = flexion ? p.flexor_max_tension * p.flexor_arm : p.extensor_max_tension * p.extensor_arm;
  return std::fabs(excursion) * p.damping / torque;
}

std::string tipSiteFor(const std::string& joint) {
  static const char* const kFingers[] = {"FF", "MF", "RF", "LF", "TH"};
  for (const char* f : kFingers) {
    if (joint.rfind(f, 0) == 0) {
      std::string site = "S_";
      site += static_cast<char>(f[0] + ('a' - 'A'));
      site += static_cast<char>(f[1] + ('a' - 'A'));
      return site + "tip";
    }
  }
  throw std::invalid_argument("joint '" + joint + "' is not a finger joint (FF, MF, RF, LF, TH)");
}

FingertipLever fingertipLever(const mjModel* m, const JointPair& pair, const std::string& tip_site) {
  const int site = mj_name2id(m, mjOBJ_SITE, tip_site.c_str());
  if (site < 0) throw std::invalid_argument("no site '" + tip_site + "' in the model");
  ModelData md(m);
  const mjData* d = md.data;
  FingertipLever out;
  out.site = tip_site;
  const double* axis = d->xaxis + 3 * pair.joint_id;
  const double* anchor = d->xanchor + 3 * pair.joint_id;
  const double* tip = d->site_xpos + 3 * site;
  double r[3], along = 0;
  for (int k = 0; k < 3; ++k) {
    r[k] = tip[k] - anchor[k];
    along += r[k] * axis[k];
  }
  double lever_sq = 0;
  for (int k = 0; k < 3; ++k) lever_sq += (r[k] - along * axis[k]) * (r[k] - along * axis[k]);
  out.lever = std::sqrt(lever_sq);
  out.flexor_arm = std::fabs(d->actuator_moment[pair.flexor_actuator * m->nv + pair.dof]);
  out.extensor_arm = std::fabs(d->actuator_moment[pair.extensor_actuator * m->nv + pair.dof]);
  return out;
}

// ------------------------------------------------------------------------ command limits

void CommandLimits::validate() const {
  require(max_volts > -5.0 && max_volts <= 5.0, "max_volts must be in (-5, 5]");
  require(high_volts <= max_volts, "high_volts must not exceed max_volts");
  require(max_high_time > 0, "max_high_time must be > 0");
  require(hold_volts >= -5.0 && hold_volts <= high_volts, "hold_volts must be in [-5, high_volts]");
}

CommandLimiter::CommandLimiter(std::size_t cylinders, const CommandLimits& limits)
    : limits_(limits), high_since_(cylinders, kNaN), cut_(cylinders, 0) {
  limits_.validate();
}

double CommandLimiter::apply(std::size_t i, double t, double volts) {
  double out = std::isfinite(volts) ? std::clamp(volts, -5.0, limits_.max_volts) : limits_.hold_volts;
  if (out > limits_.high_volts) {
    if (!std::isfinite(high_since_[i])) high_since_[i] = t;
    if (cut_[i] || t - high_since_[i] > limits_.max_high_time) {
      cut_[i] = 1;
      out = limits_.hold_volts;
    }
  } else {
    high_since_[i] = kNaN;
    cut_[i] = 0;
  }
  if (out != volts) ++interventions_;
  return out;
}

// ---------------------------------------------------------------------------- schedules

namespace {
// Full supply is allowed for `seconds` plus a margin of a few command periods.
CommandLimits limitsWithPush(double seconds) {
  CommandLimits l;
  l.max_high_time = seconds + 0.02;
  return l;
}
}  // namespace

void BangBangParams::validate() const {
  require(push_volts > 0 && push_volts <= 5, "push_volts must be in (0, 5]");
  require(release_volts >= -5 && release_volts <= 0, "release_volts must be in [-5, 0]");
  require(hold_volts >= -5 && hold_volts <= std::min(push_volts, 4.0),
          "hold_volts must be in [-5, min(push_volts, 4)]");
  require(max_push_time > 0, "max_push_time must be > 0");
  require(reference_hz > 0 && reference_cycles >= 1, "the reference cycles need reference_hz > 0 and >= 1 cycle");
  require(!frequencies.empty(), "frequencies must not be empty");
  for (std::size_t i = 0; i < frequencies.size(); ++i) {
    require(frequencies[i] > 0 && frequencies[i] <= 100, "frequencies must be in (0, 100] Hz");
    require(i == 0 || frequencies[i] > frequencies[i - 1], "frequencies must increase");
  }
  require(cycles >= 2 && skip_cycles >= 0 && skip_cycles < cycles, "cycles must be >= 2 and > skip_cycles >= 0");
  require(complete_fraction > 0 && complete_fraction <= 1, "complete_fraction must be in (0, 1]");
  require(stop_after_incomplete >= 0, "stop_after_incomplete must be >= 0");
}

CommandLimits BangBangParams::limits() const { return limitsWithPush(max_push_time); }

PairVolts bangBangVolts(const BangBangParams& p, double frequency, double t) {
  const double period = 1.0 / frequency, half = 0.5 * period;
  const double tau = std::fmod(std::max(0.0, t), period);
  PairVolts v;
  if (tau < half) {
    v.flex = tau < p.max_push_time ? p.push_volts : p.hold_volts;
    v.ext = p.release_volts;
  } else {
    v.ext = tau - half < p.max_push_time ? p.push_volts : p.hold_volts;
    v.flex = p.release_volts;
  }
  return v;
}

int bangBangCycles(const BangBangParams& p, double frequency) {
  return std::max({p.cycles, p.skip_cycles + 1, static_cast<int>(std::ceil(p.min_window * frequency - 1e-9))});
}

void SequenceParams::validate() const {
  require(push_volts > 0 && push_volts <= 5, "push_volts must be in (0, 5]");
  require(release_volts >= -5 && release_volts <= 0, "release_volts must be in [-5, 0]");
  require(pre_time > 0 && move_time > 0, "pre_time and move_time must be > 0");
}

CommandLimits SequenceParams::limits() const { return limitsWithPush(std::max(pre_time, move_time)); }

PairVolts sequenceVolts(const SequenceParams& p, double t) {
  PairVolts v;
  if (t < 0 || t >= p.blockTime()) return v;  // idle outside the block
  const bool flexing = t >= p.pre_time && t < p.pre_time + p.move_time;
  v.flex = flexing ? p.push_volts : p.release_volts;
  v.ext = flexing ? p.release_volts : p.push_volts;
  return v;
}

void ReflexParams::validate() const {
  require(push > 0 && push < train && train < pulse, "the reflex trial needs 0 < push < train < pulse");
  require(pulse_time > 0 && pulse_time < search, "pulse_time must be in (0, search)");
  require(trial >= pulse + search + reaction_time, "the trial must hold the search and the reaction");
  require(hold_volts >= -5 && hold_volts <= 4 && release_volts >= -5 && release_volts <= 0 && push_volts > 0 &&
              push_volts <= 5,
          "reflex volts out of range");
}

CommandLimits ReflexParams::limits() const { return limitsWithPush(std::max({push, pulse_time, reaction_time})); }

ReflexVolts reflexVolts(const ReflexParams& p, double t) {
  ReflexVolts v;
  v.reacting.flex = t < p.push ? p.push_volts : p.hold_volts;
  v.reacting.ext = p.release_volts;
  v.disturbed.flex = t >= p.pulse && t < p.pulse + p.pulse_time ? p.push_volts : p.release_volts;
  v.disturbed.ext = t < p.push ? p.push_volts : p.hold_volts;
  return v;
}

std::vector<StepParams::Step> StepParams::steps() const {
  std::vector<Step> out;
  double t = pin + gap + hold;
  for (int side = 0; side < 2; ++side) {
    for (double l : levels) {
      out.push_back(side == 0 ? Step{-5.0, l, t} : Step{5.0, -l, t});
      t += 2 * hold + gap;
    }
  }
  return out;
}

double StepParams::duration() const { return pin + gap + 2 * levels.size() * (2 * hold + gap); }

void StepParams::validate() const {
  require(!levels.empty(), "step levels must not be empty");
  for (double l : levels) require(l > 0 && l <= 5, "step levels must be in (0, 5] V");
  require(hold > 0 && gap > 0 && pin > 0, "step hold, gap and pin must be > 0");
}

CommandLimits StepParams::limits() const { return limitsWithPush(std::max(hold, pin)); }

PairVolts stepVolts(const StepParams& p, double t) {
  PairVolts v;
  v.ext = -5.0;
  if (t < 0 || t >= p.duration()) return v;
  if (t < p.pin + p.gap) {
    v.flex = t < p.pin ? 5.0 : 0.0;
    return v;
  }
  for (const auto& s : p.steps()) {
    if (t < s.time - p.hold || t >= s.time + p.hold + p.gap) continue;
    v.flex = t < s.time ? s.from : t < s.time + p.hold ? s.to : 0.0;
  }
  return v;
}

void ChirpParams::validate() const {
  require(f0 > 0 && f1 >= f0, "the chirp needs 0 < f0 <= f1");
  require(duration > 0 && pin >= 0 && settle >= 0, "chirp duration must be > 0, pin and settle >= 0");
  require(amplitude > 0 && offset - amplitude >= -5 && offset + amplitude <= 4,
          "chirp offset +- amplitude must stay within [-5, 4] V");
}

CommandLimits ChirpParams::limits() const { return limitsWithPush(pin); }

double chirpFrequency(const ChirpParams& p, double t) {
  return p.f0 * std::pow(p.f1 / p.f0, std::clamp(t, 0.0, p.duration) / p.duration);
}

double chirpPhase(const ChirpParams& p, double t) {
  const double k = std::log(p.f1 / p.f0);
  if (k < 1e-12) return 2 * M_PI * p.f0 * t;
  return 2 * M_PI * p.f0 * p.duration / k * std::expm1(k * t / p.duration);
}

double chirpVolts(const ChirpParams& p, double t) {
  if (t < 0 || t > p.duration) return p.offset;
  return p.offset + p.amplitude * std::sin(chirpPhase(p, t));
}

PairVolts chirpPlanVolts(const ChirpParams& p, double t) {
  PairVolts v;
  v.ext = -5.0;
  v.flex = t < p.pin ? 5.0 : chirpVolts(p, t - p.start());
  return v;
}

void ForceParams::validate() const {
  require(hold > 0 && gap > 0 && plateau > 0 && plateau < hold, "force hold, gap > 0 and 0 < plateau < hold");
}

CommandLimits ForceParams::limits() const { return limitsWithPush(hold); }

PairVolts forceVolts(const ForceParams& p, double t) {
  PairVolts v;
  if (t < p.extEnd()) {
    v.flex = t < p.flexEnd() ? 5.0 : -5.0;
    v.ext = t >= p.extStart() ? 5.0 : -5.0;
  }
  return v;
}

// ------------------------------------------------------------------------------ analysis

Stroke measureStroke(const Series& q, double t0, double frequency, int cycles, int skip_cycles, double reference,
                     double complete_fraction) {
  Stroke s;
  s.frequency = frequency;
  const double period = 1.0 / frequency;
  double pp = 0, lo = 0, hi = 0;
  for (int k = skip_cycles; k < cycles; ++k) {
    const double a = t0 + k * period, b = a + period;
    double mn = INFINITY, mx = -INFINITY;
    int n = 0;
    for (std::size_t i = lowerIndex(q, a); i < q.size() && q.t[i] < b; ++i, ++n) {
      mn = std::min(mn, q.v[i]);
      mx = std::max(mx, q.v[i]);
    }
    if (n < 3) continue;  // a cycle without samples (a gap in the data) is not a stroke
    pp += mx - mn;
    lo += mn;
    hi += mx;
    ++s.cycles;
  }
  if (s.cycles == 0) return s;
  s.peak_to_peak = pp / s.cycles;
  s.low = lo / s.cycles;
  s.high = hi / s.cycles;
  s.fraction = s.peak_to_peak / reference;
  s.complete = s.fraction >= complete_fraction;
  return s;
}

void summariseBangBang(BangBangResult* r) {
  r->highest_complete_hz = r->crossing_hz = kNaN;
  std::size_t i = 0;
  while (i < r->strokes.size() && r->strokes[i].complete) r->highest_complete_hz = r->strokes[i++].frequency;
  if (i == 0 || i == r->strokes.size()) return;  // below the lowest or above the highest frequency tested
  const Stroke& a = r->strokes[i - 1];
  const Stroke& b = r->strokes[i];
  if (!std::isfinite(b.fraction) || a.fraction == b.fraction) return;
  r->crossing_hz =
      a.frequency + (r->complete_fraction - a.fraction) / (b.fraction - a.fraction) * (b.frequency - a.frequency);
}

Movement measureMovement(const Series& q, double t_command, double t_end, int direction, double range,
                         double min_excursion) {
  Movement m;
  m.flexion = direction > 0;
  const std::size_t first = lowerIndex(q, t_command);
  if (first >= q.size() || q.t[first] > t_end) return m;
  m.start = first > 0 ? q.v[first - 1] : q.v[first];
  double extreme = m.start;
  for (std::size_t i = first; i < q.size() && q.t[i] <= t_end; ++i)
    extreme = direction > 0 ? std::max(extreme, q.v[i]) : std::min(extreme, q.v[i]);
  m.extreme = extreme;
  m.excursion = (extreme - m.start) * direction;
  m.fraction_of_range = m.excursion / range;
  if (m.excursion < min_excursion) return m;
  m.time = crossing(q, t_command, t_end, m.start, direction, 0.9 * m.excursion) - t_command;
  return m;
}

void summariseSequence(SequenceResult* r) {
  std::set<std::string> joints;
  double total = 0;
  r->moved = 0;
  for (const auto& m : r->moves) {
    joints.insert(m.joint);
    if (!std::isfinite(m.time)) continue;
    total += m.time;
    ++r->moved;
  }
  r->joints = static_cast<int>(joints.size());
  r->total = r->moved > 0 ? total : kNaN;
  r->mean_movement = r->moved > 0 ? total / r->moved : kNaN;
}

void measureReflex(const Series& pressure, const Series& reacting_q, int reaction_direction, const ReflexThresholds& th,
                   ReflexTrial* trial) {
  ReflexTrial& r = *trial;
  r.valid = false;
  if (!std::isfinite(r.t_detect)) {
    r.note = "disturbance not detected";
    return;
  }
  if (r.t_detect < r.t_pulse) {
    r.note = "detected before the disturbance was commanded (noise)";
    return;
  }
  const Baseline bp = baselineOf(pressure, r.t_pulse - th.baseline, r.t_pulse);
  const Baseline bq = baselineOf(reacting_q, r.t_pulse - th.baseline, r.t_pulse);
  r.pressure_threshold = noiseThreshold(bp, th.k_sigma, th.pressure_floor);
  r.motion_threshold = noiseThreshold(bq, th.k_sigma, th.joint_floor);
  r.t_pressure = firstDeparture(pressure, r.t_detect, r.t_detect + th.search, bp, r.pressure_threshold, +1);
  r.t_motion =
      firstDeparture(reacting_q, r.t_detect, r.t_detect + th.search, bq, r.motion_threshold, reaction_direction);
  if (!std::isfinite(r.t_pressure)) {
    r.note = "no pressure change";
  } else if (!std::isfinite(r.t_motion)) {
    r.note = "no motion";
  } else {
    r.valid = true;
    r.note.clear();
  }
}

void summariseReflex(ReflexResult* r) {
  std::vector<double> pressure, motion, detection, reaction, transport;
  r->valid = 0;
  for (const auto& t : r->trials) {
    if (!t.valid) continue;
    ++r->valid;
    pressure.push_back(t.pressureLatency());
    motion.push_back(t.motionLatency());
    detection.push_back(t.t_detect - t.t_pulse);
    reaction.push_back(t.t_command - t.t_receive);
    transport.push_back(t.t_receive - t.t_detect);
  }
  r->pressure_latency = median(pressure);
  r->motion_latency = median(motion);
  r->detection_delay = median(detection);
  r->reaction_delay = median(reaction);
  r->transport_delay = median(transport);
}

StepResponse measureStep(const Series& p, double t_step, double t_end, double k_sigma, double floor) {
  StepResponse s;
  const Baseline before = baselineOf(p, t_step - 0.1, t_step);
  const Baseline after = baselineOf(p, t_end - 0.2 * (t_end - t_step), t_end + 1e-9);
  s.p_initial = before.mean;
  s.p_final = after.mean;
  const double delta = s.p_final - s.p_initial;
  const double threshold = noiseThreshold(before, k_sigma, floor);
  if (!std::isfinite(delta) || std::fabs(delta) <= threshold) return s;  // no response above the noise
  const double sign = delta > 0 ? 1 : -1, size = std::fabs(delta);
  const double t10 = crossing(p, t_step, t_end, s.p_initial, sign, 0.1 * size);
  const double t63 = crossing(p, t_step, t_end, s.p_initial, sign, (1 - std::exp(-1.0)) * size);
  const double t90 = crossing(p, t_step, t_end, s.p_initial, sign, 0.9 * size);
  s.first_change = firstDeparture(p, t_step, t_end, before, threshold, static_cast<int>(sign)) - t_step;
  s.t63 = t63 - t_step;
  s.rise_time = t90 - t10;
  s.time_constant = s.rise_time / std::log(9.0);
  s.dead_time = t10 - t_step - s.time_constant * std::log(10.0 / 9.0);
  return s;
}

std::vector<GainPoint> chirpGains(const Series& y, const ChirpParams& p, double t0, double cycles_per_window) {
  std::vector<GainPoint> out;
  if (y.size() < 16) return out;
  std::vector<double> dt;
  for (std::size_t i = 1; i < y.size(); ++i) dt.push_back(y.t[i] - y.t[i - 1]);
  const double nyquist_limit = 0.45 / median(dt);
  const double k = std::log(p.f1 / p.f0);
  // Time at which the chirp has made n cycles (inverse of chirpPhase / 2 pi).
  auto timeOfCycle = [&](double n) {
    return k < 1e-12 ? n / p.f0 : p.duration / k * std::log1p(n * k / (p.f0 * p.duration));
  };
  const double cycles = chirpPhase(p, p.duration) / (2 * M_PI);
  for (double n = 0; n + cycles_per_window <= cycles + 1e-9; n += cycles_per_window) {
    const double a = timeOfCycle(n), b = timeOfCycle(n + cycles_per_window);
    GainPoint g;
    g.frequency = std::sqrt(chirpFrequency(p, a) * chirpFrequency(p, b));
    if (g.frequency > nyquist_limit) break;
    Eigen::Matrix4d ata = Eigen::Matrix4d::Zero();
    Eigen::Vector4d aty = Eigen::Vector4d::Zero();
    int samples = 0;
    const double mid = 0.5 * (a + b);
    for (std::size_t i = lowerIndex(y, t0 + a); i < y.size() && y.t[i] < t0 + b; ++i) {
      const double t = y.t[i] - t0, phase = chirpPhase(p, t);
      const Eigen::Vector4d row(std::sin(phase), std::cos(phase), 1.0, t - mid);
      ata += row * row.transpose();
      aty += row * y.v[i];
      ++samples;
    }
    if (samples < 8) continue;
    const Eigen::Vector4d c = ata.ldlt().solve(aty);
    g.gain = std::hypot(c[0], c[1]) / p.amplitude;
    g.phase = std::atan2(c[1], c[0]);  // y ~ A sin(phase + this)
    // Continuous from window to window: lags beyond 180 degrees stay lags.
    if (!out.empty())
      g.phase += 2 * M_PI * std::round((out.back().phase - g.phase) / (2 * M_PI));
    out.push_back(g);
  }
  return out;
}

Bandwidth criticalFrequency(const std::vector<GainPoint>& points, double reference_hz, double drop_db) {
  Bandwidth bw;
  if (points.empty()) return bw;
  std::vector<double> low;
  for (const auto& g : points)
    if (g.frequency <= reference_hz) low.push_back(g.gain);
  bw.reference_gain = low.empty() ? points.front().gain : median(low);
  const std::size_t n = points.size();
  std::vector<double> smooth(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t a = i > 0 ? i - 1 : 0, b = std::min(n - 1, i + 1);
    double sum = 0;
    for (std::size_t j = a; j <= b; ++j) sum += points[j].gain;
    smooth[i] = sum / static_cast<double>(b - a + 1);
  }
  auto db = [&](double gain) { return 20 * std::log10(gain / bw.reference_gain); };
  for (std::size_t i = 0; i < n; ++i) {
    if (db(smooth[i]) > -drop_db) continue;
    if (i == 0) {
      bw.critical_hz = points[0].frequency;
      bw.phase_at_critical = points[0].phase;
      return bw;
    }
    const double d0 = db(smooth[i - 1]), d1 = db(smooth[i]);
    const double w = d0 == d1 ? 1.0 : (-drop_db - d0) / (d1 - d0);
    const double l0 = std::log(points[i - 1].frequency), l1 = std::log(points[i].frequency);
    bw.critical_hz = std::exp(l0 + w * (l1 - l0));
    bw.phase_at_critical = points[i - 1].phase + w * (points[i].phase - points[i - 1].phase);
    return bw;
  }
  return bw;
}

void summariseForce(ForceResult* r) {
  r->flex_tip = fingertipForce(r->flex_tension, r->lever.flexor_arm, r->lever.lever);
  r->ext_tip = fingertipForce(r->ext_tension, r->lever.extensor_arm, r->lever.lever);
}

// ------------------------------------------------------------------------------- report

namespace {

struct Row {
  std::string figure, measured, unit, thesis, note;
};

std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string grams(double newtons) { return fmt("%.0f", newtons / kStandardGravity * 1e3); }

std::string ratio(double measured, double thesis) {
  if (!std::isfinite(measured)) return "";
  return fmt("%.2f", measured / thesis) + " x thesis";
}

// The summary rows: one per figure the thesis gives (or, for the step, a figure of the text).
std::vector<Row> summaryRows(const Report& r) {
  std::vector<Row> rows;
  if (r.has_bang_bang) {
    const auto& b = r.bang_bang;
    std::string note = "complete = stroke >= " + fmt("%.0f", 100 * b.complete_fraction) +
                       " % of the slow-cycle range " + fmt("%.3f", b.reference_range) + " rad (model range " +
                       fmt("%.3f", b.model_range) + " rad)";
    if (!std::isfinite(b.highest_complete_hz) && !b.strokes.empty())
      note += "; incomplete already at the lowest frequency tested";
    else if (std::isfinite(b.highest_complete_hz) && !b.strokes.empty() && b.strokes.back().complete)
      note += "; still complete at the highest frequency tested";
    if (std::isfinite(b.bound_stroke_time) && b.bound_stroke_time > 0)
      note += "; damping-limited: the model's joint damping at full supply takes " + ms(b.bound_stroke_time, "%.0f") +
              " ms per stroke, i.e. about " + fmt("%.1f", 0.5 / b.bound_stroke_time) + " Hz";
    rows.push_back({"bang-bang " + b.joint + ": highest frequency with complete strokes",
                    fmt("%.1f", b.highest_complete_hz), "Hz", "about 7 Hz", note});
    rows.push_back({"bang-bang " + b.joint + ": stroke falls through " + fmt("%.0f", 100 * b.complete_fraction) + " %",
                    fmt("%.2f", b.crossing_hz), "Hz", "", "linear between the tested frequencies"});
  }
  if (r.has_sequence) {
    const auto& s = r.sequence;
    rows.push_back({"limit-to-limit sequence, " + std::to_string(s.joints) + " joints (" + std::to_string(s.moved) +
                        " movements timed)",
                    fmt("%.2f", s.total), "s", "2.44 s for 24 joints",
                    "sum of the movement times (to 90 % of each excursion); scaled to 24 joints: " +
                        fmt("%.2f", s.mean_movement * 2 * kThesisSequenceJoints) + " s"});
    double bound = 0;
    int bounded = 0;
    for (const auto& m : s.moves)
      if (std::isfinite(m.time) && std::isfinite(m.bound_time)) bound += m.bound_time, ++bounded;
    rows.push_back({"limit-to-limit: mean movement", ms(s.mean_movement), "ms", "about 70 ms",
                    ratio(s.mean_movement, kThesisMovementSeconds) +
                        (bounded ? "; damping-limited: " + ms(bound / bounded, "%.0f") + " ms for the same excursions"
                                 : std::string())});
  }
  if (r.has_reflex) {
    const auto& x = r.reflex;
    const std::string basis = std::to_string(x.valid) + " of " + std::to_string(x.trials.size()) +
                              " trials; pressure sampled every " + ms(x.pressure_period) + " ms";
    rows.push_back({"reflex: disturbance detected -> first pressure change", ms(x.pressure_latency), "ms", "8 ms",
                    "median, " + basis});
    rows.push_back(
        {"reflex: disturbance detected -> first motion", ms(x.motion_latency), "ms", "29 ms", "median, " + basis});
  }
  if (r.has_step) {
    for (const auto& s : r.step.steps) {
      if (s.from_volts != -5.0 || s.to_volts != 5.0) continue;
      rows.push_back({"valve step -5 -> +5 V (" + r.step.cylinder + "): time constant", ms(s.time_constant), "ms",
                      "around 20 ms (8.1)",
                      "dead time " + ms(s.dead_time) + " ms, 10-90 % rise " + ms(s.rise_time) + " ms"});
    }
  }
  for (const auto& c : r.chirps) {
    rows.push_back({"pneumatic bandwidth (-3 dB), chirp " + fmt("%.2f", c.params.offset) + " +- " +
                        fmt("%.2f", c.params.amplitude) + " V",
                    fmt("%.1f", c.bandwidth.critical_hz), "Hz", "about 25 Hz",
                    std::isfinite(c.bandwidth.critical_hz)
                        ? ratio(c.bandwidth.critical_hz, kThesisCriticalHz)
                        : "no -3 dB point up to " + fmt("%.0f", c.params.f1) + " Hz"});
  }
  if (r.has_force) {
    const auto& f = r.force;
    const std::string how = "estimated: tension x moment arm / lever (" + fmt("%.1f", f.lever.lever * 1e3) + " mm)";
    rows.push_back({"max fingertip force, flexing (" + f.joint + ")", grams(f.flex_tip), "g", "300.5 g",
                    how + ", " + fmt("%.1f", f.flex_tension) + " N tension"});
    rows.push_back({"max fingertip force, extending (" + f.joint + ")", grams(f.ext_tip), "g", "439.4 g",
                    how + ", " + fmt("%.1f", f.ext_tension) + " N tension"});
  }
  return rows;
}

std::string plotLine(const Report& r, const std::string& png) {
  if (std::find(r.plots.begin(), r.plots.end(), png) == r.plots.end()) return "";
  return "![" + png + "](" + png + ")\n\n";
}

}  // namespace

std::string summaryCsv(const Report& report) {
  std::ostringstream out;
  out << "figure,measured,unit,thesis,note\n";
  for (const auto& row : summaryRows(report))
    out << csvField(row.figure) << ',' << row.measured << ',' << row.unit << ',' << csvField(row.thesis) << ','
        << csvField(row.note) << '\n';
  return out.str();
}

std::string reportMarkdown(const Report& r) {
  std::ostringstream o;
  o << "# ADROIT platform characterisation\n\n";
  o << "Acceptance experiments of thesis 3.9 and 5.2.2 on the " << r.driver << " driver (scene " << r.scene << "), "
    << r.started << ", " << (r.quick ? "quick mode" : "full run") << ", " << fmt("%.1f", r.duration)
    << " s, commands at " << fmt("%.0f", r.rate) << " Hz.\n\n";
  if (!r.aborted.empty()) o << "**Aborted:** " << r.aborted << ". The figures below are those measured before.\n\n";
  o << "Each figure is measured as the experiment defines it, next to the thesis value; the experiments are "
       "not tuned to reach the thesis numbers. Where the driver's model differs from the robot of the "
       "thesis, the measured value stands as it is.\n\n";
  o << "Set-up: " << (r.arm_hold.empty() ? std::string("the arm was left as it was") : r.arm_hold) << ". ";
  if (r.touch_checked) {
    if (r.touch_at_rest.empty()) {
      o << "Before the experiments no touch sensor read more than 0.05 N: the hand was free of contact.";
    } else {
      o << "At rest before the experiments these touch sensors read more than 0.05 N:";
      for (std::size_t i = 0; i < r.touch_at_rest.size(); ++i)
        o << (i ? "," : "") << ' ' << r.touch_at_rest[i].first << ' ' << fmt("%.2f", r.touch_at_rest[i].second) << " N";
      o << " (contact with the surroundings or between fingers; the experiments assume the fingers they move free).";
    }
  }
  o << "\n\n| figure | measured | thesis | note |\n|---|---|---|---|\n";
  for (const auto& row : summaryRows(r))
    o << "| " << row.figure << " | " << row.measured << ' ' << row.unit << " | " << row.thesis << " | " << row.note
      << " |\n";
  o << "\nSafety: commands were limited per experiment (full supply only for about a stroke); the limits "
    << (r.limiter_interventions ? "changed " + std::to_string(r.limiter_interventions) + " commands"
                                : std::string("never had to change a command"))
    << ". Experiments run: " << (r.experiments_run.empty() ? std::string("none") : "");
  for (std::size_t i = 0; i < r.experiments_run.size(); ++i) o << (i ? ", " : "") << r.experiments_run[i];
  o << ".\n\n";
  if (!r.plot_error.empty()) o << "Plots: " << r.plot_error << "\n\n";

  if (r.has_bang_bang) {
    const auto& b = r.bang_bang;
    o << "## Open-loop bang-bang, " << b.joint << " (thesis 3.9.2)\n\n";
    o << "Each half period the pulling cylinder gets full supply (for at most the push time, then holds) and its "
         "antagonist is exhausted. The reference range is what the slow cycles reached: "
      << fmt("%.3f", b.reference_low) << " .. " << fmt("%.3f", b.reference_high) << " rad ("
      << fmt("%.3f", b.reference_range) << " rad; the model's limits span " << fmt("%.3f", b.model_range) << " rad).";
    if (std::isfinite(b.bound_stroke_time))
      o << " In the model the joint's viscous damping (" << fmt("%.3g", b.damping)
        << " N m s/rad) holds the speed at full supply to what covers that range in " << ms(b.bound_stroke_time, "%.0f")
        << " ms (no inertia, antagonist or gravity counted), which allows complete strokes up to about "
        << fmt("%.1f", 0.5 / b.bound_stroke_time) << " Hz; the thesis' 7 Hz needs strokes of about 70 ms.";
    o << "\n\n";
    o << plotLine(r, "bang_bang.png");
    o << "| frequency [Hz] | stroke [rad] | of range | low [rad] | high [rad] | cycles | complete |\n"
         "|---|---|---|---|---|---|---|\n";
    for (const auto& s : b.strokes)
      o << "| " << fmt("%g", s.frequency) << " | " << fmt("%.3f", s.peak_to_peak) << " | "
        << fmt("%.0f", 100 * s.fraction) << " % | " << fmt("%.3f", s.low) << " | " << fmt("%.3f", s.high) << " | "
        << s.cycles << " | " << (s.complete ? "yes" : "no") << " |\n";
    o << "\nHighest frequency with complete strokes: " << fmt("%.1f", b.highest_complete_hz)
      << " Hz (thesis: about 7 Hz).\n\n";
  }
  if (r.has_sequence) {
    const auto& s = r.sequence;
    o << "## Limit-to-limit sequence (thesis 3.9.4)\n\n";
    o << "Each joint in turn: an extension to start from, then flexion and extension at full supply with the "
         "antagonist exhausted. Movement time: from the command to 90 % of the excursion made in the window "
         "(the joint's own extreme, whichever limit stopped it); the fraction of the model's range says how "
         "far that extreme is.\n\n";
    o << plotLine(r, "limit_to_limit.png");
    o << "| joint | movement | time [ms] | from [rad] | to [rad] | of model range | damping-limited [ms] |\n"
         "|---|---|---|---|---|---|---|\n";
    for (const auto& m : s.moves)
      o << "| " << m.joint << " | " << (m.flexion ? "flexion" : "extension") << " | " << ms(m.time) << " | "
        << fmt("%.3f", m.start) << " | " << fmt("%.3f", m.extreme) << " | " << fmt("%.0f", 100 * m.fraction_of_range)
        << " % | " << ms(m.bound_time, "%.0f") << " |\n";
    o << "\nDamping-limited: the time the excursion takes when the pulling cylinder's full-supply torque meets "
         "only the model's viscous joint damping (no inertia, antagonist, gravity or coupled joint): where the "
         "measured time is close to it, the model's damping, not the pneumatics, sets the speed.\n";
    o << "\nTotal " << fmt("%.2f", s.total) << " s over " << s.moved << " movements of " << s.joints << " joints, mean "
      << ms(s.mean_movement) << " ms per movement (thesis: 2.44 s for 24 joints, about 70 ms "
      << "per movement).\n\n";
  }
  if (r.has_reflex) {
    const auto& x = r.reflex;
    o << "## Reflex (thesis 3.9.3, fig. 3.8)\n\n";
    o << "Disturbance: a short full-supply pulse on " << x.pulse_cylinder << " (nobody can push a finger in the "
      << "simulation; on the robot a push works the same). The tool detects it in /adroit/joint_states ("
      << x.disturbed_joint << " leaving its noise band), on the subscriber's callback, and at once commands "
      << x.reacting_joint << " to extend (";
    for (std::size_t i = 0; i < x.reacting_cylinders.size(); ++i) o << (i ? ", " : "") << x.reacting_cylinders[i];
    o << "). Latencies count from the detecting sample's stamp (T1 of fig. 3.8): first pressure change of the "
         "filling cylinder beyond its noise, first motion of "
      << x.reacting_joint << " in the commanded direction beyond its noise.\n\n";
    o << plotLine(r, "reflex.png");
    o << "| trial | detected [ms after the pulse] | sample arrived [ms after its stamp] | reaction sent [ms after "
         "arrival] | pressure [ms] | motion [ms] | note |\n|---|---|---|---|---|---|---|\n";
    for (std::size_t i = 0; i < x.trials.size(); ++i) {
      const auto& t = x.trials[i];
      o << "| " << i + 1 << " | " << ms(t.t_detect - t.t_pulse) << " | " << ms(t.t_receive - t.t_detect, "%.2f")
        << " | " << ms(t.t_command - t.t_receive, "%.3f") << " | " << ms(t.pressureLatency()) << " | "
        << ms(t.motionLatency()) << " | " << t.note << " |\n";
    }
    o << "\nMedians: first pressure change " << ms(x.pressure_latency) << " ms (thesis 8 ms), first motion "
      << ms(x.motion_latency) << " ms (thesis 29 ms). Pressure samples come every " << ms(x.pressure_period)
      << " ms: the resolution of the pressure latency. The detecting sample arrived " << ms(x.transport_delay, "%.2f")
      << " ms after its stamp";
    if (x.transport_delay < 0)
      o << " (the simulation driver publishes each state at the start of its step's real-time "
           "interval and stamps it with the interval's end)";
    o << ", and this tool sent the reaction " << ms(x.reaction_delay, "%.3f") << " ms after the sample arrived.\n\n";
  }
  if (r.has_step) {
    const auto& s = r.step;
    o << "## Valve steps (thesis 5.2.2, fig. 5.2)\n\n";
    o << "Steps of " << s.cylinder << " from either extreme, " << s.antagonist << " exhausted, so the tendon holds "
      << s.joint << " at its limit and the chamber's volume stays nearly fixed (joint travel listed). Dead time "
      << "and time constant from the 10-90 % rise of a delayed first-order lag; pressure samples come every "
      << ms(s.sample_period) << " ms, so a time constant well below that is only resolved as that small.\n\n";
    o << plotLine(r, "step.png");
    o << "| step [V] | from [kPa] | to [kPa] | first change [ms] | dead time [ms] | time constant [ms] | 10-90 % "
         "[ms] | joint travel [rad] |\n|---|---|---|---|---|---|---|---|\n";
    for (const auto& x : s.steps)
      o << "| " << fmt("%+.1f", x.from_volts) << " -> " << fmt("%+.1f", x.to_volts) << " | "
        << fmt("%.0f", x.p_initial / 1e3) << " | " << fmt("%.0f", x.p_final / 1e3) << " | " << ms(x.first_change)
        << " | " << ms(x.dead_time) << " | " << ms(x.time_constant) << " | " << ms(x.rise_time) << " | "
        << fmt("%.3f", x.joint_motion) << " |\n";
    o << "\nThesis 8.1: pneumatic time constants around 20 ms.\n\n";
  }
  if (r.has_chirp) {
    o << "## Chirp and pneumatic bandwidth (thesis 5.2.2)\n\n";
    o << "Logarithmic chirps on " << r.chirp_cylinder << " (" << r.chirp_antagonist
      << " exhausted, joint at its limit); gain of the chamber pressure at the chirp's frequency by least squares "
         "over windows of whole cycles, relative to the low-frequency gain. Critical frequency: where the gain "
         "falls 3 dB.\n\n";
    o << plotLine(r, "chirp.png");
    o << "| chirp [V] | band [Hz] | low-frequency gain [kPa/V] | -3 dB [Hz] | phase there [deg] | joint travel [rad] "
         "|\n|---|---|---|---|---|---|\n";
    for (const auto& c : r.chirps)
      o << "| " << fmt("%.2f", c.params.offset) << " +- " << fmt("%.2f", c.params.amplitude) << " | "
        << fmt("%g", c.params.f0) << " .. " << fmt("%g", c.params.f1) << " | "
        << fmt("%.1f", c.bandwidth.reference_gain / 1e3) << " | " << fmt("%.1f", c.bandwidth.critical_hz) << " | "
        << fmt("%.0f", c.bandwidth.phase_at_critical * 180 / M_PI) << " | " << fmt("%.3f", c.joint_motion) << " |\n";
    o << "\nThesis 5.2.2: critical frequency about 25 Hz. The phase includes the transport from command to "
         "sample stamp.\n\n";
  }
  if (r.has_force) {
    const auto& f = r.force;
    o << "## Maximum fingertip force (thesis table 3.3)\n\n";
    o << "Full supply on " << f.flexor << ", then on " << f.extensor << " (the antagonist exhausted). There is no "
      << "force gauge on the driver's interface, so the force is estimated by static torque balance: the "
      << "plateau tension the driver reports (pressure x bore area) times the tendon's moment arm on " << f.joint
      << ", over the lever from the joint axis to " << f.lever.site << ", at the model's reference posture "
      << "(finger straight). ";
    if (f.touch_sensor.empty()) {
      o << "The driver reports no touch sensor at the fingertip.\n\n";
    } else {
      o << "The fingertip's touch sensor " << f.touch_sensor << " read at most " << fmt("%.2f", f.touch_flex)
        << " N while flexing and " << fmt("%.2f", f.touch_ext) << " N while extending";
      if (f.touch_flex > 0.05 || f.touch_ext > 0.05)
        o << ": the tip met something at the end of the stroke (the palm, at full flexion), in a curled posture "
             "whose lever and the other joints' torques differ from the straight finger: shown, not used";
      else
        o << " (nothing under the fingertip)";
      o << ".\n\n";
    }
    o << "| | flexing | extending |\n|---|---|---|\n";
    o << "| plateau pressure [kPa] | " << fmt("%.0f", f.flex_pressure / 1e3) << " | "
      << fmt("%.0f", f.ext_pressure / 1e3) << " |\n";
    o << "| tension [N] | " << fmt("%.2f", f.flex_tension) << " | " << fmt("%.2f", f.ext_tension) << " |\n";
    o << "| moment arm [mm] | " << fmt("%.2f", f.lever.flexor_arm * 1e3) << " | "
      << fmt("%.2f", f.lever.extensor_arm * 1e3) << " |\n";
    o << "| fingertip force [N] | " << fmt("%.2f", f.flex_tip) << " | " << fmt("%.2f", f.ext_tip) << " |\n";
    o << "| fingertip force [g] | " << grams(f.flex_tip) << " | " << grams(f.ext_tip) << " |\n";
    o << "| thesis [g] | 300.5 | 439.4 |\n\n";
    o << "Supply " << fmt("%.0f", f.supply / 1e3) << " kPa, lever " << fmt("%.1f", f.lever.lever * 1e3) << " mm.\n\n";
  }
  o << "Files: summary.csv, one CSV per experiment (the samples: time from the experiment's start, commands "
       "and measurements) and its analysis CSV.\n";
  return o.str();
}

}  // namespace adroit::driver::characterisation
