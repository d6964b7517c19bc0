#include "adroit_learning/training_task.h"

#include <adroit_core/bounded_file.h>
#include <adroit_core/nearest_name.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <dirent.h>
#include <set>

namespace adroit {

double TargetSchedule::at(int t, int horizon) const {
  double v = value.empty() ? 0.0 : value[0];
  for (std::size_t i = 1; i < fraction.size(); ++i)
    if (t >= fraction[i] * horizon) v = value[i];
  return v;
}

namespace {

// A task file is a few dozen lines.
constexpr std::size_t kMaxTaskFileBytes = 1 * kMiB;

class Reader {
 public:
  Reader(const YAML::Node& root, std::string file) : root_(root), file_(std::move(file)) {}

  [[noreturn]] void fail(const std::string& field, const std::string& problem) const {
    throw TaskError(file_ + ": " + field + ": " + problem);
  }
  YAML::Node node(const std::string& field) const { return root_[field]; }

  double number(const YAML::Node& v, const std::string& field) const {
    double x;
    try {
      x = v.as<double>();
    } catch (const YAML::Exception&) {
      fail(field, "expected a number");
    }
    if (!std::isfinite(x)) fail(field, "not finite");
    return x;
  }
  double number(const std::string& field, double min, double max, bool required, double fallback) const {
    const YAML::Node v = root_[field];
    if (!v) {
      if (required) fail(field, "missing");
      return fallback;
    }
    const double x = number(v, field);
    if (x < min || x > max) fail(field, "must be in [" + fmt(min) + ", " + fmt(max) + "], got " + fmt(x));
    return x;
  }
  std::string text(const std::string& field, bool required, const std::string& fallback = "") const {
    const YAML::Node v = root_[field];
    if (!v) {
      if (required) fail(field, "missing");
      return fallback;
    }
    if (!v.IsScalar()) fail(field, "expected a string");
    return v.as<std::string>();
  }
  std::map<std::string, double> jointMap(const std::string& field) const {
    std::map<std::string, double> out;
    const YAML::Node v = root_[field];
    if (!v) return out;
    if (!v.IsMap()) fail(field, "expected a map of joint name: angle (rad)");
    for (const auto& kv : v) {
      const std::string name = kv.first.as<std::string>();
      out[name] = number(kv.second, field + "." + name);
    }
    return out;
  }
  static std::string fmt(double x) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%g", x);
    return buf;
  }

 private:
  YAML::Node root_;
  std::string file_;
};

const std::set<std::string> kKnownFields = {
    "name", "description", "scene", "horizon", "control_dt", "initial_keyframe", "initial_joints",
    "initial_object_position",
    "initial_pressure", "target_joints", "joint_weight", "final_joint_weight", "action_weight",
    "object_position_weight", "object_rotation_weight", "final_scale", "rotation_axis", "rotation_target",
    "locked_cylinders", "locked_command", "initial_command", "initial_variance", "imitation_variance", "epsilon",
    "success_joint_rms", "success_angle", "drop_height", "initial_object_yaw", "object_position_target",
    "object_height_weight", "object_height_target", "success_criterion"};

// A world position [x, y, z] within 10 m of the origin.
std::vector<double> worldPosition(const Reader& r, const std::string& field) {
  std::vector<double> out;
  const YAML::Node p = r.node(field);
  if (!p) return out;
  if (!p.IsSequence() || p.size() != 3) r.fail(field, "expected [x, y, z] (m)");
  for (int i = 0; i < 3; ++i) {
    const double v = r.number(p[i], field);
    if (std::abs(v) > 10) r.fail(field, "must be within 10 m of the origin");
    out.push_back(v);
  }
  return out;
}

// The pickup fields (thesis 10.4, 11.3, 11.4).
void readPickupFields(const Reader& r, TrainingTask& task) {
  if (const YAML::Node yaw = r.node("initial_object_yaw")) {
    const double deg = r.number(yaw, "initial_object_yaw");
    if (deg < 0 || deg >= 180) r.fail("initial_object_yaw", "must be in [0, 180) degrees, got " + Reader::fmt(deg));
    task.initial_object_yaw = deg;
  }
  task.object_position_target = worldPosition(r, "object_position_target");
  task.object_height_weight = r.number("object_height_weight", 0, 1e6, false, 0);
  task.object_height_target = r.number("object_height_target", -1, 10, false, 0);
  task.success_criterion = r.text("success_criterion", false);
  if (!task.success_criterion.empty() && !task.pickupSuccessCriterion())
    r.fail("success_criterion", "expected 'pickup' (or none: the joint and angle criteria), got '" +
                                    task.success_criterion + "'");
}

}  // namespace

