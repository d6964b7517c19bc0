// Finite-difference dynamics derivatives along a nominal trajectory (thesis 5.5.2, 6.4.2):
// A_t = d x_{t+1} / d x_t and B_t = d x_{t+1} / d ctrl_t of one step, with x = [qpos qvel act]
// differentiated in the tangent space (dx = [dq (nv) | dv (nv) | dact (na)]). The same
// differences as MuJoCo's mjd_transitionFD (controls, then velocities skipping the position
// stage, then positions; the solver's warm start restored before every nudge), with one
// saving: bodies that nothing couples at a knot are nudged together.
//
// Grouped columns: kinematic trees (a moving body on a static one, with its subtree) that share no
// tendon, actuator or equality constraint, and touch no other tree at the knot, cannot
// affect each other within a step, so one nudged step can carry one DOF of each of them
// (Curtis-Powell-Reid column grouping of a block-diagonal Jacobian). The keypad's twelve
// keys cost one position and one velocity column instead of twelve each while no finger
// touches them; a falling object costs none beside the hand's. The columns between
// separated trees are exactly zero instead of rounding noise.
//
// On a model that collides through explicit pairs only (mjCOL_PAIR, planning_model.h), the
// position nudges test only the pairs in contact at the knot's nominal step: a nudge of 1e-6
// moves no geom into or out of a margin that it was not already at, and the contacts keep
// their order, so the columns are those of the full pass (to rounding) without its cost.
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
#include <utility>
#include <vector>

namespace adroit_mpc {

struct FdSettings {
  double epsilon = 1e-6;
  bool centered = false;     // centred differences: twice the steps, second-order accurate
  int skip = 1;              // derivative_skip
  bool group_trees = true;   // nudge separated trees together (false: one column per DOF)
  // Every nudge (and the nominal step again) starts the constraint solver from the nominal
  // step's solution instead of the knot's warm start: MuJoCo's Newton solver then converges
  // in an iteration or so instead of walking the contacts' active set from the unconstrained
  // acceleration each time (a keypad knot: 0.35x the instructions). false (default):
  // mjd_transitionFD's warm start, the knot's (see PlannerSettings::fd_warmstart).
  bool warmstart_from_nominal = false;
};

class FdDerivatives {
 public:
  // Allocates the per-worker mjData and scratch. Throws std::invalid_argument for a bad
  // setting (epsilon <= 0, skip < 1, horizon < 1, workers < 1) or an RK4 model.
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
  // Nudged position (= velocity) columns at knot 0 of the last compute() (nv without grouping).
  int lastStateColumns() const { return last_state_columns_; }

  // One knot: A (nx x nx) and B (nx x nu) at the state and controls in `d` (its qpos, qvel,
  // act, ctrl, time, qacc_warmstart). `worker` names the scratch (one per pool worker);
  // returns the number of nudged position (= velocity) columns. Allocates nothing.
  int knot(mjData* d, std::size_t worker, Eigen::MatrixXd& A, Eigen::MatrixXd& B);

 private:
  struct Scratch {
    std::vector<mjtNum> qpos, qvel, act, ctrl, warmstart;  // the knot's inputs
    std::vector<mjtNum> next, plus, minus;                 // [qpos qvel act] after a step
    std::vector<mjtNum> dpos, delta;                       // nv; nx
    std::vector<int> group;                                // tree -> representative (union-find)
    std::vector<int> count;                                // representative -> DOFs so far
    std::vector<int> slot;                                 // dof -> its column within the group
    std::vector<int> representative;                       // dof -> its group
    std::vector<int> active_pairs;                         // pair ids in contact at the nominal
    adroit::ModelPtr nudge_model;                          // the model, those pairs only (mjCOL_PAIR)
    double time = 0;
  };
  void save(const mjData* d, Scratch& s) const;
  void restore(mjData* d, const Scratch& s) const;
  void stepSkip(const mjModel* m, mjData* d, int skipstage, std::vector<mjtNum>& out) const;
  // The worker's model for position nudges: the pairs of the nominal step's contacts only.
  const mjModel* restrictPairs(const mjData* d, Scratch& s) const;
  // One input of `d` (a ctrl or act entry) moved by `by`, stepped into `out`, then restored.
  void nudgedStep(mjData* d, const Scratch& s, mjtNum* input, double by, int skipstage,
                  std::vector<mjtNum>& out) const;
  int groupDofs(const mjData* d, Scratch& s) const;  // fills s.group, s.slot; returns columns
  // (x_plus - x_minus) / h in the tangent space into s.delta.
  void difference(const std::vector<mjtNum>& minus, const std::vector<mjtNum>& plus, double h, Scratch& s) const;

  const mjModel* model_ = nullptr;
  FdSettings settings_;
  int horizon_ = 0, nx_ = 0;
  int last_state_columns_ = 0;
  std::vector<int> computed_;
  std::vector<int> static_group_;  // tree -> representative after tendons, actuators, equalities
  std::vector<int> body_tree_;     // body -> its tree (top moving body; 0: static)
  std::vector<int> dof_tree_;      // dof -> its tree
  std::vector<std::pair<long, int>> pair_of_geoms_;  // (low geom * ngeom + high geom, pair id), sorted; mjCOL_PAIR
  std::vector<adroit::DataPtr> data_;  // one per worker
  std::vector<Scratch> scratch_;       // one per worker
};

// Sets a knot's state into `d` (qpos, qvel, act, ctrl, time); no allocation.
void setKnotState(const mjModel* m, mjData* d, const Eigen::VectorXd& state, const Eigen::VectorXd& ctrl,
                  double time);

}  // namespace adroit_mpc
