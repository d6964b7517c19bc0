// mpc_success's command line: the options (see the top of mpc_success.cpp), parsed and
// checked; a wrong option or value, or one that would change nothing, ends the program with
// one line and the usage (adroit::CommandLine, status 2).
#pragma once

#include "robustness.h"
#include "trial.h"

#include <adroit_mpc/planner.h>
#include <adroit_pneumatics/pressure_control.h>

#include <algorithm>
#include <map>
#include <string>
#include <vector>

namespace success {

// The command line (see the top of mpc_success.cpp).
struct Options {
  int trials = 20;
  unsigned seed = 1;
  int only_trial = -1;  // >= 0: run this trial of the seeded set alone (its traces are written)
  double fixed_latency = -1;
  bool sensed = false;
  double feedback_scale = -1;         // the task's hint
  std::string compensation = "task";  // on | off | task (its hint)
  double contact_margin = -1, contact_softness = -1;  // --contact M,S
  bool print_events = false;
  double idle = 0;                  // --idle S: typing rests that long before its sequence
  success::TaskNumbers params;      // --set [task.]key=number, per task
  adroit::pneumatics::IlqgParams pool_ilqg;  // --pool key=value over config/pools.yaml's settings
  bool pool_set = false;                     // a --pool was given
  std::vector<std::string> latency_sweep;  // fixed latencies [s] for iLQG on every task
  adroit_mpc::PlannerSettings overrides;  // horizon, dt, skip <= 0: the task's hints
  std::string out_dir = ".";
  std::vector<std::string> tasks;
  std::vector<Variant> variants;
  success::World world;                // --object-mass ... --key-set
  std::vector<success::Sweep> sweeps;  // --sweep name=v1,v2,...

  bool has(const std::string& variant) const {
    return std::any_of(variants.begin(), variants.end(), [&](const Variant& v) { return v.name == variant; });
  }
  bool poolsRun() const {
    return std::any_of(variants.begin(), variants.end(), [](const Variant& v) { return v.pneumatic; });
  }
  std::map<std::string, double> paramsOf(const std::string& task) const {
    const auto it = params.find(task);
    return it == params.end() ? std::map<std::string, double>{} : it->second;
  }
};

// The command line's options, checked: variants and tasks by name, --set against the tasks,
// and options that would change nothing.
Options parseOptions(int argc, char** argv);

}  // namespace success
