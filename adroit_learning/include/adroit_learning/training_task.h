// A trainer task (thesis 8.4): the scene, the horizon and control step, the initial state, the
// cost terms of 8.4.1 / 8.4.2 with their weights, which cylinders the controller drives, the
// initial controller and the success criteria. Read from YAML (config/tasks/<name>.yaml);
// every field is checked at load and an error names the file and the field.
#pragma once
#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit {

class TaskError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A target that changes over the horizon: piecewise constant, value i holds from
// fraction[i] * T on (fraction[0] = 0). One entry = a fixed target.
struct TargetSchedule {
  std::vector<double> fraction;
  std::vector<double> value;
  double at(int t, int horizon) const;  // the value in force at step t of T
};

struct TrainingTask {
  std::string name, description;
  std::string scene;             // adroit_description scene (hand, tube, ...)
  int horizon = 0;               // T control steps
  double control_dt = 0;         // s, a multiple of the physics step (2 ms)

  // Initial state: a keyframe of the scene, then joint overrides (rad).
  std::string initial_keyframe;
  std::map<std::string, double> initial_joints;
  // Optional object start (world position, m) replacing the keyframe's object position; the
  // object's orientation stays the keyframe's. Empty: the keyframe's object position.
  std::vector<double> initial_object_position;
  // Optional object orientation (pickup, thesis 11.3): the tube lying with its axis at this
  // many degrees from world +x towards +y, in [0, 180) (pickup.h: tubeOrientationFromYaw).
  std::optional<double> initial_object_yaw;

  // Cost (thesis 8.4.1, 8.4.2):
  //   l_t = w_q ||q - q*||^2 + w_u ||u||^2 + w_p ||p_obj - p*||^2 + w_r (angle_obj - angle*(t))^2
  //   l_T = final_scale [w_qT ||q - q*||^2 + w_p ||p_obj - p*||^2 + w_r (angle_obj - angle*(T))^2]
  // q* = the initial pose with target_joints overridden; p* = the object's initial position.
  std::map<std::string, double> target_joints;
  double joint_weight = 1.0, final_joint_weight = 10.0, action_weight = 1e-3;
  double object_position_weight = 0, object_rotation_weight = 0, final_scale = 1.0;
  double rotation_axis[3] = {0, 0, 1};  // world axis of the object angle (rotation vector component)
  TargetSchedule rotation_target;       // rad, object angle about the axis
  // Object goal position p* (world, m); empty: the object's initial position.
  std::vector<double> object_position_target;
  // Height term of the pickup cost (thesis 10.4): w_z (z_obj - z*)^2, running and final
  // (final_scale * w_z).
  double object_height_weight = 0, object_height_target = 0;
  // Per-step joint reference q_hat_t (thesis 10.4's shaping term ||q_t - q_hat_t||^2): T + 1
  // vectors of every joint in the robot's joint order, replacing q* in the joint term. Not read
  // from YAML: a demonstration fills it; empty = the constant q*.
  std::vector<std::vector<double>> joint_reference;

  // Actions: valve commands of every cylinder except the locked ones, which hold
  // locked_command (volts; 0 = centre, the chamber stays sealed) throughout.
  std::vector<std::string> locked_cylinders;
  double locked_command = 0;

  // Initial controller: u = initial_command, covariance initial_variance * I (V^2).
  double initial_command = 0, initial_variance = 1.0;
  // Learning from a demonstration (thesis 10.4): the first iteration samples around the
  // demonstration's controls with "small random noise", this variance (V^2) instead of
  // initial_variance, which is sized for exploring from scratch. 0 = initial_variance.
  double imitation_variance = 0;
  double epsilon = 1.0;  // first KL step size (nats over the trajectory)

  // Success at T: joint RMS error over target_joints below success_joint_rms (rad); object
  // tasks also need the angle within success_angle (rad) and the object above drop_height (m).
  double success_joint_rms = 0.05, success_angle = 0.2, drop_height = -1e9;
  // "pickup": thesis 11.4's criterion instead (pickup.h: pickupSuccess, its thresholds there).
  std::string success_criterion;
  bool pickupSuccessCriterion() const { return success_criterion == "pickup"; }

  // Initial chamber pressure of every cylinder (Pa absolute): antagonists at equal pressure
  // hold the pose with some stiffness instead of starting slack.
  double initial_pressure = 250e3;
  // Initial-state noise (delayed robustification, 8.5.1): at noise level s each joint starts
  // uniformly within +-s/2 of its range around the initial pose (clamped to the range).
  bool uses_object() const {
    return object_position_weight > 0 || object_rotation_weight > 0 || object_height_weight > 0 ||
           pickupSuccessCriterion();
  }
};

// Loads and checks one task file. Throws TaskError("<file>: <field>: <problem>").
TrainingTask loadTrainingTask(const std::string& path);

// The task <name> in directory `dir` (<dir>/<name>.yaml). An unknown name throws TaskError
// listing the known ones.
TrainingTask findTrainingTask(const std::string& dir, const std::string& name);
std::vector<std::string> trainingTaskNames(const std::string& dir);

}  // namespace adroit
