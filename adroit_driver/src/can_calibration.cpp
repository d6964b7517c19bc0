#include "adroit_driver/can_calibration.h"

#include "adroit_core/bounded_file.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

namespace adroit::driver::can {

namespace {

// Shortest text that reads back as exactly `v`.
std::string exact(double v) {
  for (int precision : {15, 16, 17}) {
    std::ostringstream out;
    out.precision(precision);
    out << v;
    if (std::strtod(out.str().c_str(), nullptr) == v) return out.str();
  }
  return std::to_string(v);
}

std::string shown(const YAML::Node& node) {
  if (node.IsScalar()) return node.Scalar();
  if (node.IsMap()) return "a map";
  if (node.IsSequence()) return "a list";
  return "nothing";
}

// Bounds of one quantity's entries.
struct Quantity {
  const char* section;
  const char* what;  // "joint" / "cylinder"
  double max_offset;
  const char* unit;
};
constexpr Quantity kJoints{"joints", "joint", kMaxJointOffset, "rad"};
constexpr Quantity kPressure{"pressure", "cylinder", kMaxPressureOffset, "Pa"};
constexpr Quantity kLength{"length", "cylinder", kMaxLengthOffset, "m"};
constexpr Quantity kSupply{"supply", "", kMaxPressureOffset, "Pa"};

class Parser {
 public:
  explicit Parser(std::string source) : source_(std::move(source)) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw std::invalid_argument("calibration " + source_ + ": " + what);
  }

  double number(const YAML::Node& node, const std::string& where) const {
    double v = 0;
    bool ok = node.IsScalar();
    if (ok) {
      try {
        v = node.as<double>();
      } catch (const YAML::Exception&) {
        ok = false;
      }
    }
    if (!ok) fail(where + " must be a number, got " + shown(node));
    if (!std::isfinite(v)) fail(where + " must be finite, got " + shown(node));
    return v;
  }

  Affine entry(const YAML::Node& node, const std::string& where, const Quantity& q) const {
    if (!node.IsMap()) fail(where + " must be a map {offset: <" + q.unit + ">, gain: <g>}, got " + shown(node));
    Affine a;
    for (const auto& kv : node) {
      const std::string key = kv.first.Scalar();
      const std::string path = where + "." + key;
      if (key == "offset") {
        a.offset = number(kv.second, path);
      } else if (key == "gain") {
        a.gain = number(kv.second, path);
      } else {
        fail(path + ": unknown key (an entry has offset and gain)");
      }
    }
    checkBounds(a, where, q, [&](const char* field) { return shown(node[field]); });
    return a;
  }

  // `value(field)` gives the offending value as the user wrote it.
  template <typename Shown>
  void checkBounds(const Affine& a, const std::string& where, const Quantity& q, Shown value) const {
    if (!(a.gain >= kMinCalibrationGain && a.gain <= kMaxCalibrationGain))
      fail(where + ".gain must be in [" + exact(kMinCalibrationGain) + ", " + exact(kMaxCalibrationGain) + "], got " +
           value("gain"));
    if (!(std::abs(a.offset) <= q.max_offset))
      fail(where + ".offset must be within +-" + exact(q.max_offset) + " " + q.unit + ", got " + value("offset"));
  }

  // A section mapping names to entries; names must be in `names`.
  void section(const YAML::Node& node, const Quantity& q, const std::vector<std::string>& names,
               std::vector<Affine>* out) const {
    const std::string where = q.section;
    if (node.IsNull()) return;  // "joints:" with nothing under it
    if (!node.IsMap()) fail(where + " must be a map of " + q.what + " name -> {offset, gain}, got " + shown(node));
    std::unordered_map<std::string, std::size_t> index;
    for (std::size_t i = 0; i < names.size(); ++i) index.emplace(names[i], i);
    for (const auto& kv : node) {
      const std::string name = kv.first.Scalar();
      const auto it = index.find(name);
      if (it == index.end()) fail(where + "." + name + ": unknown " + q.what + " (not in the model)");
      (*out)[it->second] = entry(kv.second, where + "." + name, q);
    }
  }

 private:
  std::string source_;
};

}  // namespace

