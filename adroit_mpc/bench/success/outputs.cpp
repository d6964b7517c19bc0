#include "outputs.h"

#include "trial_runner.h"

namespace success {

bool Outputs::open(const std::string& out_dir, bool sweeping) {
  dir = out_dir;
  if (sweeping) {
    sweep.open(dir + "/success_sweep.csv");
    sweep << "sweep,value,task,variant,trial,success,final_error,keys_correct,keys_total,presses,wrong_presses,"
             "unasked,duration,plan_ms\n";
    return static_cast<bool>(sweep);
  }
  trials.open(dir + "/success_trials.csv");
  traces.open(dir + "/success_traces.csv");
  presses.open(dir + "/success_presses.csv");
  trials << "task,variant,trial,success,final_error,lowest_z,farthest_from_grasp,keys_correct,keys_total,duration,"
            "plan_ms,diverged,unasked\n";
  traces << "task,variant,t,error\n";
  presses << "variant,trial,presses,wrong_presses,keys_correct,keys_total,unasked\n";
  return trials && traces && presses;
}

void Outputs::record(const std::string& task, const Variant& variant, const TrialSpec& spec, const TrialResult& r,
                     const TrialRunner& runner, bool first) {
  if (sweep.is_open()) {
    sweep << point << "," << task << "," << variant.name << "," << spec.index << "," << r.success << ","
          << r.final_error << "," << r.keys_correct << "," << r.keys_total << "," << r.presses << ","
          << r.wrong_presses << "," << r.unasked << "," << r.duration << "," << r.plan_ms_median << "\n";
    return;
  }
  trials << task << "," << variant.name << "," << spec.index << "," << r.success << "," << r.final_error << ","
         << (r.lowest_z > 1e8 ? 0 : r.lowest_z) << "," << r.farthest_from_grasp << "," << r.keys_correct << ","
         << r.keys_total << "," << r.duration << "," << r.plan_ms_median << "," << r.diverged << "," << r.unasked
         << "\n";
  if (task == "type")
    presses << variant.name << "," << spec.index << "," << r.presses << "," << r.wrong_presses << ","
            << r.keys_correct << "," << r.keys_total << "," << r.unasked << "\n";
  if (!first) return;
  for (const auto& [time, e] : r.trace) traces << task << "," << variant.name << "," << time << "," << e << "\n";
  runner.writeStates(dir + "/states_" + task + "_" + variant.name + ".csv", r);
  runner.writeForces(dir + "/forces_" + task + "_" + variant.name + ".csv");
}

}  // namespace success
