#include "adroit_pneumatics/params_io.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <yaml-cpp/yaml.h>

#include "adroit_core/bounded_file.h"

namespace adroit::pneumatics {

namespace {

struct Field {
  const char* name;
  double ParametricParams::*member;
};
// Fields of each form, in the order they are written. Eq. 5.5 files written before the dead
// time existed have no td: it stays optional there (0 when absent).
const Field kEq55Fields[] = {{"c2", &ParametricParams::c2}, {"c3", &ParametricParams::c3}, {"c4", &ParametricParams::c4},
                             {"c5", &ParametricParams::c5}, {"c6", &ParametricParams::c6}, {"c7", &ParametricParams::c7},
                             {"c8", &ParametricParams::c8}, {"c9", &ParametricParams::c9}, {"cg", &ParametricParams::cg}};
const Field kSaturatingFields[] = {
    {"c2", &ParametricParams::c2}, {"c3", &ParametricParams::c3},       {"c4", &ParametricParams::c4},
    {"c5", &ParametricParams::c5}, {"v0", &ParametricParams::v0},       {"c7", &ParametricParams::c7},
    {"c8", &ParametricParams::c8}, {"c9", &ParametricParams::c9},       {"cg", &ParametricParams::cg},
    {"u_sat", &ParametricParams::u_sat}, {"e_fill", &ParametricParams::e_fill},
    {"e_exhaust", &ParametricParams::e_exhaust}, {"td", &ParametricParams::td}};
constexpr const char* kEq55Name = "eq5.5";
constexpr const char* kSaturatingName = "saturating";

double readNumber(const YAML::Node& v, const std::string& where, const std::string& source) {
  double x;
  try {
    x = v.as<double>();
  } catch (const YAML::Exception&) {
    throw std::runtime_error(source + ": " + where + ": expected a number");
  }
  if (!std::isfinite(x)) throw std::runtime_error(source + ": " + where + ": not finite");
  return x;
}

ParametricParams parseParams(const YAML::Node& node, const std::string& where, const std::string& source) {
  if (!node.IsMap()) throw std::runtime_error(source + ": " + where + ": expected a map of model parameters");
  ParametricParams p;
  if (const YAML::Node form = node["form"]) {
    const std::string name = form.IsScalar() ? form.as<std::string>() : "";
    if (name == kSaturatingName) p.form = ParametricForm::kSaturating;
    else if (name != kEq55Name)
      throw std::runtime_error(source + ": " + where + ".form: expected " + kEq55Name + " or " + kSaturatingName);
  }
  const bool saturating = p.form == ParametricForm::kSaturating;
  const Field* begin = saturating ? std::begin(kSaturatingFields) : std::begin(kEq55Fields);
  const Field* end = saturating ? std::end(kSaturatingFields) : std::end(kEq55Fields);
  for (const Field* f = begin; f != end; ++f) {
    const YAML::Node v = node[f->name];
    if (!v) throw std::runtime_error(source + ": " + where + "." + f->name + ": missing");
    p.*(f->member) = readNumber(v, where + "." + f->name, source);
  }
  if (saturating && node["c6"])
    throw std::runtime_error(source + ": " + where + ".c6: not a parameter of the saturating form (v0 sets the volume dependence)");
  if (!saturating)
    if (const YAML::Node v = node["td"]) p.td = readNumber(v, where + ".td", source);
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
  // A parameter file is a few kB; the limit keeps a wrong path (a log, a device) from being read.
  return parseParameterSet(adroit::readBoundedFile(path, adroit::kMiB), path);
}

std::string formatParameterSet(const ParameterSet& set) {
  const auto one = [](const ParametricParams& p) {
    const bool saturating = p.form == ParametricForm::kSaturating;
    std::ostringstream o;
    o.precision(10);
    o << "{form: " << (saturating ? kSaturatingName : kEq55Name);
    const Field* begin = saturating ? std::begin(kSaturatingFields) : std::begin(kEq55Fields);
    const Field* end = saturating ? std::end(kSaturatingFields) : std::end(kEq55Fields);
    for (const Field* f = begin; f != end; ++f) o << ", " << f->name << ": " << p.*(f->member);
    if (!saturating) o << ", td: " << p.td;
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
