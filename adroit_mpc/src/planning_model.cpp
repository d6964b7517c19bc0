#include "adroit_mpc/planning_model.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "adroit_core/bounded_file.h"

namespace adroit_mpc {

namespace {
// The largest scene in adroit_description is ~100 kB of MJCF; a file far larger is not a model.
constexpr size_t kMaxModelFileBytes = 16 * adroit::kMiB;
}  // namespace
namespace {

void setSoftness(mjtNum* solref, mjtNum* solimp, double softness, double timestep) {
  solimp[2] = softness;                                  // width of the impedance transition
  if (solref[0] > 0) solref[0] = std::max(solref[0], 2 * timestep);  // standard (stiffness) form
}

// A pair's attributes as MuJoCo 2.2.2 mixes them for a dynamic contact of geoms a and b
// (mj_contactParam, margin and gap of mj_collideGeoms).
std::string mixedPairElement(const mjModel* m, int a, int b) {
  int condim;
  mjtNum friction[3], solref[mjNREF], solimp[mjNIMP];
  const int pa = m->geom_priority[a], pb = m->geom_priority[b];
  if (pa != pb) {
    const int g = pa > pb ? a : b;
    condim = m->geom_condim[g];
    mju_copy(friction, m->geom_friction + 3 * g, 3);
    mju_copy(solref, m->geom_solref + mjNREF * g, mjNREF);
    mju_copy(solimp, m->geom_solimp + mjNIMP * g, mjNIMP);
  } else {
    condim = std::max(m->geom_condim[a], m->geom_condim[b]);
    for (int k = 0; k < 3; ++k) friction[k] = std::max(m->geom_friction[3 * a + k], m->geom_friction[3 * b + k]);
    const mjtNum sa = m->geom_solmix[a], sb = m->geom_solmix[b];
    mjtNum mix = 0.5;
    if (sa >= mjMINVAL && sb >= mjMINVAL) mix = sa / (sa + sb);
    else if (sa < mjMINVAL && sb >= mjMINVAL) mix = 0;
    else if (sa >= mjMINVAL && sb < mjMINVAL) mix = 1;
    const mjtNum* ra = m->geom_solref + mjNREF * a;
    const mjtNum* rb = m->geom_solref + mjNREF * b;
    for (int k = 0; k < mjNREF; ++k)  // both in standard form: mixed; else the smaller, element-wise
      solref[k] = ra[0] > 0 && rb[0] > 0 ? mix * ra[k] + (1 - mix) * rb[k] : std::min(ra[k], rb[k]);
    for (int k = 0; k < mjNIMP; ++k)
      solimp[k] = mix * m->geom_solimp[mjNIMP * a + k] + (1 - mix) * m->geom_solimp[mjNIMP * b + k];
  }
  const auto list = [](const mjtNum* v, int n) {
    std::string out;
    char number[32];
    for (int k = 0; k < n; ++k) {
      std::snprintf(number, sizeof number, "%.17g", v[k]);
      out += (k ? " " : "") + std::string(number);
    }
    return out;
  };
  const mjtNum friction5[5] = {friction[0], friction[0], friction[1], friction[2], friction[2]};
  const mjtNum margin = std::max(m->geom_margin[a], m->geom_margin[b]);
  const mjtNum gap = std::max(m->geom_gap[a], m->geom_gap[b]);
  return std::string("    <pair geom1=\"") + mj_id2name(m, mjOBJ_GEOM, a) + "\" geom2=\"" + mj_id2name(m, mjOBJ_GEOM, b) +
         "\" condim=\"" + std::to_string(condim) + "\" friction=\"" + list(friction5, 5) + "\" solref=\"" +
         list(solref, mjNREF) + "\" solimp=\"" + list(solimp, mjNIMP) + "\" margin=\"" + list(&margin, 1) +
         "\" gap=\"" + list(&gap, 1) + "\"/>\n";
}

bool contains(const int* values, int n, int value) { return std::find(values, values + n, value) != values + n; }

}  // namespace

std::string explicitContactPairsXml(const std::string& xml, const mjModel* m, int* pairs) {
  std::string elements;
  int count = 0;
  const bool filter_parent = !(m->opt.disableflags & mjDSBL_FILTERPARENT);
  for (int a = 0; a < m->ngeom; ++a) {
    for (int b = a + 1; b < m->ngeom; ++b) {
      if (!((m->geom_contype[a] & m->geom_conaffinity[b]) || (m->geom_contype[b] & m->geom_conaffinity[a]))) continue;
      const int body_a = m->geom_bodyid[a], body_b = m->geom_bodyid[b];
      const int weld_a = m->body_weldid[body_a], weld_b = m->body_weldid[body_b];
      if (weld_a == weld_b) continue;
      // The parent filter spares the world: a body on the world still touches the floor.
      const int weld_parent_a = m->body_weldid[m->body_parentid[weld_a]];
      const int weld_parent_b = m->body_weldid[m->body_parentid[weld_b]];
      if (filter_parent && weld_a != 0 && weld_b != 0 && (weld_a == weld_parent_b || weld_b == weld_parent_a)) continue;
      // Excluded body pairs, and body pairs that already have an explicit pair (MuJoCo skips
      // their dynamic collisions), by MuJoCo's signature of a body pair (ids + 1, as 2.2.2
      // writes pair_signature).
      const int signature = ((std::min(body_a, body_b) + 1) << 16) + std::max(body_a, body_b) + 1;
      if (contains(m->exclude_signature, m->nexclude, signature) || contains(m->pair_signature, m->npair, signature))
        continue;
      if (!mj_id2name(m, mjOBJ_GEOM, a) || !mj_id2name(m, mjOBJ_GEOM, b)) return "";
      elements += mixedPairElement(m, a, b);
      ++count;
    }
  }
  if (pairs) *pairs = count;
  std::string out = xml;
  const std::size_t contact_end = out.rfind("</contact>");
  if (contact_end != std::string::npos) {
    out.insert(contact_end, elements);
  } else {
    const std::size_t end = out.rfind("</mujoco>");
    if (end == std::string::npos) throw std::invalid_argument("explicitContactPairsXml: no </mujoco> in the model text");
    out.insert(end, "  <contact>\n" + elements + "  </contact>\n");
  }
  return out;
}

std::string readModelText(const std::string& path) {
  try {
    return adroit::readBoundedFile(path, kMaxModelFileBytes);
  } catch (const adroit::FileError& e) {
    throw adroit::ModelLoadError(std::string("cannot read model file ") + e.what());
  }
}

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

