// Rollout backend (b): parallel in-process MuJoCo workers, each owning one SimulatedRobot of
// adroit_driver (the same plant, sensors and safety logic the simulation driver runs), so a
// rollout here sees what it would see through the driver, faster than real time.
//
// Determinism: every rollout starts each worker's robot from the same captured state
// (physics, plant, sensor noise generators), so a rollout's result depends only on its
// request, not on which worker ran it or what ran before.
#pragma once
#include <adroit_core/thread_pool.h>
#include <adroit_driver/simulated_robot.h>
#include <adroit_learning/rollout_backend.h>

#include <memory>
#include <optional>
#include <vector>

struct mjModel_;
typedef struct mjModel_ mjModel;

namespace adroit {

// The task's initial qpos on `model`: the keyframe (or the model default), the task's joint
// overrides, object position (initial_object_position, body "object") and orientation
// (`object_yaw_deg` when given, else initial_object_yaw, through tubeOrientationFromYaw), then
// `joint_offset` (per entry of `joints`, may be empty), every robot joint clamped to its
// range. Throws TaskError for an unknown keyframe or joint, std::invalid_argument for a yaw
// outside [0, 180).
std::vector<double> initialQpos(const mjModel* model, const TrainingTask& task, const std::vector<std::string>& joints,
                                const std::vector<double>& joint_offset,
                                std::optional<double> object_yaw_deg = std::nullopt);
// The geometry of body "object" (its first capsule or cylinder geom: half-length, radius, axis)
// and the top of geom "table" (0 without one). Invalid (half_length 0) when there is none.
ObjectGeometry objectGeometry(const mjModel* model);
// Ranges (hi - lo, rad) of the named 1-DOF joints.
std::vector<double> jointRanges(const mjModel* model, const std::vector<std::string>& joints);

class SimRollouts : public RolloutBackend {
 public:
  // workers <= 0: one per hardware thread. config.model_path names the scene's MJCF.
  SimRollouts(const driver::SimConfig& config, int workers);
  std::string name() const override { return "sim_workers"; }
  std::vector<std::string> jointNames() const override { return robots_.front()->jointNames(); }
  std::vector<std::string> cylinderNames() const override { return robots_.front()->cylinderNames(); }
  bool hasObject() const override { return robots_.front()->hasObject(); }
  std::vector<std::string> touchNames() const override;
  std::vector<double> jointRanges() const override;
  ObjectGeometry objectGeometry() const override { return adroit::objectGeometry(robots_.front()->model()); }
  Eigen::VectorXd initialState(const TrainingTask& task, const StateLayout& layout) override;
  std::vector<RolloutResult> run(const TrainingTask& task, const StateLayout& layout, const LgController& controller,
                                 const std::vector<RolloutRequest>& requests, const std::atomic<bool>& cancel) override;
  // One policy per rollout (make_policy is called on the worker threads); deterministic as run().
  std::vector<RolloutResult> runPolicy(const TrainingTask& task, const StateLayout& layout,
                                       const PolicyFactory& make_policy, const std::vector<RolloutRequest>& requests,
                                       int steps, const std::atomic<bool>& cancel) override;
  int workers() const { return static_cast<int>(robots_.size()); }

 private:
  void checkControlStep(const TrainingTask& task) const;
  // Resets the worker's robot to the request's initial state; false with `error` set.
  bool resetForRollout(int worker, const TrainingTask& task, const StateLayout& layout, const RolloutRequest& request,
                       std::string& error);
  // The control loop on the worker's robot with `act` (runControlLoop), after its reset.
  template <class Act>
  RolloutResult runOne(int worker, const TrainingTask& task, const StateLayout& layout, const RolloutRequest& request,
                       int steps, Act&& act, const std::atomic<bool>& cancel);
  std::vector<std::unique_ptr<driver::SimulatedRobot>> robots_;
  driver::SimState start_;  // captured once after construction (same for every worker)
  ThreadPool pool_;
};

// Fills an Observation from the simulated robot's sensed signals (what the driver publishes);
// touch: the fingertip sensors (fingertipTouch).
void observe(const driver::SimulatedRobot& robot, Observation& obs);

}  // namespace adroit
