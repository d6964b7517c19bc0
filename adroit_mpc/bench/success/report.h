// What mpc_success prints: the table (a row per task and variant, the pools' audit beside the
// pneumatic ones), the relocation baseline, the RESULT lines (DESIGN.md section 5) and the
// sweeps' tables.
#pragma once

#include "options.h"
#include "robustness.h"
#include "trial.h"

#include <array>
#include <map>
#include <string>
#include <vector>

namespace success {

class TrialRunner;

// Per variant of a task, over its trials.
struct Tally {
  int n = 0, ok = 0, diverged = 0, keys_ok = 0, keys_all = 0, unasked = 0, unasked_trials = 0;
  int presses = 0, wrong_presses = 0;
  double error_sum = 0, typing_time = 0;
  std::vector<double> plan_ms, start_errors;
  std::array<std::vector<double>, 5> phase_ms;
  void add(const TrialResult& r) {
    ++n;
    ok += r.success;
    diverged += r.diverged;
    error_sum += r.final_error;
    keys_ok += r.keys_correct;
    keys_all += r.keys_total;
    unasked += r.unasked;
    unasked_trials += r.unasked > 0;
    presses += r.presses;
    wrong_presses += r.wrong_presses;
    typing_time += r.duration;
    plan_ms.push_back(r.plan_ms_median);
    start_errors.push_back(r.start_error_median);
    for (std::size_t k = 0; k < phase_ms.size(); ++k) phase_ms[k].push_back(r.phase_ms_median[k]);
  }
  double successRate() const { return static_cast<double>(ok) / n; }
  double keysRate() const { return keys_all ? static_cast<double>(keys_ok) / keys_all : 0; }
  double keysPerMinute() const { return typing_time > 0 ? 60.0 * keys_ok / typing_time : 0; }
  double wrongPercent() const { return presses ? 100.0 * wrong_presses / presses : 0; }
  // The success figure: trials for the object tasks, keys right for typing.
  double successPercent(const std::string& task) const { return 100 * (task == "type" ? keysRate() : successRate()); }
};

using TaskTallies = std::map<std::string, std::vector<Tally>>;  // task -> per variant (Options order)

// One sweep's success per task and variant across its values, then a RESULT line per point.
struct SweepTable {
  success::Sweep sweep;
  std::vector<TaskTallies> points;  // per value
};

// Relocation's baseline: a ball left at the hold position misses every goal by this much.
void printRelocateBaseline(const std::vector<TrialSpec>& specs, const Options& o);

void printTableHeader();

void printTrialStart(const std::string& task, const Variant& variant, const TrialSpec& spec);

void printVariant(const std::string& task, const Variant& variant, const Tally& t, const TrialRunner& runner,
                  const Options& o);

// The RESULT lines of the run without --sweep. The figures are in pneumatic mode (the
// pools tracking the plan); without that variant the force-mode iLQG figures stand in (and say so).
void printResults(const Options& o, const TaskTallies& tallies);

void printHeader(const Options& o);

void printSweepTable(const SweepTable& s, const Options& o);

void printSweepResults(const SweepTable& s, const Options& o);

}  // namespace success
