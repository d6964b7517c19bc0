// Platform characterisation (issue 15, item 6): the acceptance experiments of thesis 3.9 and
// 5.2.2 as command schedules, and the analysis of what the robot did during them. ROS-free: the
// node adroit_characterise (nodes/characterise_node.cpp) runs the schedules on whichever driver is
// up and hands the recorded samples to the functions here.
//
// Experiments (all open loop except the reflex):
//   bang_bang       one joint's flexor and extensor alternately at full supply, at increasing
//                   frequency, until the strokes stay incomplete (thesis 3.9.2: about 7 Hz);
//   limit_to_limit  every joint flexed and extended limit to limit, one at a time (3.9.4:
//                   2.44 s for 24 joints, about 70 ms per movement);
//   reflex          a disturbance of one finger, detected in its joint angle, answered by
//                   extending another (3.9.3: 8 ms to the first pressure change, 29 ms to motion);
//   step, chirp     valve steps from either extreme and a logarithmic chirp on one cylinder held
//                   against its joint's limit (5.2.2: critical frequency about 25 Hz);
//   force           full supply on one finger's flexor, then its extensor: the fingertip force
//                   by static torque balance (table 3.3: 300.5 g flexing, 439.4 g extending).
// Times are seconds on one clock (the node uses the messages' stamps relative to the run's start).
#pragma once

#include <mujoco/mujoco.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace adroit::driver::characterisation {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kStandardGravity = 9.80665;  // m/s^2: the thesis gives forces in grams

// The thesis figures the report compares against.
constexpr double kThesisBangBangHz = 7.0;        // 3.9.2
constexpr double kThesisSequenceSeconds = 2.44;  // 3.9.4, for kThesisSequenceJoints
constexpr int kThesisSequenceJoints = 24;
constexpr double kThesisMovementSeconds = 0.070;  // 3.9.4, each movement
constexpr double kThesisReflexPressure = 0.008;   // 3.9.3, disturbance -> first pressure change
constexpr double kThesisReflexMotion = 0.029;     // 3.9.3, disturbance -> motion
constexpr double kThesisCriticalHz = 25.0;        // 5.2.2, chirp of the muscle assembly
constexpr double kThesisFlexForceGrams = 300.5;   // table 3.3, index fingertip, flexing
constexpr double kThesisExtForceGrams = 439.4;    // table 3.3, index fingertip, extending

// ------------------------------------------------------------------------------ time series

struct Series {
  std::vector<double> t, v;
  void add(double time, double value) {
    t.push_back(time);
    v.push_back(value);
  }
  std::size_t size() const { return t.size(); }
  bool empty() const { return t.empty(); }
};

struct Baseline {
  double mean = kNaN, sigma = kNaN;
  int samples = 0;
};
// Mean and standard deviation of the samples with t in [t0, t1).
Baseline baselineOf(const Series& s, double t0, double t1);
// max(k_sigma * sigma, floor): a departure smaller than this is noise.
double noiseThreshold(const Baseline& b, double k_sigma, double floor);
// Time of the first sample in [after, until] whose departure from the baseline exceeds
// `threshold` in `direction` (+1 up, -1 down, 0 either); NaN when there is none.
double firstDeparture(const Series& s, double after, double until, const Baseline& b, double threshold,
                      int direction = 0);

// Online onset detection, as the node runs it on every joint sample: trains a noise baseline,
// is armed, then fires once on the first sample departing by more than max(k sigma, floor).
class OnsetDetector {
 public:
  // A baseline whose threshold would exceed max_threshold is no rest: arm() refuses it.
  OnsetDetector(double k_sigma = 5.0, double floor = 0.01, double max_threshold = INFINITY)
      : k_sigma_(k_sigma), floor_(floor), max_threshold_(max_threshold) {}
  void reset();
  void train(double value);
  // Freezes the baseline. False (and stays unarmed) with fewer than kMinSamples trained or a
  // threshold above max_threshold (the joint was moving).
  bool arm();
  // True exactly once: on the first departing sample after arm().
  bool feed(double value);
  bool armed() const { return armed_; }
  bool fired() const { return fired_; }
  double threshold() const { return threshold_; }
  Baseline baseline() const;
  static constexpr int kMinSamples = 10;

 private:
  double k_sigma_, floor_, max_threshold_;
  double sum_ = 0, sum_sq_ = 0;
  int n_ = 0;
  double mean_ = 0, threshold_ = kNaN;
  bool armed_ = false, fired_ = false;
};

