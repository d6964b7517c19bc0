// The LQ core shared by the behaviour MPC (iLQG) and the trajectory-centric trainer (TVLG /
// KL-constrained LQR): a discrete-time local quadratic approximation along a nominal
// trajectory, its backward pass with box-constrained controls, and the Levenberg-Marquardt
// regularisation schedule (Tassa, Erez & Todorov 2012; Tassa, Mansard & Todorov 2014).
//
// Model/data split: LqApproximation is filled by the caller (one per problem, may be
// shared read-only by threads); BackwardPass holds every workspace, sized once, and its
// run() allocates nothing.
#pragma once

#include <adroit_core/box_qp.h>

#include <Eigen/Dense>
#include <vector>

namespace adroit {

// dx_{t+1} = A_t dx_t + B_t du_t  (t = 0..T-1), running cost l_t(x_t, u_t) to second order,
// terminal cost l_T(x_T) to second order (lx[T], lxx[T]). State deviations live in the
// tangent space (nx = 2 nv + na for MuJoCo states).
struct LqApproximation {
  LqApproximation() = default;
  LqApproximation(int nx, int nu, int horizon) { resize(nx, nu, horizon); }
  void resize(int nx, int nu, int horizon);  // allocates; sets everything to zero

  int nx = 0, nu = 0, horizon = 0;          // horizon T = number of controls
  std::vector<Eigen::MatrixXd> A, B;        // T entries: nx x nx, nx x nu
  std::vector<Eigen::VectorXd> lx;          // T + 1 entries (last = terminal)
  std::vector<Eigen::MatrixXd> lxx;         // T + 1 entries
  std::vector<Eigen::VectorXd> lu;          // T entries
  std::vector<Eigen::MatrixXd> luu, lux;    // T entries: nu x nu, nu x nx
};

// Time-varying affine control law  du_t = k_t + K_t dx_t  produced by the backward pass.
struct FeedbackGains {
  void resize(int nx, int nu, int horizon);
  std::vector<Eigen::VectorXd> k;  // T entries, nu
  std::vector<Eigen::MatrixXd> K;  // T entries, nu x nx
};

enum class RegularizationType {
  kControl,  // Quu + mu I
  kState,    // Vxx + mu I inside Quu, Qux (Tassa 2012: invariant to control scaling)
};

struct BackwardPassSettings {
  RegularizationType regularization = RegularizationType::kControl;
  BoxQpSettings qp;
};

struct BackwardPassResult {
  bool ok = false;        // false: a Q_uu was not positive definite (increase mu and retry)
  int failed_step = -1;   // the step where it failed
  // Expected cost change of the line-search step alpha: alpha * dV[0] + alpha^2 * dV[1].
  double dV[2] = {0, 0};
  int clamped_controls = 0;  // total clamped dimensions over the horizon (diagnostics)
};

class BackwardPass {
 public:
  BackwardPass(int nx, int nu, int horizon, BackwardPassSettings settings = {});

  // Controls are bounded: u_min <= u_nominal[t] + du_t <= u_max (the QP bounds of each step).
  // Pass empty u_min/u_max (size 0) for an unconstrained problem (plain Cholesky, no QP).
  BackwardPassResult run(const LqApproximation& lq, const std::vector<Eigen::VectorXd>& u_nominal,
                         const Eigen::VectorXd& u_min, const Eigen::VectorXd& u_max, double mu,
                         FeedbackGains& gains);

  // Value function of the last run at step t (t = 0..T; meaningful when it returned ok):
  // V(x) ~ Vx' dx + 0.5 dx' Vxx dx.
  const Eigen::VectorXd& Vx(int t) const { return Vx_[t]; }
  const Eigen::MatrixXd& Vxx(int t) const { return Vxx_[t]; }
  // Unregularised Q_uu of the last run at step t (t = 0..T-1; valid for the steps the run
  // reached, i.e. all when it returned ok). The maximum-entropy controller's covariance is its
  // inverse (thesis 8.2.1: C_t = Quu_t^-1).
  const Eigen::MatrixXd& Quu(int t) const { return Quu_steps_[t]; }

 private:
  void checkInputs(const LqApproximation& lq, const std::vector<Eigen::VectorXd>& u_nominal,
                   const Eigen::VectorXd& u_min, const Eigen::VectorXd& u_max, double mu) const;

  int nx_, nu_, horizon_;
  BackwardPassSettings settings_;
  BoxQp qp_;
  Eigen::LLT<Eigen::MatrixXd> llt_;  // unconstrained steps: always nu x nu, compute() reuses storage
  std::vector<Eigen::VectorXd> Vx_;
  std::vector<Eigen::MatrixXd> Vxx_;
  std::vector<Eigen::MatrixXd> Quu_steps_;  // horizon entries, nu x nu
  Eigen::VectorXd Qx_, Qu_, lower_, upper_, du_;
  Eigen::MatrixXd Quu_, Qux_, Quu_reg_, Qux_reg_, VxxA_, VxxB_, QuuK_;
};

// Levenberg-Marquardt schedule of mu (Tassa, Erez & Todorov 2012, sec. II-F).
struct RegularizationSchedule {
  double mu = 1e-6, mu_min = 1e-6, mu_max = 1e10, delta = 1.0, delta0 = 2.0;
  void increase();  // delta = max(delta0, delta * delta0); mu = max(mu_min, mu * delta)
  void decrease();  // delta = min(1 / delta0, delta / delta0); mu = mu * delta, 0 below mu_min
  bool exhausted() const { return mu > mu_max; }
};

}  // namespace adroit