Calibration parseCalibration(const std::string& text, const std::string& source,
                             const std::vector<std::string>& joint_names,
                             const std::vector<std::string>& cylinder_names) {
  const Parser parser(source);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    parser.fail("not valid YAML (line " + std::to_string(e.mark.line + 1) + ": " + e.msg + ")");
  }
  Calibration c = identityCalibration(joint_names.size(), cylinder_names.size());
  if (root.IsNull()) return c;  // an empty file: the identity
  if (!root.IsMap()) parser.fail("the top level must be a map (joints, pressure, length, supply, version)");
  for (const auto& kv : root) {
    const std::string key = kv.first.Scalar();
    if (key == "version") {
      const double v = parser.number(kv.second, "version");
      if (v != kCalibrationVersion)
        parser.fail("version must be " + std::to_string(kCalibrationVersion) + ", got " + shown(kv.second));
    } else if (key == kJoints.section) {
      parser.section(kv.second, kJoints, joint_names, &c.joint);
    } else if (key == kPressure.section) {
      parser.section(kv.second, kPressure, cylinder_names, &c.pressure);
    } else if (key == kLength.section) {
      parser.section(kv.second, kLength, cylinder_names, &c.length);
    } else if (key == kSupply.section) {
      c.supply = parser.entry(kv.second, kSupply.section, kSupply);
    } else {
      parser.fail(key + ": unknown key (known: version, joints, pressure, length, supply)");
    }
  }
  return c;
}

Calibration loadCalibration(const std::string& path, const std::vector<std::string>& joint_names,
                            const std::vector<std::string>& cylinder_names) {
  std::string text;
  try {  // a path from a parameter: a FIFO, device or huge file must not hang or exhaust the node
    text = readBoundedFile(path, kMaxCalibrationFileBytes);
  } catch (const FileError& e) {
    throw std::invalid_argument(std::string("calibration ") + e.what());
  }
  return parseCalibration(text, path, joint_names, cylinder_names);
}

std::string validateCalibration(const Calibration& c, const std::vector<std::string>& joint_names,
                                const std::vector<std::string>& cylinder_names) {
  if (c.joint.size() != joint_names.size())
    return "calibration has " + std::to_string(c.joint.size()) + " joints, the model " +
           std::to_string(joint_names.size());
  if (c.pressure.size() != cylinder_names.size() || c.length.size() != cylinder_names.size())
    return "calibration has " + std::to_string(c.pressure.size()) + " pressure and " + std::to_string(c.length.size()) +
           " length entries, the model " + std::to_string(cylinder_names.size()) + " cylinders";
  const Parser parser("(in memory)");
  try {
    const auto check = [&](const Affine& a, const std::string& where, const Quantity& q) {
      parser.checkBounds(a, where, q,
                         [&](const char* field) { return exact(std::string(field) == "gain" ? a.gain : a.offset); });
    };
    for (std::size_t j = 0; j < joint_names.size(); ++j) check(c.joint[j], "joints." + joint_names[j], kJoints);
    for (std::size_t i = 0; i < cylinder_names.size(); ++i) {
      check(c.pressure[i], "pressure." + cylinder_names[i], kPressure);
      check(c.length[i], "length." + cylinder_names[i], kLength);
    }
    check(c.supply, "supply", kSupply);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

std::string formatCalibration(const Calibration& c, const std::vector<std::string>& joint_names,
                              const std::vector<std::string>& cylinder_names) {
  if (c.joint.size() != joint_names.size() || c.pressure.size() != cylinder_names.size() ||
      c.length.size() != cylinder_names.size())
    throw std::invalid_argument("formatCalibration: the calibration does not match the names");
  const auto entry = [](const Affine& a) { return "{offset: " + exact(a.offset) + ", gain: " + exact(a.gain) + "}"; };
  std::ostringstream out;
  out << "version: " << kCalibrationVersion << "\n";
  out << "joints:    # rad: joint angle = gain * palm value + offset\n";
  for (std::size_t j = 0; j < joint_names.size(); ++j)
    out << "  " << joint_names[j] << ": " << entry(c.joint[j]) << "\n";
  out << "pressure:  # Pa absolute\n";
  for (std::size_t i = 0; i < cylinder_names.size(); ++i)
    out << "  " << cylinder_names[i] << ": " << entry(c.pressure[i]) << "\n";
  out << "length:    # m of piston travel\n";
  for (std::size_t i = 0; i < cylinder_names.size(); ++i)
    out << "  " << cylinder_names[i] << ": " << entry(c.length[i]) << "\n";
  out << "supply: " << entry(c.supply) << "  # Pa absolute\n";
  return out.str();
}

}  // namespace adroit::driver::can