// ------------------------------------------------------------------------ the robot (model)

// A joint driven by an antagonistic pair of cylinders A_<joint>_flex / A_<joint>_ext.
struct JointPair {
  std::string joint, flexor, extensor;
  int joint_id = -1, qpos = -1, dof = -1, flexor_actuator = -1, extensor_actuator = -1;
  double lower = 0, upper = 0;                                    // rad, the model's limits
  int flex_sign = 1;                                              // +1 when the flexor drives the joint towards `upper`
  double damping = 0;                                             // N m s/rad, the model's joint damping
  double flexor_arm = kNaN, extensor_arm = kNaN;                  // m, |moment arm| at the reference posture
  double flexor_max_tension = kNaN, extensor_max_tension = kNaN;  // N, the cylinders' full-supply tension
  double range() const { return upper - lower; }
  double flexLimit() const { return flex_sign > 0 ? upper : lower; }
  double extLimit() const { return flex_sign > 0 ? lower : upper; }
};

// Every limited hinge joint with a cylinder pair, in the model's joint order; the direction of
// each flexor comes from its actuator's moment at the reference posture. Throws
// std::runtime_error when a pair pulls both ways or not at all.
std::vector<JointPair> jointPairs(const mjModel* model);
// Throws std::invalid_argument naming the joint and the driven ones.
const JointPair& findPair(const std::vector<JointPair>& pairs, const std::string& joint);

// The time the model's viscous joint damping alone allows for `excursion` at the full-supply
// torque of the pulling cylinder on that joint (no inertia, antagonist, gravity or coupled
// joints): an estimate of the model's movement time where damping, not the pneumatics, rules.
double dampingBoundTime(const JointPair& pair, double excursion, bool flexion);

// Static torque balance at a fingertip: a cylinder tension T acting through its tendon's moment
// arm r on the joint gives the torque T r, held by a force F = T r / L at the tip, L the distance
// of the tip from the joint axis. At the model's reference posture (fingers straight).
struct FingertipLever {
  std::string site;
  double lever = kNaN;         // m, tip site to the joint axis, perpendicular
  double flexor_arm = kNaN;    // m, |moment arm| of the flexor's tendon on the joint
  double extensor_arm = kNaN;  // m
};
// "S_fftip" for FF*, MF, RF, LF, TH joints; throws std::invalid_argument for other joints.
std::string tipSiteFor(const std::string& joint);
FingertipLever fingertipLever(const mjModel* model, const JointPair& pair, const std::string& tip_site);
inline double fingertipForce(double tension, double moment_arm, double lever) { return tension * moment_arm / lever; }

// ------------------------------------------------------------------------ command limits

// Safety limits of one experiment: commands within [-5, max_volts]; a cylinder held above
// high_volts for longer than max_high_time in a row is held at hold_volts instead until its
// requested command falls back to high_volts or below (full supply only as long as a stroke).
struct CommandLimits {
  double max_volts = 5.0;
  double high_volts = 4.0;
  double max_high_time = 0.3;
  double hold_volts = 0.0;
  void validate() const;  // throws std::invalid_argument naming the field
};

class CommandLimiter {
 public:
  CommandLimiter(std::size_t cylinders, const CommandLimits& limits);
  // The command to send for cylinder i at time t (non-decreasing per cylinder).
  double apply(std::size_t i, double t, double volts);
  std::uint64_t interventions() const { return interventions_; }  // commands changed by the limits
  const CommandLimits& limits() const { return limits_; }

 private:
  CommandLimits limits_;
  std::vector<double> high_since_;  // NaN: not above high_volts
  std::vector<char> cut_;
  std::uint64_t interventions_ = 0;
};

// ---------------------------------------------------------------------------- schedules

struct PairVolts {
  double flex = 0, ext = 0;
};

// Every experiment's schedule gives the commands of one cylinder pair (two for the reflex) as a
// function of the time since its start, and its safety limits, which the schedule respects (the
// limiter in the node is the net under it).

