// Glove joint targets -> tendon tensions (thesis eq. 10.1): u = k J_tendon (q - q_glove).
//
// J_tendon is the model's tendon Jacobian at the hand's current configuration q, so the
// error in joint space becomes a length error of every tendon: a tendon that is too long
// (the joint is past its target in the direction that lengthens it) pulls, its antagonist
// goes slack. Tendons only pull, so each tension is clamped to [min_tension, the cylinder's
// maximum]; a damping term on the tendon velocity J qdot keeps the fingers from ringing.
//
// ROS-free; one object per thread (it owns an mjData workspace, allocated once).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "adroit_core/mujoco_model.h"

namespace adroit::teleop {

struct MappingGains {
  double stiffness = 3000.0;  // N per m of tendon length error (k of eq. 10.1)
  double damping = 30.0;      // N per m/s of tendon velocity
  double min_tension = 0.3;   // N: tendons never go slack (thesis 6.3)
  // Per joint-name prefix (e.g. "WRJ", "TH"): stiffness and damping factors on the tendons
  // that actuate joints with that prefix (the longest matching prefix wins).
  std::map<std::string, double> scale;
};

class TendonMapping {
 public:
  // model: the teleop scene (owned). joints: the hinge joints q and q_glove are
  // given for, in that order (the driver's joint_states order). Throws std::invalid_argument
  // for an unknown joint, a non-hinge joint, or gains that are negative or not finite.
  TendonMapping(ModelPtr model, std::vector<std::string> joints, MappingGains gains);

  // Tensions [N] for every actuator (model order) into `tensions` (resized once). q, qdot:
  // the hand's state; target: q_glove. All of length joints().size(); false (and no output)
  // if not, or if any value is not finite.
  bool compute(const std::vector<double>& q, const std::vector<double>& qdot, const std::vector<double>& target,
               std::vector<double>& tensions);

  const std::vector<std::string>& joints() const { return joints_; }
  const std::vector<std::string>& actuatorNames() const { return actuator_names_; }
  const mjModel* model() const { return model_.get(); }

 private:
  ModelPtr model_;
  DataPtr data_;
  std::vector<std::string> joints_, actuator_names_;
  std::vector<int> qpos_adr_, dof_adr_;      // per given joint
  std::vector<int> actuator_tendon_;         // per actuator: its tendon
  std::vector<double> actuator_gain_;        // per actuator: the prefix scale
  std::vector<double> max_tension_;          // per actuator
  MappingGains gains_;
  std::vector<double> error_, velocity_;     // nv workspaces
};

}  // namespace adroit::teleop
