// A demonstration for learning from imitation (thesis 10.3, 10.4): the (x_t, u_t) trajectory
// that adroit_teleop's `demos export` writes from a teleop bag, in the trainer's state layout
// and on the task's control step. The trainer takes two things from it: the hand
// configuration q_hat_t of the shaping cost ||q_t - q_hat_t||^2, and the controls u_t its
// first iteration samples around instead of the task's initial controller. For the pickup
// task it also fixes the condition: the tube's initial orientation.
//
// ROS-free: the trainer node turns a bag into this file with `demos export`, so one piece of
// code reads bags.
#pragma once
#include <adroit_learning/pickup.h>
#include <adroit_learning/trajectory_cost.h>
#include <adroit_learning/training_task.h>

#include <Eigen/Dense>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit {

class DemonstrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Demonstration {
  std::string path;
  std::string task, mode, model;                  // from the recording's metadata
  std::vector<std::string> joints, cylinders;     // the robot's, in x and u order
  bool has_object = false;
  std::string actions;                            // "valve" or "force"
  double dt = 0;                                  // s between samples
  Eigen::MatrixXd x;                              // nx x samples (StateLayout of a task using the object)
  Eigen::MatrixXd u;                              // cylinders x samples (the commands in force at each sample)
  int samples() const { return static_cast<int>(x.cols()); }
};

// Reads a `demos export` file: its header comments (task, mode, model, joints, cylinders,
// object, actions) and blocks X (samples x nx), U (samples x cylinders), dt. Throws
// DemonstrationError "<path>: <what>" for a missing, non-regular or oversized file, a header
// without these lines, blocks whose sizes disagree with it, or non-finite values.
Demonstration readDemonstrationFile(const std::string& path);

// "" when the demonstration can teach `task`, else one line naming what is wrong: another
// task or scene, actions that are not valve commands (a force mode recording: the trainer
// learns valve commands), no object for an object task, a sample step other than the task's
// control step, or fewer than T + 1 samples ("too short: 2.1 s, the task needs 4 s").
std::string demonstrationTaskMismatch(const Demonstration& demo, const TrainingTask& task);
// "" when it was recorded on the robot `layout` describes (joints, cylinders, state size).
std::string demonstrationRobotMismatch(const Demonstration& demo, const StateLayout& layout);
// Both.
std::string demonstrationMismatch(const Demonstration& demo, const TrainingTask& task, const StateLayout& layout);

// What imitation changes in the task (thesis 10.4): q_hat_t = the demonstration's joints at
// steps 0..T (joint_reference) and, for a task with initial_object_yaw, the tube's initial yaw
// as the demonstration started it (tubeYawFromState), so the local policy trains on the
// demonstration's condition, and the exploration variance is the task's imitation_variance
// (when set). Call after demonstrationMismatch returned "".
void imitateDemonstration(const Demonstration& demo, const StateLayout& layout, const ObjectGeometry& geometry,
                          TrainingTask& task);

// The demonstration's first T controls of the action cylinders (nu x T): the mean of the
// first iteration's controller.
Eigen::MatrixXd demonstrationActions(const Demonstration& demo, const StateLayout& layout, int horizon);

// The tube's yaw (degrees in [0, 180)) in a state x of `layout` (the object's rotation vector).
double tubeYawFromState(const Eigen::Ref<const Eigen::VectorXd>& x, const StateLayout& layout,
                        const ObjectGeometry& geometry);

}  // namespace adroit