TrainingTask loadTrainingTask(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::Load(readBoundedFile(path, kMaxTaskFileBytes));
  } catch (const FileError& e) {
    throw TaskError(e.what());
  } catch (const YAML::Exception& e) {
    throw TaskError(path + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) throw TaskError(path + ": expected a map of task fields");
  const Reader r(root, path);
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (!kKnownFields.count(key)) r.fail(key, "unknown field");
  }
  TrainingTask task;
  task.name = r.text("name", true);
  task.description = r.text("description", false);
  task.scene = r.text("scene", true);
  const double horizon = r.number("horizon", 1, 10000, true, 0);
  if (horizon != std::floor(horizon)) r.fail("horizon", "must be a whole number of control steps");
  task.horizon = static_cast<int>(horizon);
  task.control_dt = r.number("control_dt", 1e-3, 1.0, true, 0);
  task.initial_keyframe = r.text("initial_keyframe", false);
  task.initial_joints = r.jointMap("initial_joints");
  task.initial_object_position = worldPosition(r, "initial_object_position");
  task.initial_pressure = r.number("initial_pressure", 101325.0, 700e3, false, task.initial_pressure);
  task.target_joints = r.jointMap("target_joints");
  task.joint_weight = r.number("joint_weight", 0, 1e6, false, task.joint_weight);
  task.final_joint_weight = r.number("final_joint_weight", 0, 1e6, false, task.final_joint_weight);
  task.action_weight = r.number("action_weight", 0, 1e6, false, task.action_weight);
  task.object_position_weight = r.number("object_position_weight", 0, 1e6, false, 0);
  task.object_rotation_weight = r.number("object_rotation_weight", 0, 1e6, false, 0);
  task.final_scale = r.number("final_scale", 0, 1e6, false, 1.0);
  if (const YAML::Node axis = r.node("rotation_axis")) {
    if (!axis.IsSequence() || axis.size() != 3) r.fail("rotation_axis", "expected [x, y, z]");
    double norm = 0;
    for (int i = 0; i < 3; ++i) {
      task.rotation_axis[i] = r.number(axis[i], "rotation_axis");
      norm += task.rotation_axis[i] * task.rotation_axis[i];
    }
    if (norm < 1e-12) r.fail("rotation_axis", "must not be zero");
    for (double& a : task.rotation_axis) a /= std::sqrt(norm);
  }
  if (const YAML::Node target = r.node("rotation_target")) {
    // A number (fixed angle) or a list of [fraction of T, angle] from fraction 0 on.
    if (target.IsScalar()) {
      task.rotation_target.fraction = {0.0};
      task.rotation_target.value = {r.number(target, "rotation_target")};
    } else if (target.IsSequence() && target.size() > 0) {
      for (std::size_t i = 0; i < target.size(); ++i) {
        const std::string where = "rotation_target[" + std::to_string(i) + "]";
        if (!target[i].IsSequence() || target[i].size() != 2) r.fail(where, "expected [fraction of T, angle]");
        const double f = r.number(target[i][0], where);
        if (i == 0 ? f != 0.0 : (f <= task.rotation_target.fraction.back() || f >= 1.0))
          r.fail(where, "fractions start at 0 and increase below 1");
        task.rotation_target.fraction.push_back(f);
        task.rotation_target.value.push_back(r.number(target[i][1], where));
      }
    } else {
      r.fail("rotation_target", "expected an angle or a list of [fraction of T, angle]");
    }
  } else {
    task.rotation_target = {{0.0}, {0.0}};
  }
  if (const YAML::Node locked = r.node("locked_cylinders")) {
    if (!locked.IsSequence()) r.fail("locked_cylinders", "expected a list of cylinder names");
    for (const auto& n : locked) task.locked_cylinders.push_back(n.as<std::string>());
  }
  task.locked_command = r.number("locked_command", -5, 5, false, 0);
  task.initial_command = r.number("initial_command", -5, 5, false, 0);
  task.initial_variance = r.number("initial_variance", 1e-6, 25, false, task.initial_variance);
  task.imitation_variance = r.number("imitation_variance", 0, 25, false, task.imitation_variance);
  task.epsilon = r.number("epsilon", 1e-6, 1e6, false, task.epsilon);
  task.success_joint_rms = r.number("success_joint_rms", 0, 10, false, task.success_joint_rms);
  task.success_angle = r.number("success_angle", 0, 10, false, task.success_angle);
  task.drop_height = r.number("drop_height", -1e9, 10, false, task.drop_height);
  readPickupFields(r, task);
  if (task.initial_object_yaw && !task.uses_object())
    r.fail("initial_object_yaw", "only for tasks with object cost terms");
  if (!task.initial_object_position.empty() && !task.uses_object())
    r.fail("initial_object_position", "only for tasks with object cost terms");
  if (task.target_joints.empty() && !task.uses_object())
    r.fail("target_joints", "a task without object terms needs joint targets");
  return task;
}

std::vector<std::string> trainingTaskNames(const std::string& dir) {
  std::vector<std::string> names;
  if (DIR* d = opendir(dir.c_str())) {
    while (const dirent* e = readdir(d)) {
      const std::string file = e->d_name;
      const std::string ext = ".yaml";
      if (file.size() > ext.size() && file.compare(file.size() - ext.size(), ext.size(), ext) == 0)
        names.push_back(file.substr(0, file.size() - ext.size()));
    }
    closedir(d);
  }
  std::sort(names.begin(), names.end());
  return names;
}

TrainingTask findTrainingTask(const std::string& dir, const std::string& name) {
  const std::vector<std::string> names = trainingTaskNames(dir);
  if (std::find(names.begin(), names.end(), name) == names.end()) {
    std::string known;
    for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
    throw TaskError("unknown task '" + name + "'" + didYouMean(name, names) + " (known: " +
                    (known.empty() ? "none in " + dir : known) + ")");
  }
  TrainingTask task = loadTrainingTask(dir + "/" + name + ".yaml");
  if (task.name != name) throw TaskError(dir + "/" + name + ".yaml: name: '" + task.name + "' differs from the file name");
  return task;
}

}  // namespace adroit
