// A behaviour task for the MPC (thesis 6.5): a running and a terminal cost on the planning
// model, with Gauss-Newton derivatives, plus the task's progress on the real system.
//
// Threading: the planner owns its own copy of the task (clone() once, at initialisation) and
// refreshes it with copyParametersFrom() at the start of every optimise, so the node can change
// the goal or the key sequence on its own copy at any time. Cost functions are const and
// thread-safe; their scratch memory is the per-thread TaskScratch.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Dense>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace adroit_mpc {

// Planner control vector u = [actuator controls (model nu) | synergy activations (synergy_dims)].
// State deviation dx = [dq (nv, tangent) | dv (nv) | act (na)], nx = 2 nv + na.
struct CostDerivatives {
  void resize(int nx, int nu);  // allocates; zeroes
  void setZero();
  Eigen::VectorXd lx, lu;
  Eigen::MatrixXd lxx, luu, lux;  // lux: nu x nx
};

// Per-thread scratch of a task (Jacobian buffers...). Tasks derive from it.
struct TaskScratch {
  virtual ~TaskScratch() = default;
};

// A message about the task's progress for the node to publish (typed key, error, phase).
struct TaskEvent {
  std::string kind;    // e.g. "key", "error", "phase"
  std::string detail;  // e.g. "7", "pressed 8 instead of 7", "hold"
};

// Construction parameters of a task from YAML / ROS params, flat: unknown keys are an error.
struct TaskParams {
  std::map<std::string, double> numbers;               // weights "w_<term>", scalars
  std::map<std::string, std::vector<double>> vectors;  // goal position, hold pose...
  std::map<std::string, std::string> strings;          // key sequence, finger assignment...
};

class Task {
 public:
  virtual ~Task() = default;
  virtual std::string name() const = 0;
  virtual std::unique_ptr<Task> clone() const = 0;
  // Copies the live parameters (goal, phase, key progress, weights) of a task of the same
  // type; allocates nothing. Throws std::invalid_argument for another task type.
  virtual void copyParametersFrom(const Task& other) = 0;

  // Resolves names against the planning model; throws std::invalid_argument naming what is
  // missing. synergy_dims: extra control dimensions after the model's actuators.
  virtual void bind(const mjModel* model, int synergy_dims) = 0;
  virtual std::unique_ptr<TaskScratch> makeScratch(const mjModel* model) const = 0;

  // `data` holds the knot's state after mj_forward (positions, velocities, sites valid).
  // u has nu + synergy_dims entries. t: absolute time [s] of the knot.
  virtual double runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                             TaskScratch& s) const = 0;
  virtual double terminalCost(const mjModel* m, const mjData* d, double t, TaskScratch& s) const = 0;
  // Same costs with their derivatives (gradient and Gauss-Newton Hessian) into `out`
  // (out.lu / luu / lux are left zero by terminalCostDerivatives). Returns the cost.
  virtual double runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u,
                                        double t, TaskScratch& s, CostDerivatives& out) const = 0;
  virtual double terminalCostDerivatives(const mjModel* m, const mjData* d, double t, TaskScratch& s,
                                         CostDerivatives& out) const = 0;

  // Progress on the real system (node thread): key presses, phase changes. `d` is the
  // estimated state after mj_forward on the planning model. Returns events to publish.
  virtual std::vector<TaskEvent> observe(const mjModel* /*m*/, const mjData* /*d*/, double /*t*/) { return {}; }
  // Named cost weights (YAML defaults, dynamic_reconfigure). setWeight throws
  // std::invalid_argument for an unknown name or a negative / non-finite value.
  virtual std::vector<std::string> weightNames() const = 0;
  virtual double weight(const std::string& name) const = 0;
  virtual void setWeight(const std::string& name, double value) = 0;

  // Live commands. Each returns false with a one-line reason in *why when the task does not
  // take the command or the input is bad (NaN, outside the workspace, unknown key).
  virtual bool setGoal(const Eigen::Vector3d& /*position*/, const Eigen::Quaterniond& /*orientation*/,
                       std::string* why) {
    *why = "task " + name() + " takes no goal pose";
    return false;
  }
  virtual bool release(std::string* why) {
    *why = "task " + name() + " has nothing to release";
    return false;
  }
  virtual bool setSequence(const std::string& /*keys*/, std::string* why) {
    *why = "task " + name() + " takes no key sequence";
    return false;
  }

  // Task-specific success measure at the current state (benchmarks, tests): e.g. object
  // distance to the goal [m]; typing: keys still to type.
  virtual double error(const mjModel* m, const mjData* d) const = 0;
};

// "catch", "relocate" or "type" (task_factory.cpp); throws std::invalid_argument with one
// line naming the bad task name or parameter.
std::unique_ptr<Task> makeTask(const std::string& name, const TaskParams& params);

}  // namespace adroit_mpc
