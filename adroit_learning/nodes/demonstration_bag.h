// A teleop bag as a Demonstration (thesis 10.3 -> 10.4): adroit_teleop's `demos export` turns
// the bag into the trainer's matrix format on the task's control step (one piece of code reads
// bags and knows their topics), started with an argument vector, never a shell.
#pragma once
#include <adroit_learning/demonstration.h>

#include <string>

namespace adroit {

// Exports `bag` at `control_dt` (valve actions when it has them) into `work_dir`/demonstration.txt and reads
// it. Throws DemonstrationError with one line naming the bag and what is wrong (not a bag,
// missing topics, non-finite values, gaps: `demos export`'s own message).
Demonstration exportDemonstration(const std::string& bag, double control_dt, const std::string& work_dir);

}  // namespace adroit
