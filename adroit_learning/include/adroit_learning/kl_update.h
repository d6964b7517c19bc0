// KL-constrained controller update of trajectory-centric RL (thesis 8.2.2; Levine & Abbeel
// 2014): given fitted linear-Gaussian dynamics, a quadratic cost and the previous controller
// p_old, find the linear-Gaussian controller minimising the expected cost subject to
// KL(p_new(tau) || p_old(tau)) <= epsilon.
//
// For a multiplier eta the Lagrangian is minimised by the maximum-entropy LQR on the
// surrogate cost  l(x, u) / eta - log p_old(u | x), a quadratic in (x, u). It is solved by
// adroit_core's BackwardPass (the same backward pass as the behaviour MPC) in absolute
// coordinates: the affine dynamics term f_t enters through a constant state entry,
// x~ = [x; 1], so the pass sees purely linear dynamics and the affine cost terms are its
// linear terms. The new controller is u ~ N(K x + k, Quu^-1). eta is found by a safeguarded
// secant of log KL over log eta, the KL of the resulting trajectory distribution coming from
// a forward pass of the state-action marginals under the fitted dynamics.
#pragma once

#include <adroit_core/lq_backward_pass.h>
#include <adroit_core/thread_pool.h>
#include <adroit_learning/lg_controller.h>

#include <Eigen/Dense>
#include <cstddef>
#include <vector>

namespace adroit {

// The learning code's optional parallelism: body(i, worker) for i in [0, n) on the pool's
// workers, or in order on this thread (worker 0) without a pool. Results are the same either
// way (every index writes only its own outputs and its worker's scratch).
inline std::size_t workerCount(const ThreadPool* pool) { return pool ? pool->size() : 1; }
template <typename Body>
void forEachIndex(ThreadPool* pool, std::size_t n, Body&& body) {
  if (pool) {
    pool->parallelForWorkers(n, body);
  } else {
    for (std::size_t i = 0; i < n; ++i) body(i, std::size_t{0});
  }
}

// x_{t+1} ~ N(Fx_t x_t + Fu_t u_t + f_t, Sigma_t), t = 0..T-1;  x_0 ~ N(x0_mean, x0_cov).
struct LgDynamics {
  LgDynamics() = default;
  LgDynamics(int nx, int nu, int horizon) { resize(nx, nu, horizon); }
  void resize(int nx, int nu, int horizon);  // zeros; allocates
  int nx = 0, nu = 0, horizon = 0;
  Eigen::VectorXd x0_mean;
  Eigen::MatrixXd x0_cov;
  std::vector<Eigen::MatrixXd> Fx, Fu, Sigma;  // T entries
  std::vector<Eigen::VectorXd> f;              // T entries
};

// l_t(x, u) = 0.5 x'cxx x + 0.5 u'cuu u + u'cux x + cx'x + cu'u  (t < T; constants dropped),
// l_T(x) = 0.5 x'cxx[T] x + cx[T]'x.
struct QuadraticCost {
  QuadraticCost() = default;
  QuadraticCost(int nx, int nu, int horizon) { resize(nx, nu, horizon); }
  void resize(int nx, int nu, int horizon);  // zeros; allocates
  std::vector<Eigen::MatrixXd> cxx;  // T + 1 entries (last = terminal)
  std::vector<Eigen::VectorXd> cx;   // T + 1 entries
  std::vector<Eigen::MatrixXd> cuu;  // T entries, nu x nu
  std::vector<Eigen::MatrixXd> cux;  // T entries, nu x nx
  std::vector<Eigen::VectorXd> cu;   // T entries
};

// Gaussian marginals of a controller under the dynamics: joint [x_t; u_t] for t < T, x_T.
struct TrajectoryMarginals {
  std::vector<Eigen::VectorXd> xu_mean;  // T entries, nx + nu
  std::vector<Eigen::MatrixXd> xu_cov;   // T entries
  Eigen::VectorXd xT_mean;
  Eigen::MatrixXd xT_cov;
};

// Forward pass of the marginals (allocates on first use of `out` only). `pool`: the steps'
// action blocks on its workers (the state chain itself is sequential).
void forwardMarginals(const LgDynamics& dyn, const LgController& controller, TrajectoryMarginals& out,
                      ThreadPool* pool = nullptr);
// E[sum_t l_t + l_T] under the marginals (exact for Gaussian marginals and quadratic cost).
double expectedCost(const QuadraticCost& cost, const TrajectoryMarginals& marginals);
// KL(p_new(tau) || p_old(tau)) = sum_t E_{x ~ p_new(x_t)} KL(p_new(u|x) || p_old(u|x)), given
// p_new's marginals (both trajectory distributions share the dynamics and x_0). NaN when the
// marginals overflowed.
double klDivergence(const LgController& p_new, const LgController& p_old, const TrajectoryMarginals& new_marginals,
                    ThreadPool* pool = nullptr);

struct KlUpdateSettings {
  double eta_init = 1.0;       // first multiplier tried (warm start: the last update's eta)
  double kl_slope_init = -1.0; // d log KL / d log eta until two etas are evaluated (warm
                               // start: the last update's kl_slope); negative
  double eta_min = 1e-6;       // smallest eta: below it the constraint counts as slack
  double eta_max = 1e16;       // largest eta tried before giving up
  double tolerance = 0.1;      // accept |KL - epsilon| <= tolerance * epsilon
  int max_iterations = 100;    // evaluations of the max-entropy LQR
  ThreadPool* pool = nullptr;  // when set: the per-step work outside the backward pass on its workers
};

struct KlUpdateResult {
  LgController controller;
  double eta = 0;
  double kl = 0;               // KL(p_new || p_old) of the returned controller
  double predicted_cost = 0;   // expected cost of the new controller under the dynamics
  double kl_slope = -1.0;      // d log KL / d log eta of the last two evaluations (clamped to [-4, -0.25])
  bool converged = false;      // KL within tolerance of epsilon, or below it at eta_min
  int iterations = 0;
};

class KlUpdate {
 public:
  KlUpdate(int nx, int nu, int horizon);  // sizes the backward pass (state nx + 1) once

