// Checks of the trainer's service requests and the learning-curve plot it starts. A request is
// checked in full before anything reaches a driver and before any number is converted, so a
// refused request changes nothing; each check returns "" or one line naming the field, its
// range and the value received.
#pragma once

#include <adroit_core/run_program.h>

#include <cstdint>
#include <string>
#include <vector>

namespace adroit {

constexpr std::uint64_t kMaxTrainIterations = 10000;
constexpr std::uint64_t kMaxTrainRollouts = 1000;
constexpr double kMaxExecuteDuration = 3600.0;  // s

// "iterations must be in [1, 10000], got 3000000000"
std::string countProblem(const std::string& field, std::uint64_t value, std::uint64_t min, std::uint64_t max);

// ExecutePolicy.duration: 0 (the whole policy) or a finite time in (0, kMaxExecuteDuration] s.
std::string executeDurationProblem(double duration);

// Control steps a policy runs for: its horizon, or fewer when a (checked) duration is shorter.
int executeHorizon(int policy_horizon, double control_dt, double duration);

// The plot of <dir>/learning_curve.csv into <dir>/learning_curve.png (scripts/
// plot_learning_curve.py) as an argument vector: the directory is one argument, never shell text.
std::vector<std::string> learningCurvePlotCommand(const std::string& script, const std::string& dir,
                                                  const std::string& title = "");
ProgramResult plotLearningCurve(const std::string& script, const std::string& dir, const std::string& title = "");

}  // namespace adroit
