// Name <-> index tables for the objects of a compiled MuJoCo model, so no caller
// hard-codes an index: names are resolved once against the model.
#pragma once

#include <mujoco/mujoco.h>

#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

namespace adroit {

class NameIndex {
 public:
  NameIndex() = default;
  NameIndex(const mjModel* model, mjtObj type);

  // Index of `name`; throws std::out_of_range("unknown <kind> 'name'") when absent.
  int at(const std::string& name) const;
  std::optional<int> find(const std::string& name) const;
  bool contains(const std::string& name) const { return find(name).has_value(); }
  // Resolves every name or throws, naming the first unknown one.
  std::vector<int> resolve(const std::vector<std::string>& names) const;

  const std::string& name(int index) const { return names_.at(index); }
  const std::vector<std::string>& names() const { return names_; }
  int size() const { return static_cast<int>(names_.size()); }

 private:
  std::string kind_;
  std::vector<std::string> names_;
  std::unordered_map<std::string, int> index_;
};

struct ModelTables {
  explicit ModelTables(const mjModel* model);
  NameIndex joints, tendons, actuators, sensors, sites, bodies, geoms, keyframes;
};

// Address of a joint's first generalised position / velocity coordinate.
int jointQposAddress(const mjModel* model, int joint);
int jointDofAddress(const mjModel* model, int joint);

}  // namespace adroit