  if ((s.object_mass > 0 || s.object_size_scale != 1) && !scaleObjectBody(m, s.object_mass, s.object_size_scale))
    throw std::invalid_argument("planning model: object_mass / object_size_scale set but the scene has no body 'object'");
}

bool scaleObjectBody(mjModel* m, double mass, double size) {
  if (!(mass >= 0) || !std::isfinite(mass) || !(size > 0) || !std::isfinite(size))
    throw std::invalid_argument("object mass must be >= 0 and its size scale > 0");
  const int body = mj_name2id(m, mjOBJ_BODY, "object");
  if (body < 0) return false;
  const double mass_ratio = mass > 0 ? mass / m->body_mass[body] : 1.0;
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
  return true;
}

adroit::ModelPtr loadPlanningModel(const std::string& path, const PlanningModelSettings& settings) {
  adroit::LoadedModel loaded = adroit::loadModelFile(path);
  applyPlanningSettings(loaded.model.get(), settings);
  if (!settings.explicit_pairs || loaded.model->opt.collision != mjCOL_ALL) return std::move(loaded.model);
  // The pairs take their parameters from the geoms as the settings left them (margin,
  // softness), and the settings then give the new pairs what they give every pair.
  const std::string xml = explicitContactPairsXml(readModelText(path), loaded.model.get());
  if (xml.empty()) return std::move(loaded.model);  // an unnamed geom: dynamic collisions as they are
  adroit::LoadedModel paired = adroit::loadModelString(xml);
  applyPlanningSettings(paired.model.get(), settings);
  paired.model->opt.collision = mjCOL_PAIR;
  return std::move(paired.model);
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
  adroit::LoadedModel loaded = adroit::loadModelString(unprunedXml(readModelText(path)));
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
