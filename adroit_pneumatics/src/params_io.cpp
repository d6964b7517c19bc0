#include "adroit_pneumatics/params_io.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <yaml-cpp/yaml.h>

namespace adroit::pneumatics {

namespace {

struct Field {
  const char* name;
  double ParametricParams::*member;
};
const Field kFields[] = {{"c2", &ParametricParams::c2}, {"c3", &ParametricParams::c3}, {"c4", &ParametricParams::c4},
                         {"c5", &ParametricParams::c5}, {"c6", &ParametricParams::c6}, {"c7", &ParametricParams::c7},
                         {"c8", &ParametricParams::c8}, {"c9", &ParametricParams::c9}, {"cg", &ParametricParams::cg}};

ParametricParams parseParams(const YAML::Node& node, const std::string& where, const std::string& source) {
  if (!node.IsMap()) throw std::runtime_error(source + ": " + where + ": expected a map of c2..c9, cg");
  ParametricParams p;
  for (const Field& f : kFields) {
    const YAML::Node v = node[f.name];
    if (!v) throw std::runtime_error(source + ": " + where + "." + f.name + ": missing");
    double x;
    try {
      x = v.as<double>();
    } catch (const YAML::Exception&) {
      throw std::runtime_error(source + ": " + where + "." + f.name + ": expected a number");
    }
    if (!std::isfinite(x)) throw std::runtime_error(source + ": " + where + "." + f.name + ": not finite");
    p.*(f.member) = x;
  }
  // Optional (files written before the dead time existed have none): input dead time, s.
  if (const YAML::Node v = node["td"]) {
    try {
      p.td = v.as<double>();
    } catch (const YAML::Exception&) {
      throw std::runtime_error(source + ": " + where + ".td: expected a number");
    }
  }
  try {
    p.validate();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(source + ": " + where + ": " + e.what());
  }
  return p;
}

}  // namespace

ParameterSet parseParameterSet(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(source + ": not valid YAML (line " + std::to_string(e.mark.line + 1) + ")");
  }
  if (!root.IsMap() || !root["parametric"]) throw std::runtime_error(source + ": parametric: missing");
  const YAML::Node top = root["parametric"];
  if (!top.IsMap() || !top["default"]) throw std::runtime_error(source + ": parametric.default: missing");
  ParameterSet set;
  set.defaults = parseParams(top["default"], "parametric.default", source);
  if (const YAML::Node cyl = top["cylinders"]) {
    if (!cyl.IsMap()) throw std::runtime_error(source + ": parametric.cylinders: expected a map of name -> parameters");
    for (const auto& kv : cyl) {
      const std::string name = kv.first.as<std::string>();
      set.cylinders[name] = parseParams(kv.second, "parametric.cylinders." + name, source);
    }
  }
  return set;
}

ParameterSet loadParameterSet(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot open");
  std::stringstream ss;
  ss << f.rdbuf();
  return parseParameterSet(ss.str(), path);
}

std::string formatParameterSet(const ParameterSet& set) {
  const auto one = [](const ParametricParams& p) {
    std::ostringstream o;
    o.precision(10);
    o << '{';
    bool first = true;
    for (const Field& f : kFields) {
      o << (first ? "" : ", ") << f.name << ": " << p.*(f.member);
      first = false;
    }
    o << ", td: " << p.td;
    o << '}';
    return o.str();
  };
  std::ostringstream out;
  out << "parametric:\n  default: " << one(set.defaults) << "\n";
  if (!set.cylinders.empty()) {
    out << "  cylinders:\n";
    for (const auto& [name, p] : set.cylinders) out << "    " << name << ": " << one(p) << "\n";
  }
  return out.str();
}

void saveParameterSet(const std::string& path, const ParameterSet& set) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot write");
  f << formatParameterSet(set);
}

}  // namespace adroit::pneumatics
