// Finite-difference dynamics derivatives along a nominal trajectory (thesis 5.5.2, 6.4.2):
// A_t = d x_{t+1} / d x_t and B_t = d x_{t+1} / d ctrl_t of one mj_step, by MuJoCo's
// mjd_transitionFD, with x = [qpos qvel act] differentiated in the tangent space
// (dx = [dq (nv) | dv (nv) | dact (na)]).
//
// Knots are spread over the thread pool, one mjData per worker (allocated in initialize()).
// derivative_skip k > 1 computes the derivatives at knots 0, k, 2k, ... only and holds each
// for the next k - 1 knots: a zero-order-hold approximation of the linearisation that is good
// while the dynamics change little over k dt (free flight, steady grasps) and stale across a
// contact event inside the held span. The last knot is always computed so the terminal
// approach is linearised where it happens.
#pragma once

#include <adroit_core/mujoco_model.h>
#include <adroit_core/thread_pool.h>

#include <mujoco/mujoco.h>

#include <Eigen/Dense>
#include <vector>

namespace adroit_mpc {

struct FdSettings {
  double epsilon = 1e-6;
  bool centered = false;  // centred differences: twice the steps, second-order accurate
  int skip = 1;           // derivative_skip
};

class FdDerivatives {
 public:
  // Allocates the per-worker mjData and row-major scratch. Throws std::invalid_argument for
  // a bad setting (epsilon <= 0, skip < 1, horizon < 1, workers < 1).
  void initialize(const mjModel* model, int horizon, int workers, const FdSettings& settings);

  // states[t]: [qpos qvel act] (nq + nv + na) at knot t; ctrl[t]: model controls (nu);
  // times[t]: time of knot t. Fills A[t] (nx x nx) and B[t] (nx x nu) for t in [0, horizon),
  // the vectors already sized (no allocation). Computed knots are spread over `pool`.
  void compute(adroit::ThreadPool& pool, const std::vector<Eigen::VectorXd>& states,
               const std::vector<Eigen::VectorXd>& ctrl, const std::vector<double>& times,
               std::vector<Eigen::MatrixXd>& A, std::vector<Eigen::MatrixXd>& B);

  // Knots where compute() evaluates the model (the rest copy the previous computed knot).
  const std::vector<int>& computedKnots() const { return computed_; }
  int nx() const { return nx_; }

 private:
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const mjModel* model_ = nullptr;
  FdSettings settings_;
  int horizon_ = 0, nx_ = 0;
  std::vector<int> computed_;
  std::vector<adroit::DataPtr> data_;  // one per worker
  std::vector<RowMajor> A_rows_, B_rows_;  // per worker: mjd_transitionFD writes row-major
};

// Sets a knot's state into `d` (qpos, qvel, act, ctrl, time); no allocation.
void setKnotState(const mjModel* m, mjData* d, const Eigen::VectorXd& state, const Eigen::VectorXd& ctrl,
                  double time);

}  // namespace adroit_mpc
