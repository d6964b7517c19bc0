// Runs a program with an argument vector, never through a shell: an argument is passed to the
// program as it is, so quotes, ';' or '$(...)' in a path from a parameter or a service request
// are only characters. The only way the stack starts another process.
//
//   auto r = adroit::runProgram({"python3", script, "--csv", csv}, 30.0);
//   if (!r.ok()) ROS_WARN("plot not written: %s", r.describe().c_str());
#pragma once

#include <string>
#include <vector>

namespace adroit {

struct ProgramResult {
  bool started = false;    // false: the program could not be started (error says why)
  bool timed_out = false;  // it ran past the timeout and was killed (SIGKILL)
  int exit_code = -1;      // its exit status, or -1 if it did not exit normally
  int signal = 0;          // the signal that ended it, if one did
  std::string output;      // its standard output, when asked for
  std::string error;       // why it could not be started

  bool ok() const { return started && !timed_out && exit_code == 0; }
  // One line: "exit 1", "killed after the 30 s timeout", "cannot start 'x': No such file...".
  std::string describe() const;
};

struct ProgramOptions {
  double timeout_s = 60.0;       // killed (with its process group) after this long
  bool capture_output = false;   // collect standard output into ProgramResult::output
  size_t max_output = 1 << 20;   // bytes of output kept; the rest is read and dropped
  bool quiet = false;            // standard output and error go to /dev/null (unless captured)
  bool merge_stderr = false;     // with capture_output: standard error goes to `output` too
};

// argv[0] is looked up on PATH when it has no '/'. The child gets no standard input.
ProgramResult runProgram(const std::vector<std::string>& argv, const ProgramOptions& options = {});

}  // namespace adroit
