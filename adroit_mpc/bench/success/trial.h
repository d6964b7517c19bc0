// mpc_success's trials: the variants it compares, the seeded trials every variant runs (the
// same ones, paired) and what one trial reports.
#pragma once

#include "robustness.h"

#include <Eigen/Core>

#include <array>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace success {

// Relocation: the goal is given this long after the release, this far from the hold at least.
constexpr double kRelocateGoalDelay = 1.0;
constexpr double kRelocateMinDistance = 0.05;

struct Variant {
  std::string name, planner;
  bool synergies;
  bool pneumatic = false;  // valve commands from the pools tracking the plan (else tendon forces)
  bool open_loop_reference = false;  // pneumatic: the plan's tensions on each new plan only
  bool world_as_planned = false;  // the simulation runs the planning MJCF (diagnostic, see --variants)
  bool compensate = true;  // plan from the state predicted at the expected latency (latency_compensation.h)
  bool fd_warmstart = true;  // finite-difference nudges solved from the nominal's solution (fd_derivatives.h)
  bool cheap_derivatives = true;  // reused across optimisations, B through the forces (fd_derivatives.h)
};

struct TrialSpec {
  int index = 0;
  Eigen::Vector3d object_start = Eigen::Vector3d::Zero();
  Eigen::Vector3d goal = Eigen::Vector3d::Zero();
  std::string keys;
};

struct TrialResult {
  bool success = false;
  double final_error = 0, lowest_z = 0, duration = 0, plan_ms_median = 0;
  // Table 6.2's split of an optimisation, ms, median over the trial's plans: rollout,
  // derivatives, cost derivatives, backward pass, line search.
  std::array<double, 5> phase_ms_median{};
  // Joints (hinge and slide) of the state each plan started from against the state when it took
  // over, RMS, median over the plans: the prediction's error with latency compensation, the
  // measured state's staleness without.
  double start_error_median = 0;
  double farthest_from_grasp = 0;  // relocation, from the goal on: object centre to S_grasp (m)
  int keys_correct = 0, keys_total = 0, diverged = 0;
  int unasked = 0;  // typing with --idle: keys registered before the sequence was given
  int presses = 0, wrong_presses = 0;  // typing, from the sequence on (TypeTask::presses, wrongPresses)
  std::vector<std::pair<double, double>> trace;  // (t, error)
  std::vector<std::vector<double>> qpos_trace;   // qpos at the trace times (for render_states)
};

// The variants --variants takes, by name.
const std::map<std::string, Variant>& knownVariants();

// The scene a task runs in, as adroit_description's sceneFile names it.
std::string sceneOf(const std::string& task);

// The drop options scale the same draws whatever their values, so trial k of one drop is
// trial k of another but for the drop (and the defaults give the trials as they always were);
// the typing options draw other sequences.
std::vector<TrialSpec> makeTrials(const std::string& task, int n, unsigned seed, const success::World& world);

}  // namespace success
