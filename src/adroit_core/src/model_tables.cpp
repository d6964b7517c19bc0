#include "adroit_core/model_tables.h"

#include <stdexcept>

namespace adroit {
namespace {

int objectCount(const mjModel* m, mjtObj type) {
  switch (type) {
    case mjOBJ_JOINT: return m->njnt;
    case mjOBJ_TENDON: return m->ntendon;
    case mjOBJ_ACTUATOR: return m->nu;
    case mjOBJ_SENSOR: return m->nsensor;
    case mjOBJ_SITE: return m->nsite;
    case mjOBJ_BODY: return m->nbody;
    case mjOBJ_GEOM: return m->ngeom;
    case mjOBJ_KEY: return m->nkey;
    default: throw std::invalid_argument("NameIndex: unsupported object type");
  }
}

}  // namespace

NameIndex::NameIndex(const mjModel* model, mjtObj type) : kind_(mju_type2Str(type)) {
  const int n = objectCount(model, type);
  names_.reserve(n);
  for (int i = 0; i < n; ++i) {
    const char* name = mj_id2name(model, type, i);
    names_.emplace_back(name ? name : "");
    if (name && *name) index_.emplace(name, i);
  }
}

std::optional<int> NameIndex::find(const std::string& name) const {
  auto it = index_.find(name);
  if (it == index_.end()) return std::nullopt;
  return it->second;
}

int NameIndex::at(const std::string& name) const {
  auto found = find(name);
  if (!found) throw std::out_of_range("unknown " + kind_ + " '" + name + "'");
  return *found;
}

std::vector<int> NameIndex::resolve(const std::vector<std::string>& names) const {
  std::vector<int> out;
  out.reserve(names.size());
  for (const auto& n : names) out.push_back(at(n));
  return out;
}

ModelTables::ModelTables(const mjModel* m)
    : joints(m, mjOBJ_JOINT),
      tendons(m, mjOBJ_TENDON),
      actuators(m, mjOBJ_ACTUATOR),
      sensors(m, mjOBJ_SENSOR),
      sites(m, mjOBJ_SITE),
      bodies(m, mjOBJ_BODY),
      geoms(m, mjOBJ_GEOM),
      keyframes(m, mjOBJ_KEY) {}

int jointQposAddress(const mjModel* model, int joint) { return model->jnt_qposadr[joint]; }
int jointDofAddress(const mjModel* model, int joint) { return model->jnt_dofadr[joint]; }

}  // namespace adroit
