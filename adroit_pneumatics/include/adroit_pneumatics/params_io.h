// Fitted parametric-model constants in YAML: the identification tool writes them, the
// pools load them. Format:
//   parametric:
//     default: {c2: 0.1, c3: 2.0, c4: 0.5, c5: 0, c6: 0, c7: 100, c8: 0, c9: 20, cg: 0.2}
//     # or the saturating form (every field required):
//     default: {form: saturating, c2: 0.1, c3: 2.0, c4: 0.5, c5: -1.4, v0: 0.01, c7: 250,
//               c8: 0.4, c9: 35, cg: 0.2, u_sat: 4, e_fill: 250e3, e_exhaust: 1e6, td: 0.002}
//     cylinders:                 # optional per-cylinder overrides (complete sets)
//       A_FFJ2_flex: {c2: ..., ...}
#pragma once

#include <map>
#include <string>

#include "adroit_pneumatics/parametric_model.h"

namespace adroit::pneumatics {

struct ParameterSet {
  ParametricParams defaults;
  std::map<std::string, ParametricParams> cylinders;
  const ParametricParams& forCylinder(const std::string& name) const {
    const auto it = cylinders.find(name);
    return it == cylinders.end() ? defaults : it->second;
  }
};

// `form` is eq5.5 (the default when absent: files written before the saturating form) or
// saturating (parametric_model.h). Throws std::runtime_error with one line naming the file
// and the bad field (e.g. "model.yaml: parametric.default.c7: missing").
ParameterSet loadParameterSet(const std::string& path);
ParameterSet parseParameterSet(const std::string& yaml_text, const std::string& source = "<string>");
void saveParameterSet(const std::string& path, const ParameterSet& set);
std::string formatParameterSet(const ParameterSet& set);

}  // namespace adroit::pneumatics
