#include "adroit_mpc/planning_model.h"

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace adroit_mpc {
namespace {

void setSoftness(mjtNum* solref, mjtNum* solimp, double softness, double timestep) {
  solimp[2] = softness;                                  // width of the impedance transition
  if (solref[0] > 0) solref[0] = std::max(solref[0], 2 * timestep);  // standard (stiffness) form
}

}  // namespace

void applyPlanningSettings(mjModel* m, const PlanningModelSettings& s) {
  if (!(s.timestep > 0) || !std::isfinite(s.timestep))
    throw std::invalid_argument("planning model: timestep must be positive, got " + std::to_string(s.timestep));
  if (!(s.contact_margin >= 0) || !std::isfinite(s.contact_margin))
    throw std::invalid_argument("planning model: contact_margin must be >= 0, got " + std::to_string(s.contact_margin));
  if (!(s.contact_softness >= 0) || !std::isfinite(s.contact_softness))
    throw std::invalid_argument("planning model: contact_softness must be >= 0, got " +
                                std::to_string(s.contact_softness));
  if (!(s.object_mass >= 0) || !(s.object_size_scale > 0) || !std::isfinite(s.object_mass) ||
      !std::isfinite(s.object_size_scale))
    throw std::invalid_argument("planning model: object_mass must be >= 0 and object_size_scale > 0");

  if (s.solver_iterations < 0)
    throw std::invalid_argument("planning model: solver_iterations must be >= 0, got " +
                                std::to_string(s.solver_iterations));
  if (!(s.min_tension >= 0) || !std::isfinite(s.min_tension))
    throw std::invalid_argument("planning model: min_tension must be >= 0, got " + std::to_string(s.min_tension));
  for (int a = 0; a < m->nu; ++a) {
    mjtNum* range = m->actuator_ctrlrange + 2 * a;
    if (m->actuator_trntype[a] != mjTRN_TENDON || !m->actuator_ctrllimited[a]) continue;
    if (s.min_tension > range[1])
      throw std::invalid_argument("planning model: min_tension " + std::to_string(s.min_tension) +
                                  " N is above actuator " + std::to_string(a) + "'s upper bound");
    range[0] = std::max(range[0], s.min_tension);
  }
  m->opt.timestep = s.timestep;
  if (s.solver_iterations > 0) m->opt.iterations = s.solver_iterations;
  if (s.disable_sensors) m->opt.disableflags |= mjDSBL_SENSOR;
  else m->opt.disableflags &= ~mjDSBL_SENSOR;

  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_contype[g] == 0 && m->geom_conaffinity[g] == 0) continue;  // visual / wrap geoms
    if (s.contact_margin > 0) m->geom_margin[g] = s.contact_margin;
    if (s.contact_softness > 0)
      setSoftness(m->geom_solref + mjNREF * g, m->geom_solimp + mjNIMP * g, s.contact_softness, s.timestep);
  }
  for (int p = 0; p < m->npair; ++p) {
    if (s.contact_margin > 0) m->pair_margin[p] = s.contact_margin;
    if (s.contact_softness > 0)
      setSoftness(m->pair_solref + mjNREF * p, m->pair_solimp + mjNIMP * p, s.contact_softness, s.timestep);
  }

  if (s.object_mass > 0 || s.object_size_scale != 1) {
    const int body = mj_name2id(m, mjOBJ_BODY, "object");
    if (body < 0)
      throw std::invalid_argument("planning model: object_mass / object_size_scale set but the scene has no body 'object'");
    const double size = s.object_size_scale;
    const double mass_ratio = s.object_mass > 0 ? s.object_mass / m->body_mass[body] : 1.0;
    m->body_mass[body] *= mass_ratio;
    for (int k = 0; k < 3; ++k) {
      m->body_inertia[3 * body + k] *= mass_ratio * size * size;
      m->body_ipos[3 * body + k] *= size;
    }
    for (int g = 0; g < m->ngeom; ++g) {
      if (m->geom_bodyid[g] != body) continue;
      for (int k = 0; k < 3; ++k) {
        m->geom_size[3 * g + k] *= size;
        m->geom_pos[3 * g + k] *= size;
      }
      m->geom_rbound[g] *= size;
    }
    // Derived quantities that depend on masses (body_subtreemass, dof_invweight0...).
    adroit::DataPtr scratch = adroit::makeData(m);
    mj_setConst(m, scratch.get());
  }
}

adroit::ModelPtr loadPlanningModel(const std::string& path, const PlanningModelSettings& settings) {
  adroit::LoadedModel loaded = adroit::loadModelFile(path);
  applyPlanningSettings(loaded.model.get(), settings);
  return std::move(loaded.model);
}

std::string unprunedXml(const std::string& xml) {
  // Hand geoms are generated with contype 1 / conaffinity 0: they touch the object and the
  // world but not each other. Giving them conaffinity 1 lets every non-adjacent pair collide.
  static const std::regex hand_geom(R"((<geom [^>]*contype="1" )conaffinity="0"([^>]*>))");
  static const std::regex condim(R"((<geom [^>]*contype="1" conaffinity="1" [^>]*)condim="[0-9]")");
  static const std::regex pair(R"(\s*<pair [^>]*/>)");
  if (!std::regex_search(xml, hand_geom))
    throw std::invalid_argument("unprunedXml: no hand geom (contype=\"1\" conaffinity=\"0\") in the model text");
  std::string out = std::regex_replace(xml, hand_geom, "$1conaffinity=\"1\"$2");
  out = std::regex_replace(out, condim, "$1condim=\"3\"");
  out = std::regex_replace(out, pair, "");
  return out;
}

adroit::ModelPtr loadUnprunedPlanningModel(const std::string& path, const PlanningModelSettings& settings) {
  std::ifstream in(path);
  if (!in) throw adroit::ModelLoadError("cannot read model file " + path);
  std::stringstream text;
  text << in.rdbuf();
  adroit::LoadedModel loaded = adroit::loadModelString(unprunedXml(text.str()));
  applyPlanningSettings(loaded.model.get(), settings);
  return std::move(loaded.model);
}


int activeContacts(const mjData* d) {
  int active = 0;
  for (int c = 0; c < d->ncon; ++c)
    if (d->contact[c].exclude == 0) ++active;  // 0: in the constraint set
  return active;
}

}  // namespace adroit_mpc
