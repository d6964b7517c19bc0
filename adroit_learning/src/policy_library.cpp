#include "adroit_learning/policy_library.h"

#include <adroit_core/number_text.h>
#include <adroit_core/bounded_file.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <stdexcept>

namespace adroit {

namespace {

constexpr const char* kMagic = "adroit_policy_library";
// The state layout's block that holds the object's rotation vector (StateLayout::describe()).
constexpr const char* kRotationBlock = "object_rotation_vector";

// "" when the yaws are usable as a library's keys, else why not.
std::string yawsProblem(const std::vector<PolicyLibraryEntry>& entries) {
  if (entries.empty()) return "library has no policies";
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const double yaw = entries[i].yaw_deg;
    if (!(std::isfinite(yaw) && yaw >= 0 && yaw < 180))
      return "policy " + entries[i].path + ": angle must be in [0, 180) degrees, got " + exactNumber(yaw);
    for (std::size_t j = 0; j < i; ++j)
      if (entries[j].yaw_deg == yaw)
        return "policies " + entries[j].path + " and " + entries[i].path + " have the same angle " + exactNumber(yaw);
  }
  return "";
}

// A name that one `key value` line holds: not empty, no whitespace.
bool isSingleWord(const std::string& s) { return !s.empty() && s.find_first_of(" \t\r\n") == std::string::npos; }

// The offset of `block` in a StateLayout::describe() text ("q:24 object_position:3 ..."):
// the sum of the sizes of the blocks before it; -1 when it is not there.
int blockOffset(const std::string& layout, const std::string& block) {
  std::istringstream in(layout);
  int offset = 0;
  for (std::string item; in >> item;) {
    const auto colon = item.rfind(':');
    if (colon == std::string::npos) return -1;
    if (item.compare(0, colon, block) == 0 && colon == block.size()) return offset;
    offset += std::atoi(item.c_str() + colon + 1);
  }
  return -1;
}

// "" when `p` can run beside `first` in one library (and `first` fits the library), else why not.
std::string localPolicyProblem(const PolicyLibrary& library, const PolicyFile& first, const PolicyLibraryEntry& entry) {
  const PolicyFile& p = *entry.policy;
  const std::string& name = entry.resolved_path;
  if (p.task != library.task) return name + ": task '" + p.task + "', the library's is '" + library.task + "'";
  if (p.scene != library.scene) return name + ": scene '" + p.scene + "', the library's is '" + library.scene + "'";
  if (p.state_layout != first.state_layout)
    return name + ": state layout '" + p.state_layout + "', the library's first policy has '" + first.state_layout + "'";
  if (p.joints != first.joints || p.cylinders != first.cylinders || p.actions != first.actions)
    return name + ": other joints, cylinders or actions than the library's first policy";
  if (p.control_dt != first.control_dt)
    return name + ": control_dt " + exactNumber(p.control_dt) + " s, the library's first policy has " +
           exactNumber(first.control_dt) + " s";
  if (p.controller.horizon() != first.controller.horizon())
    return name + ": horizon " + std::to_string(p.controller.horizon()) + ", the library's first policy has " +
           std::to_string(first.controller.horizon());
  return "";
}

// The header and entries of a library's text, without reading the local policies.
PolicyLibrary parseLibrary(const std::string& text, const std::string& path) {
  const auto fail = [&](const std::string& what) { return PolicyFileError(path + ": " + what); };
  std::istringstream in(text);
  std::string line;
  if (!std::getline(in, line)) throw fail("empty file");
  {
    std::istringstream first(line);
    std::string magic;
    int version = 0;
    first >> magic >> version;
    if (magic != kMagic) throw fail("not a policy library (first line '" + line.substr(0, 60) + "')");
    if (version != kPolicyLibraryFormatVersion)
      throw fail("format version " + std::to_string(version) + ", this build reads version " +
                 std::to_string(kPolicyLibraryFormatVersion));
  }
  PolicyLibrary library;
  for (int number = 2; std::getline(in, line); ++number) {
    std::istringstream fields(line);
    std::string key;
    if (!(fields >> key) || key[0] == '#') continue;  // blank line or comment
    const std::string where = "line " + std::to_string(number) + ": ";
    if (key == "task" || key == "scene") {
      std::string value, extra;
      std::string& field = key == "task" ? library.task : library.scene;
      if (!(fields >> value) || (fields >> extra) || !field.empty()) throw fail(where + "one '" + key + " <name>' line expected");
      field = value;
    } else if (key == "policy") {
      PolicyLibraryEntry entry;
      std::string yaw;
      fields >> yaw >> std::ws;
      std::getline(fields, entry.path);  // the rest of the line: a path may hold spaces
      char* end = nullptr;
      entry.yaw_deg = std::strtod(yaw.c_str(), &end);
      if (yaw.empty() || *end != '\0' || entry.path.empty())
        throw fail(where + "expected 'policy <initial object yaw, degrees> <policy file>'");
      library.entries.push_back(std::move(entry));
    } else {
      throw fail(where + "unknown key '" + key.substr(0, 40) + "'");
    }
  }
  if (library.task.empty() || library.scene.empty()) throw fail("'task' and 'scene' lines are required");
  const std::string bad_yaws = yawsProblem(library.entries);
  if (!bad_yaws.empty()) throw fail(bad_yaws);
  return library;
}

// Reads every entry's local policy (relative paths from the library's directory) and checks
// that they belong together.
void readLocalPolicies(PolicyLibrary& library, const std::string& path) {
  const std::filesystem::path directory = std::filesystem::path(path).parent_path();
  for (PolicyLibraryEntry& entry : library.entries) {
    const std::filesystem::path local(entry.path);
    entry.resolved_path = local.is_absolute() ? local.string() : (directory / local).string();
    try {
      entry.policy = std::make_shared<const PolicyFile>(readPolicyFile(entry.resolved_path));
    } catch (const PolicyFileError& e) {
      throw PolicyFileError(path + ": " + e.what());
    }
    const std::string problem = localPolicyProblem(library, *library.entries.front().policy, entry);
    if (!problem.empty()) throw PolicyFileError(path + ": " + problem);
  }
}

Eigen::Quaterniond quaternionFromRotationVector(const Eigen::Vector3d& rv) {
  const double angle = rv.norm();
  return angle < 1e-12 ? Eigen::Quaterniond::Identity() : Eigen::Quaterniond(Eigen::AngleAxisd(angle, rv / angle));
}

}  // namespace

