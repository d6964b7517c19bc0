#include "demonstration_bag.h"

#include <adroit_core/number_text.h>
#include <adroit_core/run_program.h>

#include <cstdio>

namespace adroit {

namespace {

// The last non-empty line of a program's output: `demos` prints one line per problem.
std::string lastLine(const std::string& text) {
  std::size_t end = text.find_last_not_of("\n ");
  if (end == std::string::npos) return "";
  const std::size_t start = text.rfind('\n', end);
  return text.substr(start == std::string::npos ? 0 : start + 1, end - (start == std::string::npos ? 0 : start + 1) + 1);
}

}  // namespace

Demonstration exportDemonstration(const std::string& bag, double control_dt, const std::string& work_dir) {
  const std::string out = work_dir + "/demonstration.txt";
  ProgramOptions options;
  options.timeout_s = 120;  // a 4 GiB bag takes long; a normal one a second or two
  options.capture_output = true;
  options.merge_stderr = true;
  char dt[32];
  std::snprintf(dt, sizeof(dt), "%.9g", control_dt);
  const ProgramResult r = runProgram(
      {"rosrun", "adroit_teleop", "demos", "export", bag, "--out", out, "--dt", dt, "--actions", "auto", "--commands", "mean"}, options);
  if (!r.ok()) {
    const std::string why = lastLine(r.output);
    throw DemonstrationError(why.empty() ? bag + ": demos export failed: " + r.describe() : why);
  }
  return readDemonstrationFile(out);
}

}  // namespace adroit
