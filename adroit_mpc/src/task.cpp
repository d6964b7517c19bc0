// Shared pieces of the task interface: cost derivative storage, parameter merging and checks.
#include "adroit_mpc/task.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "adroit_mpc/task_params.h"

namespace adroit_mpc {

void CostDerivatives::resize(int nx, int nu) {
  lx = Eigen::VectorXd::Zero(nx);
  lu = Eigen::VectorXd::Zero(nu);
  lxx = Eigen::MatrixXd::Zero(nx, nx);
  luu = Eigen::MatrixXd::Zero(nu, nu);
  lux = Eigen::MatrixXd::Zero(nu, nx);
}

void CostDerivatives::setZero() {
  lx.setZero();
  lu.setZero();
  lxx.setZero();
  luu.setZero();
  lux.setZero();
}

namespace {

std::string keysOf(const TaskParams& p) {
  std::string out;
  auto add = [&out](const std::string& k) { out += (out.empty() ? "" : ", ") + k; };
  for (const auto& kv : p.numbers) add(kv.first);
  for (const auto& kv : p.vectors) add(kv.first);
  for (const auto& kv : p.strings) add(kv.first);
  return out;
}

std::string prefix(const std::string& task, const std::string& key) {
  return "task " + task + ": parameter '" + key + "' ";
}

std::string kindOf(const TaskParams& p, const std::string& key) {
  if (p.numbers.count(key)) return "a number";
  if (p.vectors.count(key)) return "a list of numbers";
  if (p.strings.count(key)) return "a string";
  return "";
}

template <class Map>
void overlay(const std::string& task, const TaskParams& defaults, const Map& given, Map& merged) {
  for (const auto& kv : given) {
    auto it = merged.find(kv.first);
    if (it != merged.end()) {
      it->second = kv.second;
      continue;
    }
    const std::string expected = kindOf(defaults, kv.first);
    if (expected.empty())
      throw std::invalid_argument("task " + task + ": unknown parameter '" + kv.first + "' (known: " +
                                  keysOf(defaults) + ")");
    throw std::invalid_argument(prefix(task, kv.first) + "must be " + expected);
  }
}

std::string formatVector(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
  return s.str();
}

}  // namespace

TaskParams mergeTaskParams(const std::string& task, const TaskParams& defaults, const TaskParams& given) {
  TaskParams merged = defaults;
  overlay(task, defaults, given.numbers, merged.numbers);
  overlay(task, defaults, given.vectors, merged.vectors);
  overlay(task, defaults, given.strings, merged.strings);
  return merged;
}

double paramNumber(const std::string& task, const TaskParams& p, const std::string& key, double min, double max) {
  const auto it = p.numbers.find(key);
  if (it == p.numbers.end()) throw std::invalid_argument(prefix(task, key) + "is missing");
  const double v = it->second;
  if (!std::isfinite(v) || v < min || v > max) {
    std::ostringstream s;
    s << prefix(task, key) << "must be finite and in [" << min << ", " << max << "] (got " << v << ")";
    throw std::invalid_argument(s.str());
  }
  return v;
}

std::vector<double> paramVector(const std::string& task, const TaskParams& p, const std::string& key, int size) {
  const auto it = p.vectors.find(key);
  if (it == p.vectors.end()) throw std::invalid_argument(prefix(task, key) + "is missing");
  if (size >= 0 && static_cast<int>(it->second.size()) != size)
    throw std::invalid_argument(prefix(task, key) + "needs " + std::to_string(size) + " numbers (got " +
                                std::to_string(it->second.size()) + ")");
  for (double v : it->second)
    if (!std::isfinite(v)) throw std::invalid_argument(prefix(task, key) + "has a non-finite entry");
  return it->second;
}

Eigen::Vector3d paramVector3(const std::string& task, const TaskParams& p, const std::string& key) {
  const auto v = paramVector(task, p, key, 3);
  return {v[0], v[1], v[2]};
}

Eigen::Quaterniond paramQuaternion(const std::string& task, const TaskParams& p, const std::string& key) {
  const auto v = paramVector(task, p, key, 4);
  Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
  if (!(q.norm() > 1e-9)) throw std::invalid_argument(prefix(task, key) + "is not a rotation (zero quaternion)");
  q.normalize();
  return q;
}

const std::string& paramString(const std::string& task, const TaskParams& p, const std::string& key) {
  const auto it = p.strings.find(key);
  if (it == p.strings.end()) throw std::invalid_argument(prefix(task, key) + "is missing");
  return it->second;
}

WeightTable::WeightTable(const std::string& task, const TaskParams& merged) : task_(task) {
  for (const auto& kv : merged.numbers) {
    if (kv.first.rfind("w_", 0) != 0) continue;
    names_.push_back(kv.first);
    values_.push_back(paramNumber(task, merged, kv.first, 0.0, 1e12));
  }
}

int WeightTable::index(const std::string& name) const {
  for (size_t i = 0; i < names_.size(); ++i)
    if (names_[i] == name) return static_cast<int>(i);
  std::string known;
  for (const auto& n : names_) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("task " + task_ + ": unknown weight '" + name + "' (known: " + known + ")");
}

void WeightTable::set(const std::string& name, double value) {
  const int i = index(name);
  if (!std::isfinite(value) || value < 0) {
    std::ostringstream s;
    s << "task " << task_ << ": weight '" << name << "' must be finite and >= 0 (got " << value << ")";
    throw std::invalid_argument(s.str());
  }
  values_[i] = value;
}

void WeightTable::copyValuesFrom(const WeightTable& other) {
  if (other.values_.size() != values_.size())
    throw std::invalid_argument("task " + task_ + ": weight tables of different tasks");
  std::copy(other.values_.begin(), other.values_.end(), values_.begin());
}

bool checkGoal(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation, const WorkspaceBox& box,
               Eigen::Quaterniond* unit, std::string* why) {
  if (!position.allFinite()) {
    *why = "goal position " + formatVector(position) + " is not finite";
    return false;
  }
  if (!orientation.coeffs().allFinite()) {
    *why = "goal orientation has a non-finite quaternion entry";
    return false;
  }
  const double norm = orientation.norm();
  if (!(norm > 1e-6)) {
    *why = "goal orientation quaternion cannot be normalised (norm " + std::to_string(norm) + ")";
    return false;
  }
  if (!box.contains(position)) {
    *why = "goal position " + formatVector(position) + " is outside the workspace box " + formatVector(box.min) +
           " .. " + formatVector(box.max);
    return false;
  }
  *unit = orientation.normalized();
  return true;
}

}  // namespace adroit_mpc