std::vector<double> PolicyLibrary::yaws() const {
  std::vector<double> out;
  for (const auto& e : entries) out.push_back(e.yaw_deg);
  return out;
}

PolicyLibrary readPolicyLibrary(const std::string& path) {
  std::string text;
  try {
    text = readBoundedFile(path, kMaxPolicyLibraryFileBytes);
  } catch (const FileError& e) {
    throw PolicyFileError(e.what());
  }
  PolicyLibrary library = parseLibrary(text, path);
  readLocalPolicies(library, path);
  return library;
}

void writePolicyLibrary(const std::string& path, const PolicyLibrary& library) {
  if (!isSingleWord(library.task) || !isSingleWord(library.scene))
    throw PolicyFileError(path + ": task and scene must be single words, got '" + library.task + "', '" +
                          library.scene + "'");
  const std::string bad_yaws = yawsProblem(library.entries);
  if (!bad_yaws.empty()) throw PolicyFileError(path + ": " + bad_yaws);
  std::ostringstream out;
  out << kMagic << " " << kPolicyLibraryFormatVersion << "\n"
      << "task " << library.task << "\n"
      << "scene " << library.scene << "\n";
  for (const auto& e : library.entries) {
    if (e.path.empty() || e.path.find('\n') != std::string::npos || std::isspace(static_cast<unsigned char>(e.path[0])))
      throw PolicyFileError(path + ": policy path '" + e.path + "' cannot be written on one line");
    out << "policy " << exactNumber(e.yaw_deg) << " " << e.path << "\n";
  }
  writeFileAtomically(path, out.str());
}

int nearestPolicyIndex(const std::vector<double>& yaws_deg, double observed_yaw_deg) {
  if (!std::isfinite(observed_yaw_deg)) return -1;
  int best = -1;
  double best_distance = 0;
  for (std::size_t i = 0; i < yaws_deg.size(); ++i) {
    const double d = std::fmod(std::abs(yaws_deg[i] - observed_yaw_deg), 180.0);
    const double distance = std::min(d, 180.0 - d);
    if (best < 0 || distance < best_distance) {  // strict: a tie keeps the lower index
      best = static_cast<int>(i);
      best_distance = distance;
    }
  }
  return best;
}

LibraryPolicy::LibraryPolicy(std::shared_ptr<const PolicyLibrary> library, const ObjectGeometry& object, std::string path)
    : library_(std::move(library)), object_(object), path_(std::move(path)) {
  if (!library_ || library_->entries.empty()) throw PolicyFileError(path_ + ": library has no policies");
  for (const auto& e : library_->entries) {
    if (!e.policy) throw PolicyFileError(path_ + ": policy " + e.path + " was not read");
    locals_.emplace_back(e.policy, e.resolved_path.empty() ? e.path : e.resolved_path);
  }
  yaws_ = library_->yaws();
  rotation_index_ = blockOffset(library_->entries.front().policy->state_layout, kRotationBlock);
  if (rotation_index_ < 0)
    throw PolicyFileError(path_ + ": its policies' state has no object rotation to choose by ('" +
                          library_->entries.front().policy->state_layout + "')");
}

void LibraryPolicy::start(const Eigen::Ref<const Eigen::VectorXd>& x0) {
  if (x0.size() < rotation_index_ + 3)
    throw std::invalid_argument(path_ + ": state of size " + std::to_string(x0.size()) + " has no object rotation");
  const Eigen::Vector3d rotation = x0.segment<3>(rotation_index_);
  if (!rotation.allFinite()) throw std::invalid_argument(path_ + ": the object's rotation is not finite");
  observed_yaw_ = tubeYawDegrees(quaternionFromRotationVector(rotation), object_);
  selected_ = nearestPolicyIndex(yaws_, observed_yaw_);
}

void LibraryPolicy::action(int t, const Eigen::Ref<const Eigen::VectorXd>& x,
                           const Eigen::Ref<const Eigen::VectorXd>& touch, Eigen::Ref<Eigen::VectorXd> u) {
  if (selected_ < 0) throw std::logic_error(path_ + ": action before start");
  locals_[selected_].action(t, x, touch, u);
}

std::string LibraryPolicy::mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                                    const std::vector<std::string>& touch, const StateLayout& layout) const {
  if (!layout.hasObject() || layout.objectRotation() != rotation_index_)
    return path_ + ": the library chooses by the object's orientation; the task's state on this robot has " +
           (layout.hasObject() ? "it elsewhere" : "no object");
  for (const TvlgPolicy& local : locals_) {
    const std::string different = local.mismatch(joints, cylinders, touch, layout);
    if (!different.empty()) return path_ + ": " + different;
  }
  return "";
}

double LibraryPolicy::selectedYaw() const {
  return selected_ < 0 ? std::nan("") : yaws_[selected_];
}

}  // namespace adroit
