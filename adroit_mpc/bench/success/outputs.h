// mpc_success's CSV files, written as the trials run.
#pragma once

#include "trial.h"

#include <fstream>
#include <string>

namespace success {

class TrialRunner;

// Where the trials go. The run without --sweep: success_trials.csv (as it always was),
// success_traces.csv and the states (and pool forces) of each task's first trial, and
// success_presses.csv (typing). A sweep: success_sweep.csv, one row per point and trial.
struct Outputs {
  std::string dir;
  std::ofstream trials, traces, presses, sweep;
  std::string point;  // the sweep point of the rows: "name,value"

  bool open(const std::string& out_dir, bool sweeping);

  void record(const std::string& task, const Variant& variant, const TrialSpec& spec, const TrialResult& r,
              const TrialRunner& runner, bool first);
};

}  // namespace success
