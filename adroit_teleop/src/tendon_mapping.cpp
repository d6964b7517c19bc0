#include "adroit_teleop/tendon_mapping.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace adroit::teleop {

namespace {

bool finiteNonNegative(double v) { return std::isfinite(v) && v >= 0; }

}  // namespace

TendonMapping::TendonMapping(ModelPtr model, std::vector<std::string> joints, MappingGains gains)
    : model_(std::move(model)), joints_(std::move(joints)), gains_(std::move(gains)) {
  const mjModel* m = model_.get();
  if (!finiteNonNegative(gains_.stiffness) || !finiteNonNegative(gains_.damping) ||
      !finiteNonNegative(gains_.min_tension))
    throw std::invalid_argument("teleop gains: stiffness, damping and min_tension must be finite and >= 0");
  for (const auto& [prefix, factor] : gains_.scale)
    if (!finiteNonNegative(factor))
      throw std::invalid_argument("teleop gains: scale of '" + prefix + "' must be finite and >= 0");
  data_ = makeData(m);
  for (const auto& name : joints_) {
    const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    if (j < 0) throw std::invalid_argument("joint '" + name + "' is not in the teleop model");
    if (m->jnt_type[j] != mjJNT_HINGE) throw std::invalid_argument("joint '" + name + "' is not a hinge");
    qpos_adr_.push_back(m->jnt_qposadr[j]);
    dof_adr_.push_back(m->jnt_dofadr[j]);
  }
  for (int a = 0; a < m->nu; ++a) {
    if (m->actuator_trntype[a] != mjTRN_TENDON)
      throw std::invalid_argument(std::string("actuator '") + mj_id2name(m, mjOBJ_ACTUATOR, a) + "' drives no tendon");
    actuator_names_.push_back(mj_id2name(m, mjOBJ_ACTUATOR, a));
    actuator_tendon_.push_back(m->actuator_trnid[2 * a]);
    max_tension_.push_back(m->actuator_ctrlrange[2 * a + 1]);
    // The gain scale of the joint this cylinder is named after (A_<joint>_flex / _ext).
    const std::string& name = actuator_names_.back();
    double factor = 1.0;
    std::size_t best = 0;
    for (const auto& [prefix, f] : gains_.scale)
      if (name.compare(0, 2 + prefix.size(), "A_" + prefix) == 0 && prefix.size() > best) {
        best = prefix.size();
        factor = f;
      }
    actuator_gain_.push_back(factor);
  }
  error_.assign(m->nv, 0.0);
  velocity_.assign(m->nv, 0.0);
}

bool TendonMapping::compute(const std::vector<double>& q, const std::vector<double>& qdot,
                            const std::vector<double>& target, std::vector<double>& tensions) {
  const std::size_t n = joints_.size();
  if (q.size() != n || qdot.size() != n || target.size() != n) return false;
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(q[i]) || !std::isfinite(qdot[i]) || !std::isfinite(target[i])) return false;
  const mjModel* m = model_.get();
  mjData* d = data_.get();
  // Only the hand's joints matter for its tendons; everything else stays at qpos0.
  for (std::size_t i = 0; i < n; ++i) {
    d->qpos[qpos_adr_[i]] = q[i];
    error_[dof_adr_[i]] = q[i] - target[i];
    velocity_[dof_adr_[i]] = qdot[i];
  }
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_tendon(m, d);
  tensions.resize(m->nu);
  for (int a = 0; a < m->nu; ++a) {
    const mjtNum* row = d->ten_J + actuator_tendon_[a] * m->nv;
    double stretch = 0, rate = 0;  // tendon length error and velocity
    for (std::size_t i = 0; i < n; ++i) {
      stretch += row[dof_adr_[i]] * error_[dof_adr_[i]];
      rate += row[dof_adr_[i]] * velocity_[dof_adr_[i]];
    }
    const double pull = actuator_gain_[a] * (gains_.stiffness * stretch + gains_.damping * rate);
    tensions[a] = std::clamp(gains_.min_tension + pull, gains_.min_tension, max_tension_[a]);
  }
  return true;
}

}  // namespace adroit::teleop
