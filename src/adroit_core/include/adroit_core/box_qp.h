// Box-constrained quadratic programme  min_x 0.5 x'Hx + g'x  s.t.  lower <= x <= upper,
// solved by projected Newton (Tassa, Mansard & Todorov, ICRA 2014). Used by the LQ backward
// pass for control limits; the free-set Cholesky factor is what the feedback gains need.
#pragma once

#include <Eigen/Dense>

namespace adroit {

struct BoxQpSettings {
  int max_iterations = 100;
  double min_gradient = 1e-8;           // stop: norm of the free gradient
  double min_relative_improvement = 1e-8;
  double step_decrease = 0.6;           // backtracking factor of the projected line search
  double min_step = 1e-22;
  double armijo = 0.1;                  // sufficient decrease
};

enum class BoxQpStatus {
  kHessianNotPositiveDefinite = -1,  // the free block of H failed Cholesky
  kNoDescent = 0,                    // line search could not improve
  kMaxIterations = 1,
  kConverged = 2,                    // small gradient or relative improvement
  kAllClamped = 3,                   // every dimension at a bound
};

// Preallocated for one dimension n; solve() allocates nothing.
class BoxQp {
 public:
  explicit BoxQp(int n, BoxQpSettings settings = {});

  // x: warm start in (projected onto the box first), solution out.
  BoxQpStatus solve(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& lower,
                    const Eigen::VectorXd& upper, Eigen::VectorXd& x);

  int iterations() const { return iterations_; }
  // After solve(): which dimensions are free (true) or clamped at a bound (false) at the
  // returned x, and (internally) the Cholesky factor of H restricted to them.
  const Eigen::Array<bool, Eigen::Dynamic, 1>& free() const { return free_; }
  int freeCount() const { return free_count_; }
  // Solves H_ff y = rhs_f for the free rows of `rhs` (columns independent) and writes zeros
  // in the clamped rows: the feedback gain K = -H_ff^-1 Q_ux restricted to the free set.
  // `out` is resized to rhs's shape (no allocation when it already has it); it must not
  // be `rhs` itself. Valid after a solve() that returned a status >= kNoDescent.
  void solveFree(const Eigen::MatrixXd& rhs, Eigen::MatrixXd& out) const;

 private:
  // Gradient and clamped set at x_; refactorises H_ff when the free set changed.
  // Returns false when H_ff is not positive definite.
  bool updateFreeSet(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& lower,
                     const Eigen::VectorXd& upper, const Eigen::VectorXd& x, bool force_factor);
  double objective(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& x,
                   Eigen::VectorXd& Hx) const;

  // implementation detail: workspaces sized once in the constructor
  int n_;
  BoxQpSettings settings_;
  int iterations_ = 0;
  int free_count_ = 0;
  Eigen::Array<bool, Eigen::Dynamic, 1> free_;
  Eigen::VectorXi free_index_;
  // Lower Cholesky factor of H_ff, computed in place in the top-left free_count_ square
  // (a max-size buffer: the free set's size varies, so an LLT<MatrixXd> would reallocate).
  Eigen::MatrixXd H_free_;
  Eigen::VectorXd grad_, Hx_, search_, candidate_, Hcandidate_, scratch_;
};

}  // namespace adroit
