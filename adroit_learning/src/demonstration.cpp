#include "adroit_learning/demonstration.h"

#include <adroit_core/word_list.h>
#include <adroit_core/bounded_file.h>
#include <adroit_core/number_text.h>
#include <adroit_learning/matrix_file.h>

#include <cmath>
#include <map>
#include <sstream>

namespace adroit {

namespace {

// A `demos export` file is far smaller than a matrix file's limit: 4 s at 25 Hz of 100 + 40
// numbers is 100 kB; an hour of recording at 25 Hz is about 250 MB.
constexpr std::size_t kMaxDemonstrationBytes = kMaxMatrixFileBytes;

// "# key: value" header lines, keyed by the text before the first ':' (e.g. "joints (24)").
std::map<std::string, std::string> headerLines(const std::string& text) {
  std::map<std::string, std::string> header;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line) && (line.empty() || line[0] == '#')) {
    const auto colon = line.find(':');
    if (line.size() < 2 || colon == std::string::npos) continue;
    std::string key = line.substr(2, colon - 2), value = line.substr(colon + 1);
    if (!value.empty() && value[0] == ' ') value.erase(0, 1);
    const auto paren = key.find(" (");
    if (paren != std::string::npos) key.erase(paren);
    header.emplace(key, value);
  }
  return header;
}

const std::string& required(const std::map<std::string, std::string>& header, const std::string& key,
                            const std::string& path) {
  const auto it = header.find(key);
  if (it == header.end())
    throw DemonstrationError(path + ": no '" + key + "' line in the header: not a file of `demos export`");
  return it->second;
}

void fillFromHeader(const std::map<std::string, std::string>& header, Demonstration& demo) {
  demo.task = required(header, "task", demo.path);
  demo.mode = required(header, "mode", demo.path);
  demo.model = required(header, "model", demo.path);
  demo.joints = splitWords(required(header, "joints", demo.path));
  demo.cylinders = splitWords(required(header, "cylinders", demo.path));
  demo.has_object = required(header, "object", demo.path).rfind("yes", 0) == 0;
  const std::vector<std::string> actions = splitWords(required(header, "actions", demo.path));
  demo.actions = actions.empty() ? "" : actions.front();
}

// The scene a recording's model names: ".../mjcf/tube.xml" -> "tube".
std::string sceneOfModel(const std::string& model) {
  const auto slash = model.find_last_of('/');
  std::string name = slash == std::string::npos ? model : model.substr(slash + 1);
  const auto dot = name.rfind(".xml");
  if (dot != std::string::npos) name.erase(dot);
  return name;
}

std::string seconds(double s) { return shortNumber(std::round(s * 100) / 100) + " s"; }

}  // namespace

Demonstration readDemonstrationFile(const std::string& path) {
  Demonstration demo;
  demo.path = path;
  std::string text;
  try {
    text = readBoundedFile(path, kMaxDemonstrationBytes);
  } catch (const FileError& e) {
    throw DemonstrationError(e.what());
  }
  fillFromHeader(headerLines(text), demo);
  try {
    const MatrixFile file = MatrixFile::parse(text, path);
    const int nj = static_cast<int>(demo.joints.size()), nc = static_cast<int>(demo.cylinders.size());
    const int nx = 2 * nj + (demo.has_object ? 12 : 0) + nc;
    const Eigen::MatrixXd& X = file.get("X");
    if (X.cols() != nx)
      throw DemonstrationError(path + ": X has " + std::to_string(X.cols()) + " columns, the header's joints, object and cylinders make " +
                               std::to_string(nx));
    demo.x = X.transpose();
    demo.u = file.get("U", static_cast<int>(X.rows()), nc).transpose();
    demo.dt = file.get("dt", 1, 1)(0, 0);
  } catch (const MatrixFileError& e) {
    throw DemonstrationError(e.what());
  }
  if (demo.samples() < 1) throw DemonstrationError(path + ": no samples");
  if (!(demo.dt > 0) || !std::isfinite(demo.dt)) throw DemonstrationError(path + ": dt must be positive, got " + shortNumber(demo.dt));
  return demo;
}

std::string demonstrationTaskMismatch(const Demonstration& demo, const TrainingTask& task) {
  const std::string where = demo.path + ": ";
  if (demo.task != task.name) return where + "recorded for task '" + demo.task + "', not '" + task.name + "'";
  if (sceneOfModel(demo.model) != task.scene)
    return where + "recorded in scene '" + sceneOfModel(demo.model) + "', task '" + task.name + "' runs in '" + task.scene + "'";
  if (demo.actions != "valve")
    return where + "its actions are " + (demo.actions.empty() ? "missing" : demo.actions) +
           " commands; the trainer learns valve commands (record with mode:=pneumatic)";
  if (task.uses_object() && !demo.has_object) return where + "has no object pose, task '" + task.name + "' needs it";
  if (std::abs(demo.dt - task.control_dt) > 1e-9)
    return where + "sampled every " + shortNumber(demo.dt) + " s, the task's control step is " + shortNumber(task.control_dt) +
           " s (export with --dt " + shortNumber(task.control_dt) + ")";
  if (demo.samples() < task.horizon + 1)
    return where + "too short: " + seconds((demo.samples() - 1) * demo.dt) + ", the task needs " + seconds(task.horizon * task.control_dt);
  return "";
}

std::string demonstrationRobotMismatch(const Demonstration& demo, const StateLayout& layout) {
  const std::string where = demo.path + ": ";
  if (demo.joints != layout.joint_names) return where + "recorded with other joints than the robot has";
  if (demo.cylinders != layout.cylinder_names) return where + "recorded with other cylinders than the robot has";
  if (demo.x.rows() != layout.nx())
    return where + "states of size " + std::to_string(demo.x.rows()) + ", the task's are " + std::to_string(layout.nx());
  return "";
}

std::string demonstrationMismatch(const Demonstration& demo, const TrainingTask& task, const StateLayout& layout) {
  const std::string problem = demonstrationTaskMismatch(demo, task);
  return problem.empty() ? demonstrationRobotMismatch(demo, layout) : problem;
}

void imitateDemonstration(const Demonstration& demo, const StateLayout& layout, const ObjectGeometry& geometry,
                          TrainingTask& task) {
  task.joint_reference.assign(task.horizon + 1, std::vector<double>(layout.joints()));
  for (int t = 0; t <= task.horizon; ++t)
    for (int j = 0; j < layout.joints(); ++j) task.joint_reference[t][j] = demo.x(layout.q() + j, t);
  if (task.initial_object_yaw) task.initial_object_yaw = tubeYawFromState(demo.x.col(0), layout, geometry);
  if (task.imitation_variance > 0) task.initial_variance = task.imitation_variance;
}

Eigen::MatrixXd demonstrationActions(const Demonstration& demo, const StateLayout& layout, int horizon) {
  Eigen::MatrixXd u(layout.nu(), horizon);
  for (int i = 0; i < layout.nu(); ++i) u.row(i) = demo.u.row(layout.action_cylinders[i]).head(horizon);
  return u;
}

double tubeYawFromState(const Eigen::Ref<const Eigen::VectorXd>& x, const StateLayout& layout,
                        const ObjectGeometry& geometry) {
  const Eigen::Vector3d rotation = x.segment<3>(layout.objectRotation());
  const double angle = rotation.norm();
  const Eigen::Quaterniond q =
      angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation / angle)) : Eigen::Quaterniond::Identity();
  return tubeYawDegrees(q, geometry);
}

}  // namespace adroit
