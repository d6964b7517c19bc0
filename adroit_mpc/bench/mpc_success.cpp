// Behaviour MPC success over randomised trials (issue: catch >= 80 %, relocation within 3 cm
// >= 80 %, typing >= 90 % of keys, in pneumatic mode; pneumatic >= 0.9 x force mode), iLQG
// against predictive sampling, synergies on / off, force against pneumatic mode, on identical
// trials. A program, not a test.
//
//   mpc_success [--trials N] [--tasks catch,relocate,type] [--variants ilqg,sampling,cem,cem_pneumatic,nosyn,pneumatic,pneumatic_open,as_planned,nocomp,coldfd,fullfd,pneumatic_fullfd]
//               [--out DIR] [--seed S] [--only-trial K] [--fixed-latency S] [--latency-sweep S,S,...]
//               [--dt S] [--horizon S] [--skip K] [--tension-step-weight W] [--sensed] [--feedback-scale F] [--contact M,S] [--events]
//               [--idle S]
//               [--compensation on|off|task] [--set [task.]key=number]... [--pool ilqg_key=number]...
//               [--object-mass KG] [--object-scale S] [--drop-height MIN,MAX] [--drop-offset M]
//               [--sensor-noise F] [--keys N] [--key-set DIGITS] [--sweep NAME=v1,v2,...]...
//
// --compensation: latency compensation (latency_compensation.h: plan from the state the running
// policy is predicted to reach when the plan takes over, at the planning latency: the fixed one,
// else the median of the trial's last nine), as the node's ~latency_compensation; default: the
// task's hint (type on). Variant nocomp is iLQG without it whatever the setting: its baseline.
// Variant coldfd is iLQG with every finite-difference nudge solved from the knot's warm start
// (mjd_transitionFD's) instead of the nominal step's solution (PlannerSettings::fd_warmstart,
// on by default): its baseline.
// Variants fullfd and pneumatic_fullfd are iLQG (force, pneumatic mode) on the derivative path
// before issue 38: every knot of the skip pattern evaluated at every optimise, one nudge per
// control (PlannerSettings::derivative_max_age 0, fd_force_space off): the baselines of the
// reused derivatives and of B through the generalised forces.
// The table's "start" column says how far each plan's starting state was from the state when it
// took over (joint RMS, median): the prediction's error, or without it the measured state's age.
//
// --dt, --horizon, --skip override the task's planner_dt, horizon and derivative_skip hints
// (defaults: config/tasks/<task>.yaml, else config/mpc.yaml's).
// --tension-step-weight W: PlannerSettings::tension_step_weight (the cost of a tension step
// from one knot to the next; 0: the plans before it). Pneumatic variants print each finger
// group's largest reference step per knot and its 99th percentile ("max step", "p99 step") beside
// the force tracking.
// --contact M,S: the planning model's contact margin and softness [m] (defaults: planning_model.h;
// typing 0.001, 0.001 as the node).
// --sensed: the planner and the policy see the driver's sensed signals (sensor realism: noise,
// quantisation, delays) instead of the true state, as the node does.
// --feedback-scale F: the fraction of the policy's feedback gains applied, in [0, 1] (the
// node's ~feedback_scale; default: the task's feedback_scale hint, else 1).
// --latency-sweep: iLQG on every task again with each fixed planning latency (simulated
// s per optimisation instead of the measured wall time): how fast the planner must be.
// Variant as_planned (diagnostic): iLQG in force mode against a simulation that runs the
// planning MJCF (Table 6.1 armature and springs, pruned contacts, the planning keypad) in its
// 2 ms steps: what the same planner does when its model is right, i.e. how much of a task's
// shortfall is model mismatch rather than the cost or the planner.
// --only-trial K: of the N seeded trials, run trial K alone (its traces and states are written);
//   each trial gets a new simulated robot (sensor noise from its seed, nothing left over from
//   the trial before), so with --fixed-latency this is exactly trial K of the full run.
// --events: print each trial's task events (phase, relocation stage, keys) with their time.
// --idle S: typing only: the hand rests over the keys S seconds, closed loop, before the
//   sequence is given; keys registered meanwhile are typed unasked (printed, CSV `unasked`).
// --set [task.]key=number: a task parameter (weight, threshold) over config/tasks/<task>.yaml, for
// tuning without a rebuild (the --latency-sweep runs use it too). Without "task." the key must be
// a number parameter of every task that runs. Refused: keys no task has, and keys that would
// change nothing here (the planner hints: --horizon, --dt, --skip, --feedback-scale,
// --compensation set those; object_mass / object_radius, which no task reads: --object-mass,
// --object-scale).
//
// What the tasks were not tuned on (success/robustness.h; defaults: what they were tuned on):
// --object-mass KG, --object-scale S: the object (bottle, ball) in the simulated world and in
//   the planning model alike (scaleObjectBody; S scales its geoms, inertia ~ S^2);
// --drop-height MIN,MAX (or H): the release height above the catch goal / relocation hold
//   (0.04,0.09); --drop-offset M: the sideways range +-M in x and y (0.015);
// --sensor-noise F: every noise std of the driver's sensors times F (read by the planner with
//   --sensed, and by the pools in pneumatic variants; refused when nothing reads them);
// --keys N, --key-set DIGITS: typing sequences of N keys drawn from DIGITS (10, 0123456789).
// An option is refused when no task that runs would feel it. --sweep NAME=v1,v2,... (NAME: an
// option above with '_' for '-', drop_height takes one height per value) runs the tasks and
// variants once per value instead of the run above, prints a table per value and one across
// the values, writes DIR/success_sweep.csv and ends with a RESULT line per task, variant and
// value (success in %: trials, typing: keys right; target 90).
// Typing reports its presses: every registered press, and the wrong ones (a key other than the
// one expected next, a wrong key later backspaced included: keys right forgives it);
// RESULT type_<variant>_wrong_press_percent (target <= 10 %), DIR/success_presses.csv.
// --pool ilqg_key=number: a setting of the pools' iLQG (names of IlqgParams, setIlqgParam),
// over config/pools.yaml's (iterations 1, the rest IlqgParams' defaults).
//
// Closed loop in emulated real time, ROS-free, against the simulation driver's core
// (adroit_driver::SimulatedRobot: the physical scene in 2 ms steps, the pneumatic plant,
// sensors, watchdog). Variants ilqg, sampling, cem, nosyn drive it in force mode (the policy's
// tendon forces every step); pneumatic (cem_pneumatic: CEM) is iLQG with the plan's tensions over the horizon
// sent to a pool of every cylinder (adroit_pneumatics::CylinderPool, iLQG pressure control
// at 200 Hz on the sensed pressures, config/pools.yaml settings, identified models), whose
// valve commands drive the plant, as the node does in mode:=pneumatic. The pools' CPU time
// is not charged to the planner (they run beside it). The planner plans on the planning
// model from the true simulated state. The closed loop is the node's own (adroit_mpc::MpcRunner,
// mpc_runner.h) in emulated real time: a plan whose planOnce took c seconds of wall time on this
// machine takes over c seconds of simulated time after the state it started from, and the
// previous policy runs in between (what the node's planner thread does against a driver
// running in real time, with the cores to itself). The planner optimises ten times
// before the trial starts, then runs closed loop for 0.3 s with the object held at its start
// (the MPC runs before the object is released; the pools pressurise the cylinders).
//
// Trials (seeded; every variant sees the same ones, paired: trial k runs under each variant in
// turn before trial k + 1, so a change of the machine's speed falls on all variants alike):
//   catch     bottle released 4-9 cm above the goal, +-1.5 cm sideways; 2.5 s; success: it
//             never falls below the palm (z >= 0.2 m) and ends within 3 cm of the goal;
//   relocate  (thesis 6.5: relocation starts as a dynamic stabilisation) the ball released
//             4-9 cm above the hold position in the palm-up hand, +-1.5 cm sideways; the goal,
//             at least 5 cm from the hold position (x +-8, y +-6, z -10..0 cm), given 1 s
//             later (setGoal, as a user would);
//             4 s; success: the ball ends within 3 cm of the goal (the program prints how far
//             the goals are from the hold: what staying put would score). The goals are in free
//             air, so a ball there is in the hand. (A height threshold, once part of it, counted
//             the arm's dip as it takes the ball's impact, or a ball resting at a low goal, as a
//             drop.) The CSV has the lowest height and, from the goal on, the farthest distance
//             of the ball from the grasp site;
//   type      a random 10-digit sequence; until typed or 1.5 s per key; keys correct = keys
//             typed correctly (auto-correction allowed), speed = correct keys per minute;
//             presses and wrong presses (TypeTask::presses, wrongPresses).
//
// Writes DIR/success_trials.csv (one row per trial), DIR/success_traces.csv (the first trial
// of each task and variant, error over time) and plots them with plot_success.py into
// DIR/success_<task>.png, and DIR/states_<task>_<variant>.csv (the first trial's joint
// positions, for render_states); pneumatic variants also DIR/forces_<task>_<variant>.csv (the
// first trial's planned and sensed tension per cylinder at the pools' ticks) and print the
// force tracking per group next to the plant's floor (adroit_pneumatics ForceTrackingAudit).
// Ends with RESULT lines (DESIGN.md section 5).
#include <adroit_core/run_program.h>

