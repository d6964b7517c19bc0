#include "adroit_learning/sim_rollouts.h"

#include <mujoco/mujoco.h>

#include <algorithm>
#include <cmath>
#include <thread>
#include <utility>

namespace adroit {

namespace {

// As through the driver (DriverConnection::reset): two physics steps on the hold command after
// a reset, so the first observation is what the sensors report of the reset state.
bool settle(driver::SimulatedRobot& robot, double hold_volts, std::string& error) {
  const driver::CommandResult r =
      robot.commandValves(robot.cylinderNames(), {}, std::vector<double>(robot.cylinderNames().size(), hold_volts));
  if (!r.applied) {
    error = "hold command refused: " + r.error;
    return false;
  }
  robot.step();
  robot.step();
  return true;
}

int jointId(const mjModel* model, const std::string& name) {
  const int j = mj_name2id(model, mjOBJ_JOINT, name.c_str());
  if (j < 0) throw TaskError("joint '" + name + "' is not in the model");
  return j;
}

// The free object's quaternion (w x y z) from a yaw (degrees).
void setObjectYaw(const mjModel* model, const TrainingTask& task, double yaw_deg, double* quat) {
  const ObjectGeometry geometry = objectGeometry(model);
  if (!geometry.valid())
    throw TaskError("task '" + task.name + "': initial object yaw, but the object is not a capsule or cylinder");
  const Eigen::Quaterniond q = tubeOrientationFromYaw(yaw_deg, geometry);
  quat[0] = q.w(), quat[1] = q.x(), quat[2] = q.y(), quat[3] = q.z();
}

}  // namespace

ObjectGeometry objectGeometry(const mjModel* model) {
  ObjectGeometry g;
  const int object = mj_name2id(model, mjOBJ_BODY, "object");
  for (int i = 0; object >= 0 && i < model->ngeom; ++i) {
    const int type = model->geom_type[i];
    if (model->geom_bodyid[i] != object || (type != mjGEOM_CAPSULE && type != mjGEOM_CYLINDER)) continue;
    g.radius = model->geom_size[3 * i];
    g.half_length = model->geom_size[3 * i + 1];
    // Capsules and cylinders lie along their geom's z: rotate it into the body frame.
    const double* q = model->geom_quat + 4 * i;
    g.axis_in_body = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized() * Eigen::Vector3d::UnitZ();
    break;
  }
  const int table = mj_name2id(model, mjOBJ_GEOM, "table");
  // geom_pos is in the parent body's frame: the table is a world geom (table top = centre + half height).
  if (table >= 0 && model->geom_bodyid[table] == 0) g.table_top = model->geom_pos[3 * table + 2] + model->geom_size[3 * table + 2];
  return g;
}

std::vector<double> initialQpos(const mjModel* model, const TrainingTask& task, const std::vector<std::string>& joints,
                                const std::vector<double>& joint_offset, std::optional<double> object_yaw_deg) {
  if (!object_yaw_deg) object_yaw_deg = task.initial_object_yaw;
  std::vector<double> qpos(model->qpos0, model->qpos0 + model->nq);
  if (!task.initial_keyframe.empty()) {
    const int key = mj_name2id(model, mjOBJ_KEY, task.initial_keyframe.c_str());
    if (key < 0) throw TaskError("task '" + task.name + "': initial_keyframe '" + task.initial_keyframe + "' is not in the model");
    std::copy(model->key_qpos + key * model->nq, model->key_qpos + (key + 1) * model->nq, qpos.begin());
  } else if (model->nkey > 0) {
    std::copy(model->key_qpos, model->key_qpos + model->nq, qpos.begin());
  }
  for (const auto& [name, value] : task.initial_joints) qpos[model->jnt_qposadr[jointId(model, name)]] = value;
  if (!task.initial_object_position.empty() || object_yaw_deg) {
    // The free joint of body "object" (the driver's object convention).
    const int object = mj_name2id(model, mjOBJ_BODY, "object");
    if (object < 0 || model->body_jntnum[object] != 1 || model->jnt_type[model->body_jntadr[object]] != mjJNT_FREE)
      throw TaskError("task '" + task.name + "': initial object pose, but the model has no free body 'object'");
    const int adr = model->jnt_qposadr[model->body_jntadr[object]];
    std::copy(task.initial_object_position.begin(), task.initial_object_position.end(), qpos.begin() + adr);
    if (object_yaw_deg) setObjectYaw(model, task, *object_yaw_deg, qpos.data() + adr + 3);
  }
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const int j = jointId(model, joints[i]);
    double& q = qpos[model->jnt_qposadr[j]];
    if (i < joint_offset.size()) q += joint_offset[i];
    if (model->jnt_limited[j]) q = std::clamp(q, model->jnt_range[2 * j], model->jnt_range[2 * j + 1]);
  }
  return qpos;
}

std::vector<double> jointRanges(const mjModel* model, const std::vector<std::string>& joints) {
  std::vector<double> out;
  for (const auto& name : joints) {
    const int j = jointId(model, name);
    out.push_back(model->jnt_limited[j] ? model->jnt_range[2 * j + 1] - model->jnt_range[2 * j] : 0.0);
  }
  return out;
}

void observe(const driver::SimulatedRobot& robot, Observation& obs) {
  const driver::Signals& s = robot.sensed();
  obs.joint_position = s.joint_position;
  obs.joint_velocity = s.joint_velocity;
  obs.pressure = s.pressure;
  const std::vector<int> tips = fingertipTouch(robot.touchNames());  // a handful of names
  obs.touch.resize(tips.size());
  for (std::size_t i = 0; i < tips.size(); ++i) obs.touch[i] = s.touch[tips[i]];
  obs.object = s.object;
}