  // Maximum-entropy LQR on l / eta - log p_old(u|x) (prev == nullptr: on l alone, eta
  // ignored). Writes K, k, C = Quu^-1 into `out` (resized if needed). Returns false when a
  // Q_uu is not positive definite (or a gain not finite); `out` is then unspecified.
  bool solve(const LgDynamics& dyn, const QuadraticCost& cost, const LgController* prev, double eta,
             LgController& out);

  // Dual descent on eta: from eta_init, secant steps in log-log (at most 100x, 10x after a
  // failed solve) until the band is bracketed, then regula falsi in log-log with bisection as
  // the fallback. An eta whose KL or expected cost is not finite (overflow) counts as a failed
  // solve. Throws std::runtime_error when no eta up to eta_max gives a positive definite Q_uu
  // with a finite KL and cost, std::invalid_argument for inconsistent sizes or epsilon <= 0.
  KlUpdateResult update(const LgDynamics& dyn, const QuadraticCost& cost, const LgController& prev, double epsilon,
                        const KlUpdateSettings& settings = {});

 private:
  void checkSizes(const LgDynamics& dyn, const QuadraticCost& cost, const LgController* prev) const;
  // The parts of the surrogate LQ problem that do not depend on eta, loaded once per update:
  // the augmented dynamics, and the old controller's -log p_old(u|x) terms.
  void loadDynamics(const LgDynamics& dyn);
  void loadPrevious(const LgController& prev, ThreadPool* pool);
  bool solveLoaded(const QuadraticCost& cost, bool with_prev, double eta, LgController& out, ThreadPool* pool);
  void sizeWorkspaces(ThreadPool* pool);  // one of each per worker
  int nx_, nu_, horizon_;
  LqApproximation lq_;
  BackwardPass pass_;
  FeedbackGains gains_;
  std::vector<Eigen::MatrixXd> prev_P_, prev_PK_, prev_KPK_;  // per step, of the loaded old controller
  std::vector<Eigen::VectorXd> prev_Pk_, prev_KPk_;
  std::vector<Eigen::MatrixXd> inverse_;            // per worker, nu x nu: L^-1 or Quu^-1
  std::vector<Eigen::LLT<Eigen::MatrixXd>> llt_;   // per worker, of Quu
  TrajectoryMarginals marginals_;
};

// Step-size rule (Levine & Abbeel 2014): the improvement is modelled as linear in the step
// by the fitted model and quadratic in reality; the next epsilon puts the step at the
// optimum of that quadratic: epsilon * predicted / (2 (predicted - actual)), clamped to
// [min_multiplier, max_multiplier] * epsilon.
//   previous_expected:  expected cost of the old controller under the dynamics used for the update
//   predicted:          KlUpdateResult::predicted_cost (new controller, same dynamics)
//   previous_actual, actual: mean sample costs of the old and the new controller's rollouts.
struct StepSizeSettings {
  double min_multiplier = 0.1, max_multiplier = 5.0;
};
double adjustEpsilon(double epsilon, double previous_expected, double predicted, double previous_actual,
                     double actual, const StepSizeSettings& settings = {});

}  // namespace adroit
