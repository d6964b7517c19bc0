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
//
// Two savings for the MPC (issue 38), each switchable (FdSettings):
// * B through the generalised forces: the hand's 40 tendon actuators act on its 24 DOFs only
//   through qfrc = moment' force, so 24 nudges of qfrc and the chain rule give B to FD
//   precision (a control that the step clamps gets a zero column, as its own nudge would).
// * Reuse across calls: the MPC optimises the last plan shifted in time, so a linearisation of
//   one call is a fair one for the next at the same time (the hold's approximation, across
//   calls): each knot of the skip pattern takes the kept linearisation nearest to its time for
//   up to max_age seconds, unless the plan there moved beyond a tolerance; the refreshes are
//   spread over the calls, the oldest first.
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
  // B through the generalised forces: a linear actuator (no dynamics, fixed gain) acts on the
  // step only through qfrc = moment' (gain ctrl + bias), so B = (d x' / d qfrc) moment' gain,
  // with one nudge per DOF that such an actuator moves (24 on the hand) instead of one per
  // control (40). false: one nudge per control, as mjd_transitionFD.
  bool force_space_controls = false;
  // Reuse across compute() calls (the MPC's optimisations, each on the last plan shifted in
  // time). max_age > 0: a knot takes the kept linearisation nearest to its time (within
  // skip - 1 knots, as far as the hold reaches) that was computed at most max_age seconds of
  // plan time ago (this call's first knot time minus that call's), unless this call's
  // trajectory at that linearisation's time lies farther than reuse_tolerance from the state
  // it was taken at (max over |dq|, dt |dv|, |dact|: metres or radians). The calls evaluate
  // n since / max_age of their n knots on average (since: the time since the last call; the
  // fraction carried over), the oldest first, so the refreshes spread over the calls. 0: every
  // call evaluates every knot of the skip pattern (no reuse).
  double max_age = 0;
  double reuse_tolerance = 0.5;
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

  // Knots whose derivatives compute() sets (the rest hold the one before them): the skip pattern.
  const std::vector<int>& computedKnots() const { return computed_; }
  // Of those, the ones the last compute() evaluated (indices into computedKnots(), ascending);
  // the others reused a kept linearisation.
  const std::vector<int>& lastEvaluated() const { return evaluate_; }
  int lastEvaluatedKnots() const { return static_cast<int>(evaluate_.size()); }
  // The age of the oldest linearisation the last compute() reused (s of plan time; 0: none).
  double lastOldestAge() const { return last_oldest_age_; }
  // Forget the linearisations kept for reuse (after a reset, or when the state jumps).
  void forget();
  int nx() const { return nx_; }
  // Nudged position (= velocity) columns at knot 0 when a compute() last evaluated it (nv
  // without grouping).
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
    std::vector<int> forced_dofs;                          // DOFs that linear actuators move
    Eigen::MatrixXd force_columns;                         // nx x nv: d x' / d qfrc of those DOFs
    double time = 0;
  };
  // A knot's linearisation kept for the next compute() calls.
  struct Linearisation {
    bool valid = false;
    double time = 0;        // of the state it was taken at
    double computed_at = 0; // first knot time of the call that computed it
    Eigen::VectorXd state;  // [qpos qvel act]
    Eigen::MatrixXd A, B;
  };
  void save(const mjData* d, Scratch& s) const;
  void restore(mjData* d, const Scratch& s) const;
  void stepSkip(const mjModel* m, mjData* d, int skipstage, std::vector<mjtNum>& out) const;
  // The worker's model for position nudges: the pairs of the nominal step's contacts only.
  const mjModel* restrictPairs(const mjData* d, Scratch& s) const;
  // One input of `d` (a ctrl or act entry) moved by `by`, stepped into `out`, then restored.
  void nudgedStep(mjData* d, const Scratch& s, mjtNum* input, double by, int skipstage,
                  std::vector<mjtNum>& out) const;
  // B's columns of controls that are not linear in the force (every control without
  // force_space_controls), one nudge each.
  void controlColumns(mjData* d, Scratch& s, bool linear_too, Eigen::MatrixXd& B) const;
  // B's columns of the linear actuators through the generalised forces they move.
  void forceSpaceColumns(mjData* d, Scratch& s, Eigen::MatrixXd& B) const;
  // d force / d ctrl of linear actuator a at the nominal (0 where the force is clamped).
  double forceGain(const mjData* d, const Scratch& s, int a) const;
  int groupDofs(const mjData* d, Scratch& s) const;  // fills s.group, s.slot; returns columns
  // Reuse: which computed knots take a kept linearisation (source_) and which are evaluated.
  void planReuse(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times);
  // The kept linearisation nearest to `time` that may serve it (index into kept_, -1: none).
  int nearestKept(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times, double time,
                  double t0);
  // This call's trajectory at `time` (linear between knots) into `out`.
  void interpolate(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times, double time,
                   Eigen::VectorXd& out) const;
  double stateDistance(const Eigen::VectorXd& a, const Eigen::VectorXd& b);
  void keep(const std::vector<Eigen::VectorXd>& states, const std::vector<double>& times,
            const std::vector<Eigen::MatrixXd>& A, const std::vector<Eigen::MatrixXd>& B);
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
  std::vector<char> linear_actuator_;  // no dynamics, fixed gain, no or affine bias
  // Reuse (max_age > 0): the last call's linearisations, one per computed knot, and
  // this call's being built (swapped after each compute()).
  std::vector<Linearisation> kept_, next_;
  double kept_t0_ = 0;         // first knot time of the last call (kept_t0_valid_)
  bool kept_t0_valid_ = false;
  double refreshes_due_ = 0;   // evaluations owed to the max age, carried between calls
  double last_oldest_age_ = 0;
  std::vector<int> source_;    // per computed knot: the kept_ index it reuses, -1: evaluated
  std::vector<int> evaluate_;  // indices into computed_ evaluated this call
  Eigen::VectorXd dq_;         // nv: position difference (stateDistance)
  Eigen::VectorXd x_at_;       // nq + nv + na: the trajectory at a kept linearisation's time
};

// Sets a knot's state into `d` (qpos, qvel, act, ctrl, time); no allocation.
void setKnotState(const mjModel* m, mjData* d, const Eigen::VectorXd& state, const Eigen::VectorXd& ctrl,
                  double time);

}  // namespace adroit_mpc