struct BangBangParams {
  double push_volts = 5.0;      // the cylinder pulling this half period
  double release_volts = -5.0;  // its antagonist: exhausted
  double hold_volts = 0.0;      // the puller after max_push_time
  double max_push_time = 0.3;   // s at push_volts per half period: longer than a stroke
  double reference_hz = 1.0;    // the slow cycles whose extremes are the limit-to-limit range
  int reference_cycles = 2;
  std::vector<double> frequencies{1, 1.5, 2, 2.5, 3, 3.5, 4, 5, 6, 7, 8, 9, 10, 12, 14, 16, 20};  // Hz, increasing
  int cycles = 6;                                                                                 // per frequency ...
  int skip_cycles = 1;             // ... of which the first are the transient
  double min_window = 0.5;         // s per frequency at least (whole cycles)
  double complete_fraction = 0.9;  // a stroke of at least this fraction of the range is complete
  int stop_after_incomplete = 2;   // stop the sweep after this many incomplete frequencies in a row (0: never)
  void validate() const;
  CommandLimits limits() const;
};
// Commands at time t of a window at `frequency` (t = 0 at its start): flexion first.
PairVolts bangBangVolts(const BangBangParams& p, double frequency, double t);
// The number of whole cycles run at `frequency` (at least cycles, at least min_window).
int bangBangCycles(const BangBangParams& p, double frequency);

// Limit-to-limit sequence, per joint: an unmeasured extension (pre_time), then the measured
// flexion and extension (move_time each) at full supply, the antagonist exhausted.
struct SequenceParams {
  std::vector<std::string> joints;  // empty: every hand joint (not the arm)
  double push_volts = 5.0, release_volts = -5.0;
  double pre_time = 0.4, move_time = 0.4;
  double blockTime() const { return pre_time + 2 * move_time; }
  void validate() const;
  CommandLimits limits() const;
};
PairVolts sequenceVolts(const SequenceParams& p, double t);  // t from the joint's block start

// One reflex trial: the reacting finger is flexed (push) and then held by its flexor at hold
// volts against its exhausted extensor; the disturbed finger is extended (push) and then rests
// so, its flexor exhausted and its extensor at hold volts; the detector learns the disturbed joint's noise from
// `train` on and is armed at `pulse`, when the disturbed flexor gets a full-supply pulse. The
// reaction (reacting extensor full supply, flexor exhausted) is the detector's, for reaction_time.
struct ReflexParams {
  double push = 0.3, train = 0.5, pulse = 0.8, pulse_time = 0.04, search = 0.3, reaction_time = 0.25;
  double trial = 1.5;
  double push_volts = 5.0, hold_volts = 0.0, release_volts = -5.0;
  void validate() const;
  CommandLimits limits() const;
};
struct ReflexVolts {
  PairVolts disturbed, reacting;
};
ReflexVolts reflexVolts(const ReflexParams& p, double t);  // t from the trial's start

// Valve steps from either extreme (fig. 5.2): -5 -> +level for each level, then +5 -> -level,
// each after `hold` at the extreme and followed by `gap` at 0 V, after `pin` s of full supply that
// puts the joint against its flexion limit (the antagonist exhausted throughout).
struct StepParams {
  std::vector<double> levels{1, 2, 5};  // V, in (0, 5]
  double hold = 0.4, gap = 0.2, pin = 0.3;
  struct Step {
    double from, to, time;  // V, V, s from the plan's start
  };
  std::vector<Step> steps() const;
  double duration() const;
  void validate() const;
  CommandLimits limits() const;
};
PairVolts stepVolts(const StepParams& p, double t);

// Logarithmic chirp f(t) = f0 (f1/f0)^(t/T) of amplitude A around an offset (volts), after `pin`
// s of full supply (the joint against its limit) and `settle` s at the offset.
struct ChirpParams {
  double f0 = 1.0, f1 = 60.0, duration = 10.0;
  double offset = 0.0, amplitude = 1.0;
  double pin = 0.2, settle = 0.5;
  double start() const { return pin + settle; }  // the sweep's start in the plan
  void validate() const;
  CommandLimits limits() const;
};
double chirpFrequency(const ChirpParams& p, double t);
double chirpPhase(const ChirpParams& p, double t);         // rad, 0 at t = 0
double chirpVolts(const ChirpParams& p, double t);         // offset + amplitude sin(phase), offset outside [0, T]
PairVolts chirpPlanVolts(const ChirpParams& p, double t);  // t from the plan's start (pin, settle, sweep)

// Maximum force: full supply on the flexor for `hold` (extensor exhausted), both exhausted for
// `gap`, full supply on the extensor for `hold`, both at 0 V for `gap`. Plateau: the last `plateau` s.
struct ForceParams {
  double hold = 0.6, gap = 0.3, plateau = 0.2;
  double flexEnd() const { return hold; }
  double extStart() const { return hold + gap; }
  double extEnd() const { return 2 * hold + gap; }
  double duration() const { return 2 * (hold + gap); }
  void validate() const;
  CommandLimits limits() const;
};
PairVolts forceVolts(const ForceParams& p, double t);

