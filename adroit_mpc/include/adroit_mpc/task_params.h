// Task parameters shared by the behaviour tasks: the defaults of every task (the values of
// config/tasks/<name>.yaml), merging with one-line errors, named weights, goal checks.
#pragma once

#include <adroit_mpc/task.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace adroit_mpc {

// "catch", "relocate", "type".
std::vector<std::string> taskNames();

// Every parameter a task takes, with its default. The YAML files config/tasks/<name>.yaml
// hold the same keys and values (test_tasks checks they agree). Throws std::invalid_argument
// "unknown task 'x' (known: catch, relocate, type)".
TaskParams defaultTaskParams(const std::string& task);

// `defaults` overridden by `given`. Throws std::invalid_argument with one line for a key the
// task does not take ("task catch: unknown parameter 'x' (known: ...)") or a value of the
// wrong kind (a list where a number is expected...).
TaskParams mergeTaskParams(const std::string& task, const TaskParams& defaults, const TaskParams& given);

// Typed reads of merged parameters; throw std::invalid_argument("task catch: parameter 'x' ...").
double paramNumber(const std::string& task, const TaskParams& p, const std::string& key, double min, double max);
std::vector<double> paramVector(const std::string& task, const TaskParams& p, const std::string& key,
                                int size /* -1: any */);
Eigen::Vector3d paramVector3(const std::string& task, const TaskParams& p, const std::string& key);
// A quaternion [w x y z], normalised; throws when its norm is not finite or ~0.
Eigen::Quaterniond paramQuaternion(const std::string& task, const TaskParams& p, const std::string& key);
const std::string& paramString(const std::string& task, const TaskParams& p, const std::string& key);

// The named cost weights of a task: every number parameter "w_<term>". Fixed set after
// construction; values copy without allocation.
class WeightTable {
 public:
  WeightTable() = default;
  WeightTable(const std::string& task, const TaskParams& merged);  // takes every "w_" number

  const std::vector<std::string>& names() const { return names_; }
  int index(const std::string& name) const;  // throws std::invalid_argument for an unknown name
  double operator[](int i) const { return values_[i]; }
  double get(const std::string& name) const { return values_[index(name)]; }
  // Throws std::invalid_argument for an unknown name or a negative / non-finite value.
  void set(const std::string& name, double value);
  // Same names assumed (same task type); copies the values only.
  void copyValuesFrom(const WeightTable& other);

 private:
  std::string task_;
  std::vector<std::string> names_;
  std::vector<double> values_;
};

// An axis-aligned box of allowed goal positions [m, world frame].
struct WorkspaceBox {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(-1), max = Eigen::Vector3d::Constant(1);
  bool contains(const Eigen::Vector3d& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
};

// Checks a goal pose: finite position inside the box, finite quaternion that normalises.
// On success writes the normalised quaternion to *unit and returns true; otherwise returns
// false with a one-line reason in *why.
bool checkGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation, const WorkspaceBox& box,
               Eigen::Quaterniond* unit, std::string* why);

}  // namespace adroit_mpc