// Its parts (success/): the variants and the seeded trials (trial.h), the closed loop of one
// trial (trial_runner.h), the command line (options.h), what it prints (report.h) and writes
// (outputs.h), the world beyond the tasks' tuning and the sweeps (robustness.h).
#include "success/options.h"
#include "success/outputs.h"
#include "success/report.h"
#include "success/robustness.h"
#include "success/trial.h"
#include "success/trial_runner.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace success {

namespace {

std::unique_ptr<TrialRunner> makeRunner(const std::string& task, const Variant& variant, const Options& o,
                                        const success::World& world) {
  auto runner = std::make_unique<TrialRunner>(task, variant, o.overrides, world, o.contact_margin, o.contact_softness);
  runner->setFixedLatency(o.fixed_latency);
  runner->setSensed(o.sensed);
  if (o.feedback_scale >= 0) runner->setFeedbackScale(o.feedback_scale);
  if (o.compensation != "task") runner->setCompensation(o.compensation == "on");
  runner->setPrintEvents(o.print_events);
  runner->setIdle(o.idle);
  runner->setParams(o.paramsOf(task));
  runner->setPoolParams(o.pool_ilqg);
  return runner;
}

std::vector<TrialSpec> trialsOf(const std::string& task, const Options& o, const success::World& world) {
  auto specs = makeTrials(task, o.trials, o.seed, world);
  if (o.only_trial >= 0) specs = {specs[o.only_trial]};
  return specs;
}

// Every variant on the task's trials, paired: trial k runs under every variant before trial
// k + 1 does, so a change in this shared machine's speed during the run falls on all variants
// alike (run in blocks, the variant run last would take all of a slowdown). Prints a row per
// variant; returns the tallies in variant order.
std::vector<Tally> runTask(const std::string& task, const Options& o, const success::World& world, Outputs& out) {
  const auto specs = trialsOf(task, o, world);
  if (task == "relocate") printRelocateBaseline(specs, o);
  std::vector<std::unique_ptr<TrialRunner>> runners;
  for (const auto& variant : o.variants) runners.push_back(makeRunner(task, variant, o, world));
  std::vector<Tally> tallies(o.variants.size());
  for (const auto& spec : specs) {
    for (std::size_t v = 0; v < o.variants.size(); ++v) {
      runners[v]->resetTrace();
      if (o.print_events) printTrialStart(task, o.variants[v], spec);
      const TrialResult r = runners[v]->run(spec);
      if (o.print_events) std::printf("  end: error %.4f m%s\n", r.final_error, r.success ? " (success)" : "");
      tallies[v].add(r);
      out.record(task, o.variants[v], spec, r, *runners[v], &spec == &specs.front());
      std::fflush(stdout);
    }
  }
  for (std::size_t v = 0; v < o.variants.size(); ++v) printVariant(task, o.variants[v], tallies[v], *runners[v], o);
  return tallies;
}

// --latency-sweep: iLQG on every task again at each fixed planning latency.
void runLatencySweep(const Options& o, std::ofstream& trials_csv) {
  for (const auto& task : o.latency_sweep.empty() ? std::vector<std::string>{} : o.tasks) {
    const auto specs = makeTrials(task, o.trials, o.seed, o.world);
    std::printf("\n%s, iLQG, success against a fixed planning latency (simulated s per optimisation):\n",
                task.c_str());
    TrialRunner runner(task, knownVariants().at("ilqg"), o.overrides, o.world, o.contact_margin, o.contact_softness);
    runner.setParams(o.paramsOf(task));
    if (o.compensation != "task") runner.setCompensation(o.compensation == "on");
    if (o.feedback_scale >= 0) runner.setFeedbackScale(o.feedback_scale);
    for (const auto& value : o.latency_sweep) {
      const double latency = std::atof(value.c_str());
      runner.setFixedLatency(latency);
      int ok = 0, keys_ok = 0, keys_all = 0;
      for (const auto& spec : specs) {
        runner.resetTrace();
        const TrialResult r = runner.run(spec);
        ok += r.success;
        keys_ok += r.keys_correct;
        keys_all += r.keys_total;
        trials_csv << task << ",latency_" << value << "," << spec.index << "," << r.success << "," << r.final_error
                   << "," << (r.lowest_z > 1e8 ? 0 : r.lowest_z) << "," << r.farthest_from_grasp << ","
                   << r.keys_correct << "," << r.keys_total << "," << r.duration << "," << 1e3 * latency << ","
                   << r.diverged << "," << r.unasked << "\n";
      }
      if (task == "type")
        std::printf("  latency %5.0f ms: %d/%zu sequences, %d/%d keys\n", 1e3 * latency, ok, specs.size(), keys_ok,
                    keys_all);
      else
        std::printf("  latency %5.0f ms: %d/%zu\n", 1e3 * latency, ok, specs.size());
      std::fflush(stdout);
    }
  }
}

// The run without --sweep: the table, the CSVs, the plots, the RESULT lines.
int runDefault(const Options& o) {
  Outputs out;
  if (!out.open(o.out_dir, false)) {
    std::fprintf(stderr, "mpc_success: cannot write into %s\n", o.out_dir.c_str());
    return 2;
  }
  printTableHeader();
  TaskTallies tallies;
  for (const auto& task : o.tasks) tallies[task] = runTask(task, o, o.world, out);
  runLatencySweep(o, out.trials);
  out.trials.close();
  out.traces.close();
  out.presses.close();

  // plot_success.py is installed next to this program.
  const std::string script = std::filesystem::read_symlink("/proc/self/exe").parent_path() / "plot_success.py";
  const auto plot = adroit::runProgram({"python3", script, o.out_dir}, adroit::ProgramOptions{});
  if (!plot.ok()) std::printf("\n(plotting failed: %s)\n", plot.describe().c_str());
  else std::printf("\nplots: %s/success_<task>.png\n", o.out_dir.c_str());
  std::printf("\n");
  printResults(o, tallies);
  return 0;
}

// --sweep: the tasks and variants again for each value of each swept option, the rest of the
// world as the command line has it.
int runSweeps(const Options& o) {
  Outputs out;
  if (!out.open(o.out_dir, true)) {
    std::fprintf(stderr, "mpc_success: cannot write into %s\n", o.out_dir.c_str());
    return 2;
  }
  std::vector<SweepTable> tables;
  for (const auto& sweep : o.sweeps) {
    tables.push_back({sweep, {}});
    for (const auto& value : sweep.values) {
      success::World world = o.world;
      success::setWorldOption(world, sweep.name, value);  // checked by parseSweep
      std::printf("\n%s = %s: %s\n", sweep.name.c_str(), value.c_str(), success::describe(world).c_str());
      printTableHeader();
      out.point = sweep.name + "," + value;
      TaskTallies tallies;
      for (const auto& task : o.tasks) tallies[task] = runTask(task, o, world, out);
      tables.back().points.push_back(tallies);
    }
  }
  for (const auto& table : tables) printSweepTable(table, o);
  std::printf("\ntrials: %s/success_sweep.csv\n\n", o.out_dir.c_str());
  for (const auto& table : tables) printSweepResults(table, o);
  return 0;
}

}  // namespace

}  // namespace success

int main(int argc, char** argv) {
  const success::Options options = success::parseOptions(argc, argv);
  success::printHeader(options);
  return options.sweeps.empty() ? success::runDefault(options) : success::runSweeps(options);
}
