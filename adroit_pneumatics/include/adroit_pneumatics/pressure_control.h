// Pressure controllers for one cylinder: iLQG MPC on the parametric model (thesis 5.5)
// and the PIDF baseline, behind one interface so a pool can run either.
// Units: SI throughout (Pa, V, s), parameters included. The thesis (5.6.1) states its
// weights per MPa^2; alpha_p = 1e-12 / Pa^2 is its 1 / MPa^2. The solver's thresholds act on
// quantities that do not depend on the pressure unit (cost, expected cost change, the
// Hessian in u), so working in Pa instead of MPa changes nothing but the numbers' exponents.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "adroit_pneumatics/parametric_model.h"

namespace adroit::pneumatics {

// Scalar discrete dynamics p' = f(p, u) for the iLQG core, with df/dp and df/du.
class ScalarDynamics {
 public:
  virtual ~ScalarDynamics() = default;
  virtual double step(double p, double u, double* dp, double* du) const = 0;
  // Step that may also depend on the previous command w (input dead time: w still acts at
  // the start of the step). Default: no dependence on w.
  virtual double stepWithMemory(double p, double /*w*/, double u, double* dp, double* dw, double* du) const {
    if (dw) *dw = 0.0;
    return step(p, u, dp, du);
  }
};

struct IlqgParams {
  int horizon = 100;            // N
  double dt = 0.005;            // s
  // Cost weights of eq. 5.12 (squared norms), in the dynamics' units: for the pressure
  // controller alpha_p is per Pa^2 (1e-12 = the thesis' 1 per MPa^2), alpha_u and alpha_w
  // per V^2.
  double alpha_p = 1e-12;
  double alpha_u = 1e-4;
  double alpha_w = 1e-4;
  double u_min = -2.0;          // V, about 40 % of the valve range (5.6.3 item 4)
  double u_max = 2.0;
  int iterations = 1;           // per solve: one iLQG iteration per control period from the
                                // time-shifted warm start (real-time iteration; the thesis
                                // takes "a few" per estimate update, 5.5.4)
  double feedback_fraction = 0.2;  // partial feedback (5.6.3 item 5)
  // When the pressure is this far (Pa; dynamics units) from the reference at the start of a solve (a jump
  // of the reference), the solver also tries the time-optimal guess "command limit until the
  // predicted pressure reaches the reference, then the command that holds it" and starts
  // from whichever of it and the warm start costs less. 0 disables.
  double jump_threshold = 20e3;  // Pa; 0 disables
  int jump_iterations = 3;      // iterations of a solve that starts far from the reference
  // Offset-free MPC (IlqgPressureController): gain of the disturbance estimate, a constant
  // pressure-rate bias d (Pa/s) added to the model, updated each tick from the one-step
  // prediction error e as d += disturbance_gain * e / dt. 0 turns it off.
  double disturbance_gain = 0.15;
  double disturbance_limit = 20e6;  // Pa/s, |d| bound (a sane model is off by far less)
  // Start pressure of each solve: pred + measurement_gain (p_meas - pred), pred = the model's
  // one-step prediction (with d) from the last tick. 1 = the raw measurement; smaller
  // filters sensor noise without the lag of a plain low-pass (the model carries the motion).
  double measurement_gain = 0.25;
  // Innovations larger than this (Pa) are model error, not sensor noise: the part of the
  // innovation beyond the band is taken in full. 0 = always measurement_gain.
  double measurement_band = 4000.0;  // 2 sigma of the sensor noise
  // u_des of eq. 5.12: false (default) = the previous plan shifted in time (alpha_u is then a
  // pure proximal regulariser that cannot bias the steady state), true = the model's
  // steady-state inverse of the reference (biased whenever the model is).
  bool u_des_steady_state = false;
  void validate() const;        // throws std::invalid_argument naming the field
};

// Sets one field of p by its name (horizon, dt, alpha_p, alpha_u, alpha_w, u_min, u_max,
// iterations, feedback_fraction, jump_threshold, jump_iterations, disturbance_gain,
// disturbance_limit, measurement_gain, measurement_band); false for an unknown name. For the
// benchmarks' command-line overrides; call validate() afterwards.
bool setIlqgParam(IlqgParams& p, const std::string& name, double value);

// Time-varying affine policy u = u_i + fraction * K_i . ([p, w] - [p_i, w_i]).
struct Policy {
  bool valid = false;
  double t0 = 0, dt = 0;
  std::vector<double> p, w, u, kp, kw;  // p in Pa, kp in V/Pa
};

// Box-constrained iLQG on x = [p, w], u (valve memory w = previous command, eq. 5.11).
// Works on any ScalarDynamics; p and references in the dynamics' units. Every buffer is
// allocated at construction: solve() allocates nothing (the pool's 200 Hz tick runs it).
class IlqgSolver {
 public:
  explicit IlqgSolver(const IlqgParams& params);
  const IlqgParams& params() const { return params_; }

  // p_ref, u_des: horizon + 1 samples. u_init: n_init (<= horizon) warm-start samples,
  // u_des beyond them. Returns false if the result is not finite.
  bool solve(const ScalarDynamics& f, double p0, double w0, const double* p_ref, const double* u_des,
             const double* u_init, int n_init, int iterations);
  bool solve(const ScalarDynamics& f, double p0, double w0, const double* p_ref, const double* u_des,
             const std::vector<double>& u_init, int iterations) {
    return solve(f, p0, w0, p_ref, u_des, u_init.data(), static_cast<int>(u_init.size()), iterations);
  }