// ------------------------------------------------------------------------------ analysis

// Bang-bang: the mean peak-to-peak angle over whole cycles (each cycle window holds one full
// period, so its max - min is the stroke whatever the phase lag).
struct Stroke {
  double frequency = kNaN;
  double peak_to_peak = kNaN, low = kNaN, high = kNaN;  // rad, means over the cycles
  double fraction = kNaN;                               // of the reference range
  int cycles = 0;
  bool complete = false;
};
Stroke measureStroke(const Series& q, double t0, double frequency, int cycles, int skip_cycles, double reference,
                     double complete_fraction);

struct BangBangResult {
  std::string joint;
  double model_range = kNaN;      // rad, the model's limits
  double reference_range = kNaN;  // rad, extremes reached in the slow reference cycles
  double reference_low = kNaN, reference_high = kNaN;
  double complete_fraction = 0.9;
  double damping = kNaN;              // N m s/rad, the model's joint damping
  double bound_stroke_time = kNaN;    // s, dampingBoundTime of the reference range, slower direction
  std::vector<Stroke> strokes;        // increasing frequency
  double highest_complete_hz = kNaN;  // highest frequency with it and every lower one complete
  double crossing_hz = kNaN;          // where the stroke fraction falls through complete_fraction (interpolated)
};
// Fills highest_complete_hz and crossing_hz from the strokes.
void summariseBangBang(BangBangResult* result);

// One limit-to-limit movement: the time from the command to 90 % of the excursion the joint
// makes in its window (its own extreme, whichever limit stopped it).
struct Movement {
  std::string joint;
  bool flexion = true;
  double start = kNaN, extreme = kNaN;  // rad
  double excursion = kNaN;              // rad, in the commanded direction
  double fraction_of_range = kNaN;      // excursion / the model's range
  double time = kNaN;                   // s; NaN when the joint did not move (excursion < min_excursion)
  double bound_time = kNaN;             // s, dampingBoundTime of the excursion (filled by the caller)
};
Movement measureMovement(const Series& q, double t_command, double t_end, int direction, double range,
                         double min_excursion = 0.02);

struct SequenceResult {
  std::vector<Movement> moves;
  int joints = 0;
  double total = kNaN;          // s, sum of the movement times (the sequence without dwell)
  double mean_movement = kNaN;  // s
  int moved = 0;                // movements with a time
};
void summariseSequence(SequenceResult* result);

// Reflex: t_detect is the stamp of the joint sample on which the disturbance was detected (the
// event trigger T1 of fig. 3.8); latencies count from it, as in the thesis.
struct ReflexTrial {
  double t_pulse = kNaN;     // disturbance command sent
  double t_detect = kNaN;    // stamp of the detecting sample
  double t_receive = kNaN;   // when that sample arrived
  double t_command = kNaN;   // reaction command sent
  double t_pressure = kNaN;  // first pressure change of the reacting cylinder (its sample's stamp)
  double t_motion = kNaN;    // first motion of the reacting joint, in the reaction's direction
  double detect_threshold = kNaN, pressure_threshold = kNaN, motion_threshold = kNaN;
  bool valid = false;
  std::string note;  // why a trial is not valid
  double pressureLatency() const { return t_pressure - t_detect; }
  double motionLatency() const { return t_motion - t_detect; }
};
struct ReflexThresholds {
  double k_sigma = 5.0;
  double joint_floor = 0.01;    // rad
  double pressure_floor = 5e3;  // Pa
  double baseline = 0.25;       // s of samples before the disturbance command
  double search = 0.3;          // s after the detection
};
// Completes a trial from the reacting cylinder's pressure and the reacting joint's angle;
// `reaction_direction` is the sign of the commanded motion of that joint.
void measureReflex(const Series& pressure, const Series& reacting_q, int reaction_direction,
                   const ReflexThresholds& thresholds, ReflexTrial* trial);

struct ReflexResult {
  std::string disturbed_joint, pulse_cylinder, reacting_joint;
  std::vector<std::string> reacting_cylinders;
  std::vector<ReflexTrial> trials;
  double pressure_latency = kNaN, motion_latency = kNaN;  // s, medians over the valid trials
  double detection_delay = kNaN;                          // s, median disturbance command -> detecting sample's stamp
  double reaction_delay = kNaN;   // s, median arrival of the detecting sample -> reaction sent (this tool)
  double transport_delay = kNaN;  // s, median detecting sample's stamp -> its arrival
  double pressure_period = kNaN;  // s, median interval of the pressure samples (the resolution)
  int valid = 0;
};
void summariseReflex(ReflexResult* result);

