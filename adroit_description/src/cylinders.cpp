#include "adroit_description/cylinders.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "adroit_core/mujoco_model.h"

namespace adroit {
namespace description {
namespace {

std::string customText(const mjModel* m, const std::string& name) {
  const int id = mj_name2id(m, mjOBJ_TEXT, name.c_str());
  if (id < 0) return "";
  return std::string(m->text_data + m->text_adr[id], m->text_size[id] > 0 ? m->text_size[id] - 1 : 0);
}

// d(tendon length)/d(qvel[dof]) after mj_fwdPosition; MuJoCo stores ten_J dense or sparse.
double tendonMoment(const mjModel* m, const mjData* d, int tendon, int dof) {
  if (!mj_isSparse(m)) return d->ten_J[tendon * m->nv + dof];
  const int adr = d->ten_J_rowadr[tendon];
  for (int k = 0; k < d->ten_J_rownnz[tendon]; ++k) {
    if (d->ten_J_colind[adr + k] == dof) return d->ten_J[adr + k];
  }
  return 0.0;
}

// Tendon length with every joint it spans set to the limit that lengthens it.
// Moment arms are taken at the model's reference pose; the routing keeps their sign.
std::pair<double, double> tendonLengthRange(const mjModel* m, mjData* d, int tendon) {
  mj_resetData(m, d);
  mj_fwdPosition(m, d);
  std::vector<double> longest(d->qpos, d->qpos + m->nq), shortest = longest;
  for (int j = 0; j < m->njnt; ++j) {
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE) continue;
    const double moment = tendonMoment(m, d, tendon, m->jnt_dofadr[j]);
    if (moment == 0 || !m->jnt_limited[j]) continue;
    const double lo = m->jnt_range[2 * j], hi = m->jnt_range[2 * j + 1];
    longest[m->jnt_qposadr[j]] = moment > 0 ? hi : lo;
    shortest[m->jnt_qposadr[j]] = moment > 0 ? lo : hi;
  }
  auto lengthAt = [&](const std::vector<double>& q) {
    std::copy(q.begin(), q.end(), d->qpos);
    mj_fwdPosition(m, d);
    return d->ten_length[tendon];
  };
  return {lengthAt(shortest), lengthAt(longest)};
}

}  // namespace

std::vector<Cylinder> cylinderTable(const mjModel* m) {
  std::vector<Cylinder> table;
  DataPtr scratch = makeData(m);
  for (int a = 0; a < m->nu; ++a) {
    if (m->actuator_trntype[a] != mjTRN_TENDON) continue;
    Cylinder c;
    c.actuator = a;
    c.tendon = m->actuator_trnid[2 * a];
    const char* name = mj_id2name(m, mjOBJ_ACTUATOR, a);
    c.name = name ? name : "actuator " + std::to_string(a);
    if (m->nuser_actuator < 2) {
      throw std::runtime_error("actuator '" + c.name + "' has no user data [bore, stroke]");
    }
    c.bore_diameter = m->actuator_user[a * m->nuser_actuator];
    c.stroke = m->actuator_user[a * m->nuser_actuator + 1];
    c.type = customText(m, "cylinder_" + c.name);
    if (c.type.empty()) throw std::runtime_error("actuator '" + c.name + "' has no cylinder type text");
    if (!(c.bore_diameter > 0) || !(c.stroke > 0)) {
      throw std::runtime_error("actuator '" + c.name + "' has a non-positive bore or stroke");
    }
    c.bore_area = M_PI * c.bore_diameter * c.bore_diameter / 4.0;
    c.max_tension = m->actuator_ctrlrange[2 * a + 1];
    const auto [shortest, longest] = tendonLengthRange(m, scratch.get(), c.tendon);
    c.longest_tendon_length = longest;
    if (longest - shortest > c.stroke + 1e-9) {
      throw std::runtime_error("actuator '" + c.name + "': tendon travel " + std::to_string(longest - shortest) +
                               " m exceeds the cylinder stroke " + std::to_string(c.stroke) + " m");
    }
    table.push_back(c);
  }
  return table;
}

double pistonTravel(const Cylinder& c, double tendon_length) {
  return std::clamp(c.longest_tendon_length - tendon_length, 0.0, c.stroke);
}

}  // namespace description
}  // namespace adroit