  const std::vector<double>& u() const { return u_; }
  const std::vector<double>& p() const { return p_; }
  const std::vector<double>& w() const { return w_; }
  // Feedback gains of the last successful backward pass (the one that produced u()).
  const std::vector<double>& gainP() const { return kp_; }
  const std::vector<double>& gainW() const { return kw_; }
  double cost() const { return cost_; }

 private:
  double rollout(const ScalarDynamics& f, double p0, double w0, const double* p_ref, const double* u_des,
                 const std::vector<double>& u_ff, double step, std::vector<double>& p, std::vector<double>& w,
                 std::vector<double>& u) const;
  bool backward(const double* p_ref, const double* u_des, double reg, double* expected);
  // The "limit, then hold" initial guess for a reference far from p0 (see jump_threshold).
  void bangHoldGuess(const ScalarDynamics& f, double p0, double w0, const double* p_ref, std::vector<double>& u);

  IlqgParams params_;
  std::vector<double> p_, w_, u_, a_, b_, c_, kff_, kp_, kw_;
  std::vector<double> p_try_, w_try_, u_try_, p_alt_, w_alt_, u_alt_, u_start_, knots_;  // workspaces
  double cost_ = 0;
};

struct ControlStats {
  double solve_seconds = 0;
  bool solved = false;
  bool rejected = false;  // a solver result was not finite and was dropped
};

class PressureController {
 public:
  virtual ~PressureController() = default;
  // One control tick at time t: p_meas (Pa), w_last (V, command currently applied),
  // p_ref: n_ref pressure samples (Pa) at t + k * dt_ref. Returns a finite command in
  // the controller's limits, or NaN if it has nothing safe to command. may_solve false: a
  // controller that re-solves a plan (iLQG) evaluates the plan it has instead, unless it has
  // none yet (a pool's compute budget for the tick is spent; CylinderPool).
  virtual double update(double t, double p_meas, double w_last, const ParametricInputs& in, const double* p_ref,
                        int n_ref, double dt_ref, ControlStats* stats, bool may_solve) = 0;
  virtual void reset() = 0;
};

// iLQG MPC: re-solves every `solve_every` control periods (params.dt; warm start by time
// shift) and evaluates the resulting policy at every call. The solves go by time, not by
// calls: a pool that ticks on every actuator state (the hardware, 500 Hz and more) evaluates
// the policy on each sample and still solves once per period.
class IlqgPressureController : public PressureController {
 public:
  IlqgPressureController(const ParametricModel& model, const IlqgParams& params, int solve_every = 1);
  double update(double t, double p_meas, double w_last, const ParametricInputs& in, const double* p_ref, int n_ref,
                double dt_ref, ControlStats* stats, bool may_solve) override;
  void reset() override;
  const Policy& policy() const { return policy_; }
  // Policy evaluated at time t and state; NaN if no valid policy covers t.
  double evaluate(double t, double p_meas, double w_last) const;
  // Current disturbance estimate (Pa/s) and start-pressure estimate of the last tick (Pa).
  double disturbance() const { return disturbance_; }
  double pressureEstimate() const { return p_est_; }

 private:
  void updateDisturbance(double t, double p_meas, double w_last, const ParametricInputs& in);

  ParametricModel model_;
  IlqgSolver solver_;
  int solve_every_;
  Policy policy_;
  std::vector<double> p_ref_, u_des_, warm_;  // sized at construction
  // Offset-free estimator memory: last tick's time, measurement, commands and inputs.
  bool have_last_ = false;
  double last_t_ = 0, last_p_ = 0, last_w_ = 0, last_u_ = 0, disturbance_ = 0, p_est_ = 0;
  ParametricInputs last_in_;
};

struct PidfParams {
  double kp = 3e-6;          // V/Pa   (3 V/MPa)
  double ki = 3e-5;          // V/(Pa s)
  double kd = 2e-8;          // V s/Pa
  double filter_hz = 30.0;   // derivative low-pass
  bool feedforward = true;   // add the model's steady-state command for the reference
  // s: the feedforward takes the reference this far ahead (interpolated in the previewed
  // reference; its last sample when the preview is shorter). The loop's dead time is the
  // usual choice: the command then acts when the reference it was meant for is due.
  double feedforward_advance = 0.0;
  double u_min = -2.0, u_max = 2.0;
  void validate() const;
};

// PID with filtered derivative, anti-windup by conditional integration and optional
// model feedforward. The feedback uses only the current reference sample (it is myopic by
// design); the feedforward may look feedforward_advance ahead.
class PidfController : public PressureController {
 public:
  PidfController(const ParametricModel& model, const PidfParams& params);
  double update(double t, double p_meas, double w_last, const ParametricInputs& in, const double* p_ref, int n_ref,
                double dt_ref, ControlStats* stats, bool may_solve) override;
  void reset() override;

 private:
  ParametricModel model_;
  PidfParams params_;
  bool started_ = false;
  double last_t_ = 0, integral_ = 0, last_error_ = 0, derivative_ = 0;
};

// Resamples a reference given at dt_in onto `n` samples at dt_out (linear interpolation,
// last value held past the end).
void resampleReference(const double* in, int n_in, double dt_in, double offset, double dt_out, int n, double* out);

}  // namespace adroit::pneumatics
