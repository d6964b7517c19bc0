#include "adroit_learning/trainer_requests.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace adroit {

std::string countProblem(const std::string& field, std::uint64_t value, std::uint64_t min, std::uint64_t max) {
  if (value >= min && value <= max) return "";
  return field + " must be in [" + std::to_string(min) + ", " + std::to_string(max) + "], got " +
         std::to_string(value);
}

std::string executeDurationProblem(double duration) {
  if (duration == 0 || (duration > 0 && duration <= kMaxExecuteDuration)) return "";  // NaN fails both
  char text[160];
  std::snprintf(text, sizeof text, "duration must be 0 (the whole policy) or in (0, %g] s, got %g", kMaxExecuteDuration,
                duration);
  return text;
}

int executeHorizon(int policy_horizon, double control_dt, double duration) {
  if (duration <= 0) return policy_horizon;
  // duration <= kMaxExecuteDuration and control_dt >= 1 ms (task files): fits an int.
  const double steps = std::ceil(duration / control_dt);
  return steps < policy_horizon ? std::max(1, static_cast<int>(steps)) : policy_horizon;
}

std::vector<std::string> learningCurvePlotCommand(const std::string& script, const std::string& dir,
                                                  const std::string& title) {
  std::vector<std::string> argv = {"/usr/bin/python3", script, dir + "/learning_curve.csv",
                                   dir + "/learning_curve.png"};
  if (!title.empty()) argv.push_back(title);
  return argv;
}

ProgramResult plotLearningCurve(const std::string& script, const std::string& dir, const std::string& title) {
  ProgramOptions options;
  options.timeout_s = 60.0;
  options.quiet = true;
  return runProgram(learningCurvePlotCommand(script, dir, title), options);
}

}  // namespace adroit