SimRollouts::SimRollouts(const driver::SimConfig& config, int workers)
    : pool_(workers > 0 ? static_cast<std::size_t>(workers) : std::max(1u, std::thread::hardware_concurrency())) {
  for (std::size_t w = 0; w < pool_.size(); ++w) robots_.push_back(std::make_unique<driver::SimulatedRobot>(config));
  start_ = robots_.front()->state();
}

std::vector<std::string> SimRollouts::touchNames() const {
  std::vector<std::string> names;
  for (int i : fingertipTouch(robots_.front()->touchNames())) names.push_back(robots_.front()->touchNames()[i]);
  return names;
}

std::vector<double> SimRollouts::jointRanges() const {
  return adroit::jointRanges(robots_.front()->model(), jointNames());
}

Eigen::VectorXd SimRollouts::initialState(const TrainingTask& task, const StateLayout& layout) {
  driver::SimulatedRobot& robot = *robots_.front();
  robot.setState(start_);
  std::string error;
  const std::vector<double> qpos = initialQpos(robot.model(), task, layout.joint_names, {});
  if (!robot.resetToState(qpos, {}, std::vector<double>(robot.cylinderNames().size(), task.initial_pressure), &error) ||
      !settle(robot, task.locked_command, error))
    throw TaskError("task '" + task.name + "': initial state refused: " + error);
  Observation obs;
  observe(robot, obs);
  Eigen::VectorXd x(layout.nx());
  layout.state(obs, x);
  return x;
}

bool SimRollouts::resetForRollout(int worker, const TrainingTask& task, const StateLayout& layout,
                                  const RolloutRequest& request, std::string& error) {
  driver::SimulatedRobot& robot = *robots_[worker];
  if (robot.safety().safe_state && !robot.release(&error)) {
    error = "robot stays in its safe state: " + error;
    return false;
  }
  error = objectYawProblem(request);
  if (!error.empty()) return false;
  robot.setState(start_);
  const std::vector<double> qpos =
      initialQpos(robot.model(), task, layout.joint_names, request.joint_offset, request.object_yaw_deg);
  if (!robot.resetToState(qpos, {}, std::vector<double>(layout.cylinder_names.size(), task.initial_pressure), &error)) {
    error = "reset refused: " + error;
    return false;
  }
  return settle(robot, task.locked_command, error);
}

template <class Act>
RolloutResult SimRollouts::runOne(int worker, const TrainingTask& task, const StateLayout& layout,
                                  const RolloutRequest& request, int steps, Act&& act,
                                  const std::atomic<bool>& cancel) {
  RolloutResult failed;
  if (!resetForRollout(worker, task, layout, request, failed.error)) return failed;
  driver::SimulatedRobot& robot = *robots_[worker];
  const int substeps = static_cast<int>(std::lround(task.control_dt / robot.timestep()));
  const std::vector<std::uint16_t> no_indices;
  const std::vector<std::string>& names = robot.cylinderNames();
  return runControlLoop(
      layout, steps, cancel, std::forward<Act>(act),
      [&](Observation& obs, std::string& error) {
        if (robot.safety().safe_state) {
          error = "the robot entered its safe state: " + robot.describe(robot.safetyEvents().last);
          return false;
        }
        observe(robot, obs);
        return true;
      },
      [&](const std::vector<double>& volts, std::string& error) {
        const driver::CommandResult r = robot.commandValves(names, no_indices, volts);
        if (!r.applied) error = "valve command refused: " + r.error;
        return r.applied;
      },
      [&](std::string&) {
        for (int k = 0; k < substeps; ++k) robot.step();
        return true;
      });
}

void SimRollouts::checkControlStep(const TrainingTask& task) const {
  const double ratio = task.control_dt / robots_.front()->timestep();
  if (std::abs(ratio - std::lround(ratio)) > 1e-9 || ratio < 1)
    throw TaskError("task '" + task.name + "': control_dt must be a multiple of the physics step");
}

std::vector<RolloutResult> SimRollouts::run(const TrainingTask& task, const StateLayout& layout,
                                            const LgController& controller, const std::vector<RolloutRequest>& requests,
                                            const std::atomic<bool>& cancel) {
  checkControlStep(task);
  std::vector<RolloutResult> results(requests.size());
  pool_.parallelForWorkers(requests.size(), [&](std::size_t i, std::size_t worker) {
    results[i] = runOne(static_cast<int>(worker), task, layout, requests[i], controller.horizon(),
                        controllerAction(controller, requests[i].noise), cancel);
  });
  return results;
}

std::vector<RolloutResult> SimRollouts::runPolicy(const TrainingTask& task, const StateLayout& layout,
                                                  const PolicyFactory& make_policy,
                                                  const std::vector<RolloutRequest>& requests, int steps,
                                                  const std::atomic<bool>& cancel) {
  checkControlStep(task);
  std::vector<RolloutResult> results(requests.size());
  pool_.parallelForWorkers(requests.size(), [&](std::size_t i, std::size_t worker) {
    int rollout_steps = steps;
    std::unique_ptr<Policy> policy = policyForRollout(make_policy, *this, layout, task, rollout_steps, results[i].error);
    if (policy)
      results[i] = runOne(static_cast<int>(worker), task, layout, requests[i], rollout_steps, policyAction(*policy), cancel);
  });
  return results;
}

}  // namespace adroit