// Valve step: dead time and time constant from the 10-90 % rise of a first-order lag with delay
// (t10 = D + tau ln(10/9), t90 = D + tau ln 10), the first change beyond noise, the asymptote.
struct StepResponse {
  double from_volts = kNaN, to_volts = kNaN;
  double p_initial = kNaN, p_final = kNaN;  // Pa
  double first_change = kNaN;               // s after the step: beyond the noise
  double dead_time = kNaN;                  // s
  double rise_time = kNaN;                  // s, 10 % -> 90 %
  double time_constant = kNaN;              // s, rise_time / ln 9
  double t63 = kNaN;                        // s after the step
  double joint_motion = kNaN;               // rad, the joint's travel during the step (volume not locked if large)
};
StepResponse measureStep(const Series& p, double t_step, double t_end, double k_sigma = 5.0, double floor = 3e3);

// Chirp: the gain and phase of the response at the chirp's frequency, by least squares over
// windows of whole cycles (regressors sin phase, cos phase, offset, drift).
struct GainPoint {
  double frequency = kNaN, gain = kNaN, phase = kNaN;  // Hz, output units per volt, rad
};
// `t0` is the chirp's start on the series' clock; windows above 0.45 of the sample rate are dropped.
std::vector<GainPoint> chirpGains(const Series& y, const ChirpParams& p, double t0, double cycles_per_window = 4);

struct Bandwidth {
  double reference_gain = kNaN;  // the low-frequency gain (median of the points up to reference_hz)
  double critical_hz = kNaN;     // first fall through -drop_db (smoothed over 3 points); NaN if none
  double phase_at_critical = kNaN;
};
Bandwidth criticalFrequency(const std::vector<GainPoint>& points, double reference_hz, double drop_db = 3.0);

struct ChirpResult {
  ChirpParams params;
  std::vector<GainPoint> points;
  Bandwidth bandwidth;
  double joint_motion = kNaN;  // rad, peak-to-peak of the joint during the chirp
};

struct StepResult {
  std::string cylinder, antagonist, joint;
  double sample_period = kNaN;  // s, median interval of the pressure samples
  std::vector<StepResponse> steps;
};

struct ForceResult {
  std::string joint, flexor, extensor;
  FingertipLever lever;
  double supply = kNaN;                            // Pa, during the pushes
  double flex_tension = kNaN, ext_tension = kNaN;  // N, plateau of the driver's tension
  double flex_pressure = kNaN, ext_pressure = kNaN;
  double flex_tip = kNaN, ext_tip = kNaN;  // N
  std::string touch_sensor;
  double touch_flex = kNaN, touch_ext = kNaN;  // N, the fingertip's touch sensor, max during each push
};
void summariseForce(ForceResult* result);  // the tip forces from tensions and lever

// ------------------------------------------------------------------------------- report

struct Report {
  std::string driver;  // "simulation" | "hardware" | what the diagnostics said
  std::string scene, started;
  bool quick = false;
  double rate = 0;      // Hz, command rate
  double duration = 0;  // s, the whole run
  std::string aborted;  // why the run stopped early ("" = it did not)
  std::uint64_t limiter_interventions = 0;
  std::vector<std::string> experiments_run;
  std::string arm_hold;                                       // how the arm was held during the run ("" = not at all)
  std::vector<std::pair<std::string, double>> touch_at_rest;  // touch sensors above 0.05 N before the experiments
  bool touch_checked = false;
  bool has_bang_bang = false, has_sequence = false, has_reflex = false, has_step = false, has_chirp = false,
       has_force = false;
  BangBangResult bang_bang;
  SequenceResult sequence;
  ReflexResult reflex;
  StepResult step;
  std::vector<ChirpResult> chirps;
  std::string chirp_cylinder, chirp_antagonist;
  ForceResult force;
  std::vector<std::string> plots;  // PNG files written next to the report ("" if plotting failed)
  std::string plot_error;
};
// Markdown: the summary table (each figure next to the thesis value), then one section per
// experiment with its plot and its numbers.
std::string reportMarkdown(const Report& report);

// The summary as CSV rows: figure,measured,unit,thesis,note.
std::string summaryCsv(const Report& report);

}  // namespace adroit::driver::characterisation
